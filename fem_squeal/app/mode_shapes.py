"""Mode shapes on the outer surface, for the report's pictures and its 3-D view.

The complex modes' fields, gathered on rank 0 by :func:`fem_squeal.fe.output.write_vtu` (points =
the mesh's coordinate nodes, cells in VTK order), are reduced to what a picture needs:

- the **surface**: the boundary faces of the cells, tetrahedra or hexahedra (faces that belong to
  one cell only; the faces of parts that touch through an interface are boundary faces of each),
  drawn by their corner triangles (a curved P2 face as its flat corner triangle, a quadrilateral as
  two), oriented outwards; above
  :data:`MAX_TRIANGLES` the surface is decimated by vertex clustering on a uniform grid;
- the **vertices in a canonical order** (sorted by coordinates, ties by the mean of their neighbours)
  and the triangles sorted, so that the data do not depend on the rank count (the global numbering
  of the nodes does);
- each mode u = a + i b **normalised** on the surface: multiplied by the phase that makes the
  largest component of the point with the largest |u| real and positive, and scaled to unit peak
  |u| there.  The phase that maximises ‖Re(e^{iφ}u)‖ would be the textbook choice, but it is
  undetermined for a travelling wave (a·a = b·b, a·b = 0: the Ryzhik ring's unstable modes), where
  the two rank counts' eigenvectors, equal up to a factor, would be drawn turned; for a standing
  wave both choices give the same real shape.  The normal displacement u·n of each triangle: the
  mean of its corners' u on its normal.

Which modes: the unstable ones ranked by growth rate Re λ (at most :data:`MAX_MODES`); without an
unstable mode the first :data:`FIRST_FEW`.  Files (published with the field files: not with
``--no-fields``): ``mode_shapes.npz`` (points, triangles, modes, u_re, u_im, un_re, un_im in
float32) and per mode ``mode_shapes/mode_<j>.png`` (two views of the real and imaginary parts),
``mode_shapes/mode_<j>_thumb.png`` and the data of the pictures as CSV: ``surface_points.csv``
(x, y, z) and ``surface_triangles.csv`` (corners, from 0), and per mode ``mode_<j>_points.csv``
(the displacement of each point) and ``mode_<j>_triangles.csv`` (the normal displacement of each
triangle: its colour).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem_squeal.util.atomic import write_csv_atomic, write_npz_atomic

#: at most this many unstable modes are drawn (the fastest-growing)
MAX_MODES = 8
#: modes drawn when none is unstable (the lowest in the band)
FIRST_FEW = 3
#: the surface is decimated above this many triangles (a picture and the 3-D view stay light)
MAX_TRIANGLES = 40000
NPZ = "mode_shapes.npz"
FOLDER = "mode_shapes"
#: the faces of a cell by their corners (VTK node order: the corners come first), per number of
#: corners: a tetrahedron's four triangles, a hexahedron's six quadrilaterals
_FACES = {4: np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]),
          8: np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])}
#: corners of the VTK cell types (meshio names)
CORNERS = {"tetra": 4, "tetra10": 4, "hexahedron": 8, "hexahedron20": 8, "hexahedron27": 8}


@dataclass
class Surface:
    """The outer surface: ``points`` (n, 3), ``triangles`` (m, 3) into points, outward, and
    ``nodes``: the indices of its points among the gathered mesh points; after clustering, ``nodes``
    are the original surface nodes and ``members`` maps each to its point (-1: in no triangle left)."""
    points: np.ndarray
    triangles: np.ndarray
    nodes: np.ndarray
    members: np.ndarray | None = None


def boundary_triangles(points: np.ndarray, cells: np.ndarray, kind: str = "tetra") -> np.ndarray:
    """Corner triangles of the faces that belong to one cell only (a quadrilateral face as two),
    oriented outwards (their normal points away from the cell's centre); ``kind``: the meshio cell
    type (:data:`CORNERS`)."""
    if kind not in CORNERS:
        raise ValueError(f"mode pictures: cells of type {kind!r} are not drawn (types: {sorted(CORNERS)})")
    n = CORNERS[kind]
    corners = np.asarray(cells)[:, :n].astype(np.int64)
    table = _FACES[n]
    faces = corners[:, table].reshape(-1, table.shape[1])
    centre = np.repeat(points[corners].mean(axis=1), len(table), axis=0)
    _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    keep = first[counts == 1]
    faces, centre = faces[keep], centre[keep]
    if faces.shape[1] == 4:          # a quadrilateral: the triangles (0, 1, 2) and (0, 2, 3)
        faces = np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
        centre = np.concatenate([centre, centre])
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), centre - a) > 0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return faces


def _canonical(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order of the points (by coordinates, ties by the mean of their triangles' corners) and the
    triangles renumbered by it, each starting at its smallest corner (orientation kept) and sorted.
    The coordinates are compared on a grid of 1e-9 of the extent: the mesh's nodes on 1 and 2 ranks
    differ by round-off (a node on the plane y = 0 at y = 3.5620e-16 or 3.5610e-16)."""
    n = len(points)
    nb = np.zeros((n, 3))
    np.add.at(nb, triangles.ravel(), np.repeat(points[triangles].mean(axis=1), 3, axis=0))
    nb /= np.maximum(np.bincount(triangles.ravel(), minlength=n), 1)[:, None]
    tol = 1e-9 * (float(np.ptp(points, axis=0).max()) or 1.0)
    p, q = np.round(points / tol), np.round(nb / tol)
    order = np.lexsort((q[:, 2], q[:, 1], q[:, 0], p[:, 2], p[:, 1], p[:, 0]))
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n)
    t = rank[triangles]
    shift = np.argmin(t, axis=1)
    t = np.take_along_axis(t, (shift[:, None] + np.arange(3)) % 3, axis=1)
    t = t[np.lexsort((t[:, 2], t[:, 1], t[:, 0]))]
    return order, t


