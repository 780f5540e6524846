"""Mode pictures without the finite-element stack (fem_squeal.app.mode_shapes, shape_pictures, viewer,
and the CSV of every plot): on a box of tetrahedra,

- the outer surface is the box's boundary, outward (∮ x·n dA = 3V) and independent of the numbering
  of the nodes and cells (another rank count numbers them otherwise): the picture data are equal;
- the normalisation does not depend on the eigenvector's arbitrary complex factor;
- the picture data are the field's values, and the rendered colour's extreme sits where the field's is;
- a plot's CSV holds the points it draws.
"""
from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

from fem_squeal.app import mode_shapes as ms
from fem_squeal.app import shape_pictures as sp

#: the six tetrahedra of a hexahedron (corners 0-7, x fastest), all of one orientation
HEX_TETS = np.array([[0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]])


def box(nx=4, ny=3, nz=2, size=(1.0, 0.6, 0.2)):
    """Tetrahedra filling [0, size] (points, cells)."""
    g = [np.linspace(0.0, s, n + 1) for s, n in zip(size, (nx, ny, nz))]
    X, Y, Z = np.meshgrid(*g, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    idx = np.arange(len(pts)).reshape(nx + 1, ny + 1, nz + 1)
    cells = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                c = [idx[i + a, j + b, k + d] for d in (0, 1) for b in (0, 1) for a in (0, 1)]
                cells += [[c[t] for t in tet] for tet in HEX_TETS]
    return pts, np.array(cells)


def bump(pts, centre=(0.8, 0.45)):
    """A displacement along z peaked at ``centre`` of the top face (and its complex partner)."""
    r2 = (pts[:, 0] - centre[0]) ** 2 + (pts[:, 1] - centre[1]) ** 2
    w = np.exp(-r2 / 0.02) * pts[:, 2] / pts[:, 2].max()
    re = np.zeros_like(pts)
    re[:, 2] = w
    im = np.zeros_like(pts)
    im[:, 0] = 0.3 * w
    return re, im


def test_the_surface_is_the_boundary_outwards():
    pts, cells = box()
    s = ms.outer_surface(pts, cells)
    assert len(s.triangles) == 2 * 2 * (4 * 3 + 4 * 2 + 3 * 2)
    a, b, c = (s.points[s.triangles[:, k]] for k in range(3))
    n2a = np.cross(b - a, c - a)                        # normal times twice the area
    flux = np.einsum("ij,ij->", (a + b + c) / 3, n2a) / 2   # ∮ x·n dA = 3 V (exact on flat faces)
    assert flux == pytest.approx(3 * 1.0 * 0.6 * 0.2, rel=1e-12)
    assert len(s.points) == len(np.unique(s.triangles))


def test_the_surface_of_hexahedra():
    pts, tets = box()
    s = ms.outer_surface(pts, _vtk_hexes(), kind="hexahedron")
    assert len(s.triangles) == 2 * 2 * (4 * 3 + 4 * 2 + 3 * 2)
    a, b, c = (s.points[s.triangles[:, k]] for k in range(3))
    assert np.einsum("ij,ij->", (a + b + c) / 3, np.cross(b - a, c - a)) / 2 == pytest.approx(3 * 0.12, rel=1e-12)
    with pytest.raises(ValueError, match="'wedge' are not drawn"):
        ms.outer_surface(pts, tets, kind="wedge")


def _vtk_hexes(nx=4, ny=3, nz=2):
    idx = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nx + 1, ny + 1, nz + 1)
    return np.array([[idx[i + a, j + b, k + d] for d, b, a in ((0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0),
                                                               (1, 0, 0), (1, 0, 1), (1, 1, 1), (1, 1, 0))]
                     for i in range(nx) for j in range(ny) for k in range(nz)])


def test_a_large_surface_is_decimated():
    pts, cells = box(20, 12, 2)
    full = ms.outer_surface(pts, cells)
    s = ms.outer_surface(pts, cells, max_triangles=300)
    assert 50 < len(s.triangles) <= 300 < len(full.triangles)
    assert np.allclose(s.points.min(axis=0), 0.0, atol=0.1)
    assert np.allclose(s.points.max(axis=0), [1.0, 0.6, 0.2], atol=0.1)
    # the clusters' values are their nodes' means: a linear field stays linear at the cluster centres
    values = ms.surface_values(s, pts @ np.array([1.0, 2.0, 3.0]))
    assert np.allclose(values, s.points @ np.array([1.0, 2.0, 3.0]), atol=1e-12)


