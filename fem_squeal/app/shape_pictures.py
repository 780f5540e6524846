"""Pictures of mode shapes (rank 0): the deformed outer surface coloured by the normal displacement,
in an orthographic projection, by the painter's algorithm: the triangles that face the viewer are
filled far ones first, each shaded by the cosine between its normal and the view direction so that
the shape reads in three dimensions.

The triangles are filled by Pillow's ``ImageDraw.polygon`` at twice the resolution and the image
reduced (anti-aliasing): the 7k triangles of a view of the brake corner in 30 ms, where
matplotlib's ``PolyCollection`` makes one ``Path`` object per triangle (0.7 s per view at 20k).
The views are then put into a frame (the views' titles, the colour bar) that matplotlib draws
once for all the modes.

Views: along the axis (z, the disc's axis: the builders' convention) and an oblique view (30° above
the disc's plane, azimuth −120°: the brake corner's caliper behind the disc).  Scales
(:func:`scales`): the 98th percentile of |u| is drawn as :data:`DEFORMATION` of the largest extent,
that of |u_n| as the end of the colour scale."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_squeal.app.plots import pyplot
from fem_squeal.util.atomic import atomic_path

#: displacement drawn where |u| is its PERCENTILEth percentile, as a share of the largest extent
DEFORMATION = 0.05
PERCENTILE = 98.0
#: (name, elevation, azimuth) of the views [deg]; elevation 90: along the axis
VIEWS = (("along the axis", 90.0, -90.0), ("oblique", 30.0, -120.0))
COLOURMAP = "RdBu_r"
SUPERSAMPLE = 2
DPI = 80
#: pixel size of a view (:func:`raster`'s default), and the largest of a thumbnail
VIEW_PX = (400, 300)
THUMB_PX = (200, 150)


def view_matrix(elev: float, azim: float) -> np.ndarray:
    """Rows: the screen's right, its up and the direction towards the viewer (orthographic camera at
    elevation ``elev`` and azimuth ``azim`` [deg], z up)."""
    e, a = np.radians(elev), np.radians(azim)
    d = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    right = np.cross([0.0, 0.0, 1.0], d)
    if np.linalg.norm(right) < 1e-9:                  # along the axis: x right, y up
        right = np.array([np.cos(a + np.pi / 2), np.sin(a + np.pi / 2), 0.0])
    right /= np.linalg.norm(right)
    return np.array([right, np.cross(d, right), d])


def projected(points: np.ndarray, triangles: np.ndarray, value: np.ndarray, R: np.ndarray):
    """The triangles that face the viewer, far first: (their corners on the screen (k, 3, 2), their
    values (``value``: one per triangle), their shade in [0.45, 1])."""
    q = points @ R.T
    a, b, c = (q[triangles[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    front = n[:, 2] > 0
    idx = np.flatnonzero(front)
    idx = idx[np.argsort(q[triangles[idx], 2].mean(axis=1), kind="stable")]
    nz = n[idx]
    shade = 0.45 + 0.55 * nz[:, 2] / np.maximum(np.linalg.norm(nz, axis=1), 1e-300)
    return q[triangles[idx]][:, :, :2], value[idx], shade


def colours(value: np.ndarray, vmax: float) -> np.ndarray:
    """RGB in [0, 1] of ``value`` on the symmetric scale ±vmax."""
    import matplotlib  # heavy: matplotlib (pictures only)

    return matplotlib.colormaps[COLOURMAP](0.5 + 0.5 * np.clip(value / vmax, -1.0, 1.0))[:, :3]


def raster(points: np.ndarray, triangles: np.ndarray, value: np.ndarray, vmax: float, R: np.ndarray,
           size: tuple[int, int] = VIEW_PX) -> np.ndarray:
    """One view as an RGB image (h, w, 3) uint8 on white: the surface fitted into ``size`` (w, h)
    with its aspect ratio, each triangle filled with the colour of its value (one per triangle),
    shaded."""
    from PIL import Image, ImageDraw  # heavy: Pillow (pictures only; matplotlib's own dependency)

    verts, v, shade = projected(points, triangles, value, R)
    w, h = size
    W, H = w * SUPERSAMPLE, h * SUPERSAMPLE
    q = (points @ R.T)[:, :2]
    lo, hi = q.min(axis=0), q.max(axis=0)
    scale = 0.94 * min(W / max(hi[0] - lo[0], 1e-300), H / max(hi[1] - lo[1], 1e-300))
    centre = 0.5 * (lo + hi)
    px = np.empty_like(verts)
    px[..., 0] = W / 2 + scale * (verts[..., 0] - centre[0])
    px[..., 1] = H / 2 - scale * (verts[..., 1] - centre[1])
    rgb = np.round(255 * colours(v, vmax) * shade[:, None]).astype(int)
    img = Image.new("RGB", (W, H), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    for xy, c in zip(px.reshape(-1, 6).tolist(), map(tuple, rgb.tolist())):
        draw.polygon(xy, fill=c)
    return np.asarray(img.reduce(SUPERSAMPLE))


def scales(u_re: np.ndarray, u_im: np.ndarray, un_re: np.ndarray, un_im: np.ndarray) -> tuple[float, float]:
    """The displacement and the normal displacement drawn full-scale: the :data:`PERCENTILE`th
    percentile of |u| at the points and of |u_n| over the triangles (both parts).  A mode's peak sits
    often at a corner of a small part (a backplate's edge): scaled by it, the rest would be grey."""
    mag = np.sqrt((u_re ** 2).sum(axis=1) + (u_im ** 2).sum(axis=1))
    un = np.abs(np.concatenate([un_re, un_im]))
    return float(np.percentile(mag, PERCENTILE)) or 1.0, float(np.percentile(un, PERCENTILE)) or 1.0


def deformed(points: np.ndarray, u: np.ndarray, full: float) -> np.ndarray:
    """``points`` displaced by u drawn at :data:`DEFORMATION` of the largest extent where |u| = full,
    each displacement clipped at 2 full (a local peak does not tear the picture)."""
    u = np.asarray(u, dtype=float)
    mag = np.linalg.norm(u, axis=1)
    clip = np.minimum(1.0, 2.0 * full / np.maximum(mag, 1e-300))
    return points + (DEFORMATION * np.ptp(points, axis=0).max() / full) * u * clip[:, None]


def _frame(width: float, height: float):
    """The figure without its views and title, drawn once: (RGB array, the views' pixel boxes
    [[(x0, y0, w, h)]] by row (real, imaginary) and column (:data:`VIEWS`), the title's centre)."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(width, height))
    fig.subplots_adjust(left=0.01, right=0.86, bottom=0.01, top=0.9, wspace=0.03, hspace=0.12)
    for row, name in zip(axes, ("real part", "imaginary part")):
        for ax, (view, _, _) in zip(row, VIEWS):
            ax.set_title(f"{name}, {view}", fontsize=9)
            ax.set_axis_off()
    sm = plt.cm.ScalarMappable(cmap=COLOURMAP, norm=plt.Normalize(-1.0, 1.0))
    bar = fig.colorbar(sm, cax=fig.add_axes([0.885, 0.2, 0.022, 0.6]),
                       label=f"normal displacement / its {PERCENTILE:g}th percentile")
    bar.set_ticks([-1, -0.5, 0, 0.5, 1])
    fig.set_dpi(DPI)
    fig.canvas.draw()
    rgb = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    H = rgb.shape[0]
    boxes = [[(round(b.x0), round(H - b.y1), round(b.width), round(b.height))
              for b in (ax.get_window_extent() for ax in row)] for row in axes]
    plt.close(fig)
    return rgb, boxes, (rgb.shape[1] / 2, round(0.04 * H))


def _font(size: int):
    """matplotlib's DejaVu Sans for Pillow (the figure's own font), Pillow's default without it."""
    import matplotlib  # heavy: matplotlib (pictures only)
    from PIL import ImageFont  # heavy: Pillow (pictures only; matplotlib's own dependency)

    try:
        return ImageFont.truetype(str(Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"), size)
    except OSError:
        return ImageFont.load_default()


def mode_pictures(shapes, paths: list[tuple[Path, Path]], titles: list[str]) -> None:
    """For each mode k of ``shapes`` (:class:`fem_squeal.app.mode_shapes.ModeShapes`): a figure of
    its real and imaginary parts (rows) in the two :data:`VIEWS` (columns), the surface displaced by
    the part and coloured by its normal displacement (one scale for both), saved at ``paths[k][0]``,
    and a thumbnail (the oblique view of the real part) at ``paths[k][1]``.  The frame (titles of
    the views, colour bar) is drawn by matplotlib once; each mode's views and title are put in it."""
    from PIL import Image, ImageDraw  # heavy: Pillow (pictures only; matplotlib's own dependency)

    frame, boxes, (tx, ty) = _frame(9.0, 6.2)
    font = _font(13)
    for k, ((png, thumb), title) in enumerate(zip(paths, titles)):
        full, vmax = scales(shapes.u_re[k], shapes.u_im[k], shapes.un_re[k], shapes.un_im[k])
        rgb = frame.copy()
        views = []
        for r, (u, un) in enumerate(((shapes.u_re[k], shapes.un_re[k]), (shapes.u_im[k], shapes.un_im[k]))):
            x = deformed(shapes.points, u, full)
            for c, (_, elev, azim) in enumerate(VIEWS):
                x0, y0, w, h = boxes[r][c]
                views.append(raster(x, shapes.triangles, un, vmax, view_matrix(elev, azim), (w, h)))
                rgb[y0:y0 + h, x0:x0 + w] = views[-1]
        img = Image.fromarray(rgb)
        draw = ImageDraw.Draw(img)
        try:
            draw.text((tx, ty), title, fill=(0, 0, 0), font=font, anchor="mm")
        except ValueError:                     # Pillow's bitmap font takes no anchor
            draw.text((10, ty - 6), title, fill=(0, 0, 0), font=font)
        with atomic_path(png) as tmp:          # a fast PNG compression: 2x larger files, 4x less time
            img.save(tmp, format="PNG", compress_level=1)
        small = Image.fromarray(views[1])      # the oblique view of the real part
        small.thumbnail(THUMB_PX, Image.LANCZOS)
        with atomic_path(thumb) as tmp:
            small.save(tmp, format="PNG", compress_level=1)