def outer_surface(points: np.ndarray, cells: np.ndarray, max_triangles: int = MAX_TRIANGLES,
                  kind: str = "tetra") -> Surface:
    """The outer surface of a mesh of ``kind`` cells (module docstring), at most ``max_triangles``."""
    tri = boundary_triangles(points, cells, kind)
    nodes, local = np.unique(tri, return_inverse=True)
    local = local.reshape(-1, 3)
    xyz = points[nodes]
    if len(local) <= max_triangles:
        order, t = _canonical(xyz, local)
        return Surface(xyz[order], t, nodes[order])
    return _clustered(xyz, local, nodes, max_triangles)


def _clustered(xyz: np.ndarray, tri: np.ndarray, nodes: np.ndarray, max_triangles: int) -> Surface:
    """Vertex clustering: the surface nodes merged per cell of a uniform grid (each cluster at the
    mean of its nodes, its values their mean), triangles that collapse dropped; the grid is
    coarsened by 1.25 until at most ``max_triangles`` are left."""
    lo = xyz.min(axis=0)
    edge = np.linalg.norm(xyz[tri[:, 1]] - xyz[tri[:, 0]], axis=1).mean()
    h = edge * np.sqrt(len(tri) / max_triangles)      # the count goes as 1/h²: a first guess
    while True:
        cell = np.floor((xyz - lo) / h).astype(np.int64)
        _, cluster = np.unique(cell, axis=0, return_inverse=True)
        cluster = cluster.ravel()
        t = cluster[tri]
        ok = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
        t = np.unique(t[ok], axis=0)   # the same triangle from several: once
        if len(t) <= max_triangles:
            break
        h *= 1.25
    k = cluster.max() + 1
    count = np.bincount(cluster, minlength=k).astype(float)
    centre = np.stack([np.bincount(cluster, xyz[:, d], minlength=k) for d in range(3)], axis=1) / count[:, None]
    used, t = np.unique(t, return_inverse=True)
    t = t.reshape(-1, 3)
    order, t = _canonical(centre[used], t)
    keep = used[order]                                   # cluster of each new point
    new_of_cluster = np.full(k, -1)
    new_of_cluster[keep] = np.arange(len(keep))
    return Surface(centre[keep], t, nodes, new_of_cluster[cluster])


def surface_values(surface: Surface, rows: np.ndarray) -> np.ndarray:
    """Values of a gathered field (rows of the mesh points) at the surface's points."""
    v = rows[surface.nodes]
    if surface.members is None:
        return v
    sel = surface.members >= 0
    n = len(surface.points)
    count = np.bincount(surface.members[sel], minlength=n).astype(float)
    total = np.zeros((n, *v.shape[1:]))
    np.add.at(total, surface.members[sel], v[sel])
    return total / count.reshape(-1, *([1] * (v.ndim - 1)))