def test_the_picture_data_do_not_depend_on_the_numbering():
    pts, cells = box()
    re, im = bump(pts)
    one = ms.mode_shapes(pts, cells, {"mode_0_re": re, "mode_0_im": im}, [0])
    rng = np.random.default_rng(3)
    perm = rng.permutation(len(pts))           # new number of each old node
    inv = np.argsort(perm)
    cells2 = perm[cells][rng.permutation(len(cells))]
    cells2 = np.array([np.roll(c, 0) for c in cells2])
    # the eigenvector of another run: any complex factor
    f = 2.7 * np.exp(1.1j)
    u2 = (re + 1j * im)[inv] * f
    two = ms.mode_shapes(pts[inv], cells2, {"mode_0_re": u2.real, "mode_0_im": u2.imag}, [0])
    for k in ("points", "triangles"):
        assert np.array_equal(getattr(one, k), getattr(two, k))
    for k in ("u_re", "u_im", "un_re", "un_im"):
        assert np.allclose(getattr(one, k), getattr(two, k), atol=1e-6)


def test_the_picture_shows_the_field():
    pts, cells = box(20, 12, 2)
    re, im = bump(pts)
    shapes = ms.mode_shapes(pts, cells, {"mode_0_re": re, "mode_0_im": im}, [0])
    # the data: unit peak, the largest component real and positive; the normal displacement of a
    # top triangle is the mean of its corners' u_z (normal +z)
    u = shapes.u_re[0] + 1j * shapes.u_im[0]
    assert np.sqrt((np.abs(u) ** 2).sum(axis=1)).max() == pytest.approx(1.0, rel=1e-6)
    top = np.all(shapes.points[shapes.triangles][:, :, 2] == 0.2, axis=1)
    assert np.allclose(shapes.un_re[0][top], shapes.u_re[0][shapes.triangles[top], 2].mean(axis=1), atol=1e-6)
    expected = re[:, 2] / np.sqrt((re ** 2 + im ** 2).sum(axis=1)).max()    # unit peak |u|
    lookup = {tuple(p): v for p, v in zip(pts.round(9), expected)}
    mine = np.array([lookup[tuple(p)] for p in shapes.points.astype(float).round(6).round(9)])
    assert np.allclose(shapes.u_re[0][:, 2], mine, atol=1e-6)
    # the picture along the axis: its colours read back through the colour map (the top face is
    # flat: shade ~1); the largest values sit over the bump's centre, no negative value anywhere
    vmax = float(shapes.un_re[0].max())
    img = sp.raster(sp.deformed(shapes.points, shapes.u_re[0], 1.0), shapes.triangles, shapes.un_re[0], vmax,
                    sp.view_matrix(90.0, -90.0), size=(200, 120)).astype(float)
    assert img.std() > 10                                            # not blank
    levels = np.linspace(-1.0, 1.0, 81)
    ramp = 255 * sp.colours(levels, 1.0)
    inside = np.any(img < 250, axis=2)
    value = levels[np.argmin(((img[inside][:, None, :] - ramp[None]) ** 2).sum(axis=2), axis=1)]
    assert value.min() > -0.1 and value.max() > 0.8
    y, x = np.nonzero(inside)
    hot = value > 0.8 * value.max()
    # the box fills 0.94 of the width (1.0 m), centred: the pixel of x = 0.8 m, y = 0.45 m (rows down)
    scale = 0.94 * min(200 / 1.0, 120 / 0.6)
    px, py = 100 + scale * (0.8 - 0.5), 60 - scale * (0.45 - 0.3)
    assert abs(x[hot].mean() - px) < 6 and abs(y[hot].mean() - py) < 6, (x[hot].mean(), y[hot].mean(), px, py)


