"""Pictures of mode shapes (rank 0): the deformed outer surface coloured by the normal displacement,
in an orthographic projection, by the painter's algorithm: the triangles that face the viewer are
filled far ones first, each shaded by the cosine between its normal and the view direction so that
the shape reads in three dimensions.

The triangles are filled by Pillow's ``ImageDraw.polygon`` at twice the resolution and the image
reduced (anti-aliasing): the 7k triangles of a view of the brake corner in 30 ms, where
matplotlib's ``PolyCollection`` makes one ``Path`` object per triangle (0.7 s per view at 20k).
The views are then put into a frame (the views' titles, the colour bar) drawn once for all the
modes, with matplotlib's colour map and font but not its pyplot (1 s to import and lay out).

Views: along the axis (z, the disc's axis: the builders' convention) and an oblique view (30° above
the disc's plane, azimuth −120°: the brake corner's caliper behind the disc).  Scales
(:func:`scales`): the 98th percentile of |u| is drawn as :data:`DEFORMATION` of the largest extent,
that of |u_n| as the end of the colour scale."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_squeal.util.atomic import atomic_path

#: displacement drawn where |u| is its PERCENTILEth percentile, as a share of the largest extent
DEFORMATION = 0.05
PERCENTILE = 98.0
#: (name, elevation, azimuth) of the views [deg]; elevation 90: along the axis
VIEWS = (("along the axis", 90.0, -90.0), ("oblique", 30.0, -120.0))
COLOURMAP = "RdBu_r"
SUPERSAMPLE = 2
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
    percentile of |u| at the points and of |u_n| over the triangles (both parts), at least a tenth of
    the largest.  A mode's peak sits often at a corner of a small part (a backplate's edge): scaled
    by it, the rest would be grey."""
    mag = np.sqrt((u_re ** 2).sum(axis=1) + (u_im ** 2).sum(axis=1))
    un = np.abs(np.concatenate([un_re, un_im]))
    # at least a tenth of the largest: where few triangles move normally (a bar's end faces under a
    # longitudinal mode) the percentile is round-off
    return tuple(max(float(np.percentile(v, PERCENTILE)), 0.1 * float(v.max())) or 1.0 for v in (mag, un))


def deformed(points: np.ndarray, u: np.ndarray, full: float) -> np.ndarray:
    """``points`` displaced by u drawn at :data:`DEFORMATION` of the largest extent where |u| = full,
    each displacement clipped at 2 full (a local peak does not tear the picture)."""
    u = np.asarray(u, dtype=float)
    mag = np.linalg.norm(u, axis=1)
    clip = np.minimum(1.0, 2.0 * full / np.maximum(mag, 1e-300))
    return points + (DEFORMATION * np.ptp(points, axis=0).max() / full) * u * clip[:, None]


def _frame(width: int = 720, height: int = 500):
    """The picture without its views and title, drawn once (Pillow; matplotlib's pyplot, 1 s to
    import and lay out, is not needed): (RGB array, the views' pixel boxes [[(x0, y0, w, h)]] by row
    (real, imaginary) and column (:data:`VIEWS`), the title's centre)."""
    from PIL import Image, ImageDraw  # heavy: Pillow (pictures only; matplotlib's own dependency)

    img = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    small = _font(11)
    top, sub, bar_w = 34, 18, 110
    w = (width - bar_w - 12) // 2
    h = (height - top - 2 * sub - 6) // 2
    boxes = []
    for r, name in enumerate(("real part", "imaginary part")):
        y0 = top + sub + r * (h + sub)
        boxes.append([(6 + c * (w + 6), y0, w, h) for c in range(2)])
        for (x0, _, _, _), (view, _, _) in zip(boxes[-1], VIEWS):
            _text(draw, (x0 + w / 2, y0 - sub / 2), f"{name}, {view}", small)
    x0, y0, bh = width - bar_w + 14, top + 60, height - top - 130
    ramp = np.round(255 * colours(np.linspace(1.0, -1.0, bh), 1.0)).astype(np.uint8)
    rgb = np.asarray(img).copy()
    rgb[y0:y0 + bh, x0:x0 + 16] = ramp[:, None, :]
    img = Image.fromarray(rgb)
    draw = ImageDraw.Draw(img)
    draw.rectangle([x0 - 1, y0 - 1, x0 + 16, y0 + bh], outline=(0, 0, 0))
    for t in (-1.0, -0.5, 0.0, 0.5, 1.0):
        y = y0 + (1.0 - t) / 2 * (bh - 1)
        draw.line([x0 + 16, y, x0 + 20, y], fill=(0, 0, 0))
        draw.text((x0 + 23, y - 6), f"{t:g}", fill=(0, 0, 0), font=small)
    label = Image.new("RGB", (bh, 16), (255, 255, 255))
    _text(ImageDraw.Draw(label), (bh / 2, 8), f"normal displacement / its {PERCENTILE:g}th percentile", small)
    img.paste(label.rotate(90, expand=True), (x0 + 54, y0))
    return np.asarray(img).copy(), boxes, (width / 2, top / 2)


def _text(draw, centre, text: str, font) -> None:
    """``text`` centred at ``centre`` (Pillow's bitmap font, without anchors: from its left end)."""
    try:
        draw.text(centre, text, fill=(0, 0, 0), font=font, anchor="mm")
    except ValueError:
        draw.text((centre[0] - 3 * len(text), centre[1] - 6), text, fill=(0, 0, 0), font=font)


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
    the views, colour bar) is drawn once; each mode's views and title are put in it."""
    from PIL import Image, ImageDraw  # heavy: Pillow (pictures only; matplotlib's own dependency)

    frame, boxes, (tx, ty) = _frame()
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
        _text(ImageDraw.Draw(img), (tx, ty), title, font)
        with atomic_path(png) as tmp:          # a fast PNG compression: 2x larger files, 4x less time
            img.save(tmp, format="PNG", compress_level=1)
        small = Image.fromarray(views[1])      # the oblique view of the real part
        small.thumbnail(THUMB_PX, Image.LANCZOS)
        with atomic_path(thumb) as tmp:
            small.save(tmp, format="PNG", compress_level=1)