def face_normals(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit normals of the triangles (outward for the surface's orientation)."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    return n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]


def normal_displacement(u: np.ndarray, points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """u_n of each triangle: the mean of its corners' displacements on its unit normal (per face, so
    that the side faces of a sharp edge are not coloured by the edge's averaged normal)."""
    return np.einsum("...mi,mi->...m", u[..., triangles, :].mean(axis=-2), face_normals(points, triangles))


def normalised(re: np.ndarray, im: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """u = re + i im (n, 3) times c = (|u_pd| / u_pd) / |u_p| (module docstring): p the point of the
    largest |u|, d its largest component; then u_pd is real and positive and the peak |u_p| is 1."""
    u = np.asarray(re, dtype=float) + 1j * np.asarray(im, dtype=float)
    mag = (np.abs(u) ** 2).sum(axis=1)
    p = int(np.argmax(mag))
    d = int(np.argmax(np.abs(u[p])))
    if mag[p] == 0.0:
        return u.real, u.imag
    u = u * (abs(u[p, d]) / u[p, d]) / np.sqrt(mag[p])
    return u.real, u.imag


def chosen_modes(rows: list[dict]) -> list[int]:
    """Indices of the modes to draw: the unstable ones by decreasing growth rate (at most
    :data:`MAX_MODES`), or the first :data:`FIRST_FEW` when none is unstable."""
    bad = sorted((r for r in rows if r.get("unstable")), key=lambda r: -r["real_part"])
    return [r["index"] for r in bad[:MAX_MODES]] if bad else [r["index"] for r in rows[:FIRST_FEW]]


@dataclass
class ModeShapes:
    """What ``mode_shapes.npz`` holds: the surface, and per drawn mode its normalised displacement at
    the points (k, n, 3) and normal displacement of the triangles (k, m), real and imaginary parts."""
    points: np.ndarray
    triangles: np.ndarray
    modes: np.ndarray
    u_re: np.ndarray
    u_im: np.ndarray
    un_re: np.ndarray
    un_im: np.ndarray

    def save(self, path: Path) -> None:
        write_npz_atomic(path, {k: getattr(self, k) for k in self.__dataclass_fields__})

    @classmethod
    def load(cls, path: Path) -> ModeShapes:
        with np.load(path) as z:
            return cls(**{k: z[k] for k in cls.__dataclass_fields__})


def mode_shapes(points: np.ndarray, cells: np.ndarray, fields: dict[str, np.ndarray], modes: list[int],
                max_triangles: int = MAX_TRIANGLES, kind: str = "tetra") -> ModeShapes:
    """The surface data of ``modes`` from the gathered mesh and fields ``mode_<j>_re``/``_im``."""
    s = outer_surface(points, cells, max_triangles, kind)
    parts = [normalised(surface_values(s, fields[f"mode_{j}_re"]), surface_values(s, fields[f"mode_{j}_im"]))
             for j in modes]
    re = np.array([p[0] for p in parts]).reshape(len(modes), len(s.points), 3)
    im = np.array([p[1] for p in parts]).reshape(len(modes), len(s.points), 3)
    f32 = np.float32
    return ModeShapes(s.points.astype(f32), s.triangles.astype(np.int32), np.array(modes, dtype=np.int32),
                      re.astype(f32), im.astype(f32), normal_displacement(re, s.points, s.triangles).astype(f32),
                      normal_displacement(im, s.points, s.triangles).astype(f32))


def write_mode_shapes(work: Path, gathered: tuple, rows: list[dict], title: str = "") -> dict:
    """``mode_shapes.npz``, the pictures and their CSV (rank 0) from what :func:`write_vtu` gathered;
    returns {"modes": [...], "triangles", "points", "seconds_per_mode"} for results.json."""
    from fem_squeal.app import shape_pictures  # heavy: matplotlib (pictures only)

    points, cells, kind, fields = gathered
    modes = chosen_modes(rows)
    if not modes:
        return {"modes": []}
    t0 = time.perf_counter()
    shapes = mode_shapes(points, cells, fields, modes, kind=kind)
    shapes.save(work / NPZ)
    t1 = time.perf_counter()
    folder = work / FOLDER
    by_index = {r["index"]: r for r in rows}
    titles = [f"mode {j}: {by_index[j]['freq_hz']:.0f} Hz, Re λ = {by_index[j]['real_part']:.3g} 1/s"
              + (" (unstable)" if by_index[j].get("unstable") else "") + (f"  {title}" if title else "")
              for j in modes]
    shape_pictures.mode_pictures(
        shapes, [(folder / f"mode_{j}.png", folder / f"mode_{j}_thumb.png") for j in modes], titles)
    write_csv_atomic(folder / "surface_points.csv", ["x", "y", "z"], list(shapes.points.T), fmt="%.7g")
    write_csv_atomic(folder / "surface_triangles.csv", ["a", "b", "c"], list(shapes.triangles.T), fmt="%d")
    for k, j in enumerate(modes):
        write_csv_atomic(folder / f"mode_{j}_points.csv", ["ux_re", "uy_re", "uz_re", "ux_im", "uy_im", "uz_im"],
                         [*shapes.u_re[k].T, *shapes.u_im[k].T], fmt="%.6g")
        write_csv_atomic(folder / f"mode_{j}_triangles.csv", ["un_re", "un_im"],
                         [shapes.un_re[k], shapes.un_im[k]], fmt="%.6g")
    t2 = time.perf_counter()
    return {"modes": modes, "points": len(shapes.points), "triangles": len(shapes.triangles),
            "surface_seconds": t1 - t0, "seconds_per_mode": (t2 - t1) / len(modes)}