def test_mode_choice_and_files(tmp_path):
    pts, cells = box()
    re, im = bump(pts)
    rows = [{"index": j, "freq_hz": 100.0 * (j + 1), "real_part": rp, "unstable": rp > 0}
            for j, rp in enumerate([-1.0, 5.0, -2.0, 9.0])]
    assert ms.chosen_modes(rows) == [3, 1]
    assert ms.chosen_modes([dict(r, unstable=False) for r in rows]) == [0, 1, 2]
    rows[1]["unstable"] = False
    fields = {f"mode_{j}_{p}": x for j in range(4) for p, x in (("re", re), ("im", im))}
    info = ms.write_mode_shapes(tmp_path, (pts, cells, "tetra", fields), rows, "box")
    assert info["modes"] == [3] and info["triangles"] == 104
    shapes = ms.ModeShapes.load(tmp_path / ms.NPZ)
    for j in (3,):
        png = tmp_path / "mode_shapes" / f"mode_{j}.png"
        assert png.stat().st_size > 10_000 and (tmp_path / "mode_shapes" / f"mode_{j}_thumb.png").is_file()
        tri = np.loadtxt(tmp_path / "mode_shapes" / "surface_triangles.csv", delimiter=",", skiprows=1)
        un = np.loadtxt(tmp_path / "mode_shapes" / f"mode_{j}_triangles.csv", delimiter=",", skiprows=1)
        k = info["modes"].index(j)
        assert np.array_equal(tri.astype(int), shapes.triangles)
        assert np.allclose(un[:, 0], shapes.un_re[k], atol=1e-6)
    from PIL import Image

    img = np.asarray(Image.open(tmp_path / "mode_shapes" / "mode_3.png").convert("L"), dtype=float)
    assert img.std() > 10


def test_viewer_data_round_trip():
    from fem_squeal.app.viewer import viewer_html

    pts, cells = box()
    re, im = bump(pts)
    shapes = ms.mode_shapes(pts, cells, {"mode_0_re": re, "mode_0_im": im}, [0])
    html = viewer_html(shapes, ["mode 0 <test>"])
    assert not re_url.search(html)
    block = html.split('id="viewer-data">', 1)[1].split("</script>", 1)[0]
    data = json.loads(block)
    import base64

    assert np.array_equal(np.frombuffer(base64.b64decode(data["points"]), "<f4").reshape(-1, 3), shapes.points)
    assert np.array_equal(np.frombuffer(base64.b64decode(data["modes"][0]["re"]), "<f4").reshape(-1, 3),
                          shapes.u_re[0])
    assert data["modes"][0]["label"] == "mode 0 <test>" and "<test>" not in block


re_url = re.compile(r"https?://")


def test_every_plot_writes_its_data(tmp_path):
    from fem_squeal.app import plots

    w = 2j * np.pi
    lam = np.array([[-1 + w * 1000, 3 + w * 2000], [-2 + w * 1100, 4 + w * 2100]])
    plots.complex_plane(tmp_path / "cp.png", lam, (0.0, 5000.0))
    with open(tmp_path / "cp.csv") as f:
        rows = list(csv.DictReader(f))
    got = sorted((float(r["x"]), float(r["y"])) for r in rows)
    assert np.allclose(got, sorted((z.real, z.imag / (2 * np.pi)) for z in lam.ravel()))
    plots.stability_maps(tmp_path / "m.png", np.array([0.1, 0.2]), np.array([1.0, 2.0, 3.0]),
                         np.arange(6).reshape(1, 3, 2), np.arange(6).reshape(3, 2), [(0.0, 1000.0)], "E")
    with open(tmp_path / "m.csv") as f:
        rows = list(csv.DictReader(f))
    first = [(float(r["x"]), float(r["y"]), float(r["value"])) for r in rows if r["panel"] == "0"]
    assert sorted(first) == sorted((mu, E, 2 * i + j) for i, E in enumerate([1.0, 2.0, 3.0])
                                   for j, mu in enumerate([0.1, 0.2]))
    rec = {"index": 2, "freq_hz": 1000.0, "real_part": 3.0, "near_coalescence": False,
           "rel_d_real_part": {"mu": 2.0, "E": -1.0}, "rel_d_freq_hz": {"mu": 5.0, "E": 7.0}}
    plots.tornado(tmp_path / "t.png", rec)
    with open(tmp_path / "t.csv") as f:
        rows = list(csv.DictReader(f))
    assert {(r["panel"], r["series"], float(r["x"])) for r in rows} == {
        ("0", "mu", 2.0), ("0", "E", -1.0), ("1", "mu", 5.0), ("1", "E", 7.0)}
