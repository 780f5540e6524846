"""Small structured meshes of hexahedra, wedges, pyramids and tetrahedra written as Abaqus decks:
the inputs of the split's verification (``tests/test_mesh_hex*.py``, ``benchmarks/hex_plate.py``).

- :func:`mixed_block`: a box of hexahedra in which some cells are two wedges, six pyramids around a
  centre node, or tetrahedra (faces shared with hexahedra, wedges and pyramids), optionally with
  shuffled node numbers and moved interior nodes, linear or quadratic (straight edges);
- :func:`annular_plate_hex20`: a ring r_i <= r <= r_o, |z| <= h/2 of C3D20 hexahedra whose
  mid-edge nodes lie on the circles (curved geometry);
- :func:`write_inp`: an Abaqus deck of such a mesh with element sets, node sets and surfaces.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from geometry.split import local_split, quad_faces

#: meshio type -> Abaqus element type (VTK order = Abaqus order for these).
ABAQUS = {"tetra": "C3D4", "tetra10": "C3D10", "hexahedron": "C3D8", "hexahedron20": "C3D20R", "wedge": "C3D6",
          "wedge15": "C3D15", "pyramid": "C3D5", "pyramid13": "C3D13"}
_EDGES = {
    "tetra": [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)],
    "hexahedron": [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)],
    "wedge": [(0, 1), (1, 2), (2, 0), (3, 4), (4, 5), (5, 3), (0, 3), (1, 4), (2, 5)],
    "pyramid": [(0, 1), (1, 2), (2, 3), (3, 0), (0, 4), (1, 4), (2, 4), (3, 4)],
}
_QUADRATIC = {"tetra": "tetra10", "hexahedron": "hexahedron20", "wedge": "wedge15", "pyramid": "pyramid13"}


def write_inp(path: str | Path, points: np.ndarray, blocks: list[tuple[str, np.ndarray]], *,
              elsets: dict[str, np.ndarray] | None = None, nsets: dict[str, np.ndarray] | None = None,
              surfaces: dict[str, list[tuple[int, str]]] | None = None, node_ids: np.ndarray | None = None,
              elem_ids: np.ndarray | None = None, types: dict[str, str] | None = None) -> None:
    """An Abaqus deck: nodes (numbers ``node_ids``, default 1..n), one ``*ELEMENT`` block per entry
    of ``blocks`` (numbers ``elem_ids`` over the concatenated blocks, default 1..m), element sets as
    0-based element indices, node sets as node indices, surfaces as (element index, "S1".."S6");
    ``types`` overrides :data:`ABAQUS` (e.g. ``{"hexahedron20": "C3D20"}``)."""
    node_ids = np.arange(1, len(points) + 1) if node_ids is None else np.asarray(node_ids)
    total = sum(len(c) for _, c in blocks)
    elem_ids = np.arange(1, total + 1) if elem_ids is None else np.asarray(elem_ids)
    out = ["*HEADING", "fem_squeal geometry.hex_decks", "*NODE"]
    out += [f"{i}, {x!r}, {y!r}, {z!r}" for i, (x, y, z) in zip(node_ids.tolist(), np.asarray(points).tolist())]
    k = 0
    for mtype, conn in blocks:
        out.append(f"*ELEMENT, TYPE={(types or {}).get(mtype, ABAQUS[mtype])}")
        for row in np.asarray(conn):
            vals = [str(elem_ids[k])] + [str(node_ids[v]) for v in row]
            k += 1
            lines = [", ".join(vals[i:i + 15]) for i in range(0, len(vals), 15)]   # Abaqus: 16 per line
            out.append(",\n".join(lines))
    for name, idx in (elsets or {}).items():
        out.append(f"*ELSET, ELSET={name}")
        ids = elem_ids[np.asarray(idx, dtype=np.int64)]
        out += [", ".join(map(str, ids[i:i + 16].tolist())) for i in range(0, len(ids), 16)]
    for name, idx in (nsets or {}).items():
        out.append(f"*NSET, NSET={name}")
        ids = node_ids[np.asarray(idx, dtype=np.int64)]
        out += [", ".join(map(str, ids[i:i + 16].tolist())) for i in range(0, len(ids), 16)]
    for name, rows in (surfaces or {}).items():
        out.append(f"*SURFACE, NAME={name}, TYPE=ELEMENT")
        out += [f"{elem_ids[e]}, {label}" for e, label in rows]
    Path(path).write_text("\n".join(out) + "\n")


def quadratic(points: np.ndarray, blocks: list[tuple[str, np.ndarray]], curve=None):
    """The same elements with straight mid-edge nodes (shared by neighbours); ``curve`` maps the
    mid-points (k, 3) onto the true geometry if given."""
    mids: dict[tuple[int, int], int] = {}
    new: list[np.ndarray] = []
    out = []
    for mtype, conn in blocks:
        rows = []
        for row in np.asarray(conn):
            extra = []
            for a, b in _EDGES[mtype]:
                key = (min(row[a], row[b]), max(row[a], row[b]))
                if key not in mids:
                    mids[key] = len(points) + len(new)
                    new.append(0.5 * (points[key[0]] + points[key[1]]))
                extra.append(mids[key])
            rows.append(list(row) + extra)
        out.append((_QUADRATIC[mtype], np.asarray(rows, dtype=np.int64)))
    x = np.vstack([points, *new]) if new else points
    if curve is not None and new:
        x[len(points):] = curve(x[len(points):])
    return x, out


def _grid(shape, size):
    nx, ny, nz = shape
    g = np.stack(np.meshgrid(*[np.linspace(0, s, n + 1) for s, n in zip(size, shape)], indexing="ij"), -1)
    return g.reshape(-1, 3), lambda i, j, k: (i * (ny + 1) + j) * (nz + 1) + k


def mixed_block(shape=(3, 2, 2), size=(3.0, 2.0, 2.0), *, wedges=(), pyramids=(), tets=(), tet_rule="max",
                order: int = 1, seed: int | None = 0, jiggle: float = 0.15):
    """A box of ``shape`` cells; cells (i, j, k) in ``wedges`` become two wedges, in ``pyramids`` six
    pyramids on a centre node, in ``tets`` six tetrahedra around the diagonal 0-6 (``tet_rule="min"``:
    the diagonals through the smallest node numbers instead).  Interior grid nodes move by up to
    ``jiggle`` of a cell; node numbers are shuffled (``seed``; None keeps the grid order).
    Returns (points, blocks, element cell index (i, j, k) of each element, box size)."""
    rng = np.random.default_rng(seed if seed is not None else 0)
    nx, ny, nz = shape
    x, node = _grid(shape, size)
    h = np.asarray(size) / np.asarray(shape)
    inner = np.all((x > 1e-9) & (x < np.asarray(size) - 1e-9), axis=1)
    x[inner] += jiggle * h * rng.uniform(-1, 1, (inner.sum(), 3))
    perm = rng.permutation(len(x)) if seed is not None else np.arange(len(x))   # new number of old node
    blocks: dict[str, list] = {"hexahedron": [], "wedge": [], "pyramid": [], "tetra": []}
    where: dict[str, list] = {k: [] for k in blocks}
    extra = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                c = [node(i + a, j + b, k + d) for d, a, b in ((0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1),
                                                               (1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1))]
                c = [int(perm[v]) for v in c]
                cell = (i, j, k)
                if cell in wedges:
                    blocks["wedge"] += [[c[0], c[1], c[2], c[4], c[5], c[6]], [c[0], c[2], c[3], c[4], c[6], c[7]]]
                    where["wedge"] += [cell, cell]
                elif cell in pyramids:
                    centre = len(x) + len(extra)
                    extra.append(np.mean(x[np.argsort(perm)[c]], axis=0))
                    for f in ([0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]):
                        blocks["pyramid"].append([c[v] for v in f] + [centre])
                        where["pyramid"].append(cell)
                elif cell in tets:
                    if tet_rule == "min":
                        d = tuple(int(np.argmin([c[v] for v in q]) % 2) for q in quad_faces("hexahedron"))
                        local = local_split("hexahedron", d)
                        if any(8 in t for t in local):
                            raise ValueError("this numbering needs a centre node")
                    else:   # the six tetrahedra around the diagonal 0-6 (Kuhn)
                        local = [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6),
                                 (0, 5, 1, 6)]
                    for t in local:
                        blocks["tetra"].append([c[v] for v in t])
                        where["tetra"].append(cell)
                else:
                    blocks["hexahedron"].append(c)
                    where["hexahedron"].append(cell)
    pts = np.empty_like(x)
    pts[perm] = x
    if extra:
        pts = np.vstack([pts, extra])
    out = [(t, np.asarray(v, dtype=np.int64)) for t, v in blocks.items() if v]
    cells = [tuple(w) for t, v in where.items() if blocks[t] for w in v]
    # orient the tetrahedra positively (Kuhn's are, up to the jiggle)
    fixed = []
    for t, conn in out:
        if t == "tetra":
            p = pts[conn]
            v = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
            conn = np.where((v < 0)[:, None], conn[:, [0, 2, 1, 3]], conn)
        fixed.append((t, conn))
    if order == 2:
        pts, fixed = quadratic(pts, fixed)
    return pts, fixed, cells, np.asarray(size)


def annular_plate_hex20(inner_radius: float, outer_radius: float, thickness: float, n_r: int, n_theta: int,
                        n_z: int = 1):
    """C3D20 ring: points, [("hexahedron20", conn)], the element indices on the inner radius (face
    S6: nodes 4-8-5-1 lie at r_i) and on the outer one (S4)."""
    r = np.linspace(inner_radius, outer_radius, 2 * n_r + 1)
    t = np.linspace(0, 2 * np.pi, 2 * n_theta + 1)[:-1]
    z = np.linspace(-thickness / 2, thickness / 2, 2 * n_z + 1)
    nt = len(t)

    def nid(i, j, k):
        return (i * nt + j % nt) * len(z) + k

    R, T, Z = np.meshgrid(r, t, z, indexing="ij")
    pts = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(), Z.ravel()])
    conn, inner, outer = [], [], []
    # local (di, dj, dk) of the 20 nodes in C3D20 order: corners, bottom, top, vertical mid-edges
    corners = [(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0), (0, 0, 2), (2, 0, 2), (2, 2, 2), (0, 2, 2)]
    edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
    local = corners + [tuple((np.array(corners[a]) + corners[b]) // 2) for a, b in edges]
    for i in range(n_r):
        for j in range(n_theta):
            for k in range(n_z):
                conn.append([nid(2 * i + a, 2 * j + b, 2 * k + c) for a, b, c in local])
                if i == 0:
                    inner.append(len(conn) - 1)
                if i == n_r - 1:
                    outer.append(len(conn) - 1)
    used = np.unique(np.asarray(conn))
    renum = np.full(len(pts), -1)
    renum[used] = np.arange(len(used))            # drop the unused face and body centres of the grid
    return pts[used], [("hexahedron20", renum[np.asarray(conn)])], np.asarray(inner), np.asarray(outer)


def annular_plate_hex8(inner_radius: float, outer_radius: float, thickness: float, n_r: int, n_theta: int,
                       n_z: int = 1):
    """C3D8 ring of n_r x n_theta x n_z cells (corners on the circles): points, [("hexahedron", conn)],
    the element indices on the inner radius (face S6) and on the outer one (S4), as
    :func:`annular_plate_hex20`."""
    r = np.linspace(inner_radius, outer_radius, n_r + 1)
    t = np.linspace(0, 2 * np.pi, n_theta + 1)[:-1]
    z = np.linspace(-thickness / 2, thickness / 2, n_z + 1)
    R, T, Z = np.meshgrid(r, t, z, indexing="ij")
    pts = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(), Z.ravel()])

    def nid(i, j, k):
        return (i * n_theta + j % n_theta) * len(z) + k

    conn, inner, outer = [], [], []
    for i in range(n_r):
        for j in range(n_theta):
            for k in range(n_z):
                conn.append([nid(i + a, j + b, k + c) for a, b, c in _CUBE])
                if i == 0:
                    inner.append(len(conn) - 1)
                if i == n_r - 1:
                    outer.append(len(conn) - 1)
    return pts, [("hexahedron", np.asarray(conn))], np.asarray(inner), np.asarray(outer)


# ------------------------------------------------------------------------------ polar blocks, brake deck
#: Abaqus face labels: C3D20 by the grid side (i = r, j = θ, k = z) the face lies on; C3D10 by the
#: corner the face leaves out (S1 = 1-2-3, S2 = 1-4-2, S3 = 2-4-3, S4 = 3-4-1).
HEX_FACE = {"z0": "S1", "z1": "S2", "t0": "S3", "r1": "S4", "t1": "S5", "r0": "S6"}
TET_FACE = {3: "S1", 2: "S2", 0: "S3", 1: "S4"}
#: Kuhn's six tetrahedra of a cell around its diagonal (0,0,0)-(1,1,1): conforming between cells of
#: the same grid, every edge midpoint a node of the grid of half the spacing.
_CUBE = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
_KUHN = [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6)]


def polar_block(r: tuple[float, float], theta: tuple[float, float], z: tuple[float, float],
                n: tuple[int, int, int], kind: str = "hex20", mirror: bool = False):
    """A block r0 <= r <= r1, θ0 <= θ <= θ1 [rad], z0 <= z <= z1 of n = (n_r, n_θ, n_z) cells, each a
    C3D20 (``kind="hex20"``) or six C3D10 (``"tet10"``, Kuhn's split); every node, mid-edge nodes
    included, lies on the polar grid of half the spacing, so the geometry is curved exactly like the
    hexahedra's.  θ1 − θ0 = 2π closes the ring.  ``mirror`` (tet10): Kuhn's split of the cell mirrored
    in θ, around the diagonal (0,1,0)-(1,0,1): other diagonals on the r-θ and θ-z faces than the
    smallest-node rule of ``geometry.split`` gives the C3D20 of this grid.  Returns points, (meshio
    type, connectivity) and the faces on the six sides "r0", "r1", "t0", "t1", "z0", "z1" as
    [(element, Abaqus face label)]."""
    n_r, n_t, n_z = n
    ring = abs(theta[1] - theta[0] - 2 * np.pi) < 1e-12
    rr = np.linspace(*r, 2 * n_r + 1)
    tt = np.linspace(*theta, 2 * n_t + 1)[:-1 if ring else None]
    zz = np.linspace(*z, 2 * n_z + 1)
    nt = len(tt)

    def nid(i, j, k):
        return (i * nt + j % nt) * len(zz) + k

    R, T, Z = np.meshgrid(rr, tt, zz, indexing="ij")
    pts = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(), Z.ravel()])
    conn, faces = [], {s: [] for s in HEX_FACE}

    for i in range(n_r):
        for j in range(n_t):
            for k in range(n_z):
                at_side = {"r0": i == 0, "r1": i == n_r - 1, "t0": j == 0 and not ring,
                           "t1": j == n_t - 1 and not ring, "z0": k == 0, "z1": k == n_z - 1}
                g = lambda a, b, c, i=i, j=j, k=k: nid(2 * i + a, 2 * j + b, 2 * k + c)  # noqa: E731 (half grid)
                if kind == "hex20":
                    corners = [tuple(2 * np.array(c)) for c in _CUBE]
                    mids = [tuple((np.array(corners[a]) + corners[b]) // 2) for a, b in _EDGES["hexahedron"]]
                    conn.append([g(*c) for c in corners + mids])
                    for s, lab in HEX_FACE.items():
                        if at_side[s]:
                            faces[s].append((len(conn) - 1, lab))
                elif kind == "tet10":
                    cube = [(a, 1 - b, c) for a, b, c in _CUBE] if mirror else _CUBE
                    for t in _KUHN:
                        cs = [np.array(cube[v]) * 2 for v in t]
                        mids = [(cs[a] + cs[b]) // 2 for a, b in _EDGES["tetra"]]
                        conn.append([g(*c) for c in cs + mids])
                        for s, off in _tet_sides([cube[v] for v in t]):
                            if at_side[s]:
                                faces[s].append((len(conn) - 1, TET_FACE[off]))
                else:
                    raise ValueError(f"kind: hex20 or tet10 (got {kind!r})")
    conn = np.asarray(conn)
    if kind == "tet10":         # Kuhn's tetrahedra have both orientations: make them all positive
        p = pts[conn[:, :4]]
        v = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
        flip = v < 0
        # swap corners 1 <-> 2 (and the mid-edge nodes 01 <-> 02, 13 <-> 23; 12 stays)
        conn[flip] = conn[flip][:, [0, 2, 1, 3, 6, 5, 4, 7, 9, 8]]
        for s in faces:
            faces[s] = [(e, _FLIPPED[lab] if flip[e] else lab) for e, lab in faces[s]]
    used = np.unique(conn)
    renum = np.full(len(pts), -1)
    renum[used] = np.arange(len(used))
    return pts[used], ("hexahedron20" if kind == "hex20" else "tetra10", renum[conn]), faces


#: face labels of a C3D10 after swapping its corners 2 and 3 (1-based): S1 1-2-3 -> 1-3-2 (still S1),
#: S2 1-4-2 -> becomes 1-4-3 (S4's set), S3 2-4-3 -> 3-4-2 (S3), S4 3-4-1 -> 2-4-1 (S2's set)
_FLIPPED = {"S1": "S1", "S2": "S4", "S3": "S3", "S4": "S2"}


def _tet_sides(corners):
    """(side, local index of the corner off the face) for each face of the tetrahedron of the given
    cell-local corners (0/1 per axis) that lies on a side of its cell."""
    out = []
    c = np.array(corners)
    for off in range(4):
        f = np.delete(c, off, axis=0)
        for s, (ax, v) in {"r0": (0, 0), "r1": (0, 1), "t0": (1, 0), "t1": (1, 1), "z0": (2, 0),
                           "z1": (2, 1)}.items():
            if np.all(f[:, ax] == v):
                out.append((s, off))
    return out


#: The mixed-element brake of ``scenes/hex_brake_*.toml`` [m, rad]: an annular disc clamped on its
#: bore, a pad (lining) on each side over a sector, each with a steel backplate behind it.
BRAKE = dict(disc_r=(0.04, 0.12), disc_h=0.012, pad_r=(0.07, 0.115), pad_angle=np.radians(50.0),
             pad_h=0.01, backplate_h=0.005)


def brake_deck(path: str | Path, *, disc: str = "hex20", pads: str = "hex20", backplates: str = "tet10",
               mirror: bool = False,
               refine: int = 1, n_disc: tuple[int, int, int] = (3, 36, 2), n_pad: tuple[int, int, int] = (3, 6, 1),
               n_backplate: tuple[int, int, int] = (2, 5, 1), dims: dict | None = None) -> dict:
    """Abaqus deck of :data:`BRAKE`: element sets DISC, PAD_TOP, PAD_BOTTOM, BACKPLATE_TOP,
    BACKPLATE_BOTTOM and element-based surfaces DISC_BORE, DISC_TOP, DISC_BOTTOM, PAD_<side>_FRICTION,
    PAD_<side>_BACK, BACKPLATE_<side>_FRONT, BACKPLATE_<side>_BACK.  Each part is "hex20" (C3D20) or
    "tet10" (Kuhn's six C3D10 per cell of the same grid, ``mirror``: :func:`polar_block`); the parts
    have their own nodes (the pads touch the disc through contact, the backplates are tied to the
    pads).  ``refine`` multiplies
    every cell count.  Returns the element counts by type."""
    d = {**BRAKE, **(dims or {})}
    half = d["disc_h"] / 2
    a0, a1 = np.pi / 2 - d["pad_angle"] / 2, np.pi / 2 + d["pad_angle"] / 2     # pads centred on +y
    m = lambda n: tuple(int(v * refine) for v in n)  # noqa: E731
    blocks = {
        "DISC": (d["disc_r"], (0.0, 2 * np.pi), (-half, half), m(n_disc), disc),
        "PAD_TOP": (d["pad_r"], (a0, a1), (half, half + d["pad_h"]), m(n_pad), pads),
        "PAD_BOTTOM": (d["pad_r"], (a0, a1), (-half - d["pad_h"], -half), m(n_pad), pads),
        "BACKPLATE_TOP": (d["pad_r"], (a0, a1), (half + d["pad_h"], half + d["pad_h"] + d["backplate_h"]),
                          m(n_backplate), backplates),
        "BACKPLATE_BOTTOM": (d["pad_r"], (a0, a1), (-half - d["pad_h"] - d["backplate_h"], -half - d["pad_h"]),
                             m(n_backplate), backplates),
    }
    sides = {"DISC": {"DISC_BORE": "r0", "DISC_TOP": "z1", "DISC_BOTTOM": "z0"},
             "PAD_TOP": {"PAD_TOP_FRICTION": "z0", "PAD_TOP_BACK": "z1"},
             "PAD_BOTTOM": {"PAD_BOTTOM_FRICTION": "z1", "PAD_BOTTOM_BACK": "z0"},
             "BACKPLATE_TOP": {"BACKPLATE_TOP_FRONT": "z0", "BACKPLATE_TOP_BACK": "z1"},
             "BACKPLATE_BOTTOM": {"BACKPLATE_BOTTOM_FRONT": "z1", "BACKPLATE_BOTTOM_BACK": "z0"}}
    pts, by_type, elsets, surfaces = [], {}, {}, {}
    n_pts = 0
    parts = []
    for name, (r, t, z, n, kind) in blocks.items():
        x, (mtype, conn), faces = polar_block(r, t, z, n, kind, mirror)
        parts.append((name, mtype, conn + n_pts, faces))
        pts.append(x)
        n_pts += len(x)
    # one *ELEMENT block per type: element indices are positions in the concatenation of the blocks
    order = sorted({p[1] for p in parts})
    offset, start = 0, {}
    for mtype in order:
        for name, mt, conn, _ in parts:
            if mt == mtype:
                start[name] = offset
                offset += len(conn)
        by_type[mtype] = np.vstack([conn for _, mt, conn, _ in parts if mt == mtype])
    for name, _, conn, faces in parts:
        elsets[name] = start[name] + np.arange(len(conn))
        for surf, side in sides[name].items():
            surfaces[surf] = [(start[name] + e, lab) for e, lab in faces[side]]
    write_inp(path, np.vstack(pts), [(t, by_type[t]) for t in order], elsets=elsets, surfaces=surfaces)
    return {t: len(c) for t, c in by_type.items()}


def brake_gmsh(path: str | Path, mesh_size: float = 0.012, dims: dict | None = None) -> int:
    """The brake of :func:`brake_deck` meshed by gmsh with unstructured curved ten-node tetrahedra
    (an independent discretisation), written as a ``.msh`` whose physical groups carry the deck's
    element-set and surface names (so the same scene maps both).  The parts are separate volumes,
    not fragmented: their meshes have their own nodes on the shared faces, as in the deck.
    Returns the number of tetrahedra."""
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    d = {**BRAKE, **(dims or {})}
    half = d["disc_h"] / 2
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("hex_brake")
    occ = gmsh.model.occ
    try:
        outer = occ.addCylinder(0, 0, -half, 0, 0, d["disc_h"], d["disc_r"][1])
        inner = occ.addCylinder(0, 0, -half, 0, 0, d["disc_h"], d["disc_r"][0])
        (disc,), _ = occ.cut([(3, outer)], [(3, inner)])

        def sector(z0, z1):
            a = occ.addCylinder(0, 0, z0, 0, 0, z1 - z0, d["pad_r"][1], angle=d["pad_angle"])
            b = occ.addCylinder(0, 0, z0, 0, 0, z1 - z0, d["pad_r"][0], angle=d["pad_angle"])
            (v,), _ = occ.cut([(3, a)], [(3, b)])
            occ.rotate([v], 0, 0, 0, 0, 0, 1, np.pi / 2 - d["pad_angle"] / 2)     # centred on +y
            return v

        zp, zb = half + d["pad_h"], half + d["pad_h"] + d["backplate_h"]
        vols = {"DISC": disc, "PAD_TOP": sector(half, zp), "PAD_BOTTOM": sector(-zp, -half),
                "BACKPLATE_TOP": sector(zp, zb), "BACKPLATE_BOTTOM": sector(-zb, -zp)}
        occ.synchronize()
        # faces: (volume, z of the plane face, or "bore")
        want = {"DISC_BORE": ("DISC", "bore"), "DISC_TOP": ("DISC", half), "DISC_BOTTOM": ("DISC", -half),
                "PAD_TOP_FRICTION": ("PAD_TOP", half), "PAD_TOP_BACK": ("PAD_TOP", zp),
                "PAD_BOTTOM_FRICTION": ("PAD_BOTTOM", -half), "PAD_BOTTOM_BACK": ("PAD_BOTTOM", -zp),
                "BACKPLATE_TOP_FRONT": ("BACKPLATE_TOP", zp), "BACKPLATE_TOP_BACK": ("BACKPLATE_TOP", zb),
                "BACKPLATE_BOTTOM_FRONT": ("BACKPLATE_BOTTOM", -zp),
                "BACKPLATE_BOTTOM_BACK": ("BACKPLATE_BOTTOM", -zb)}
        for k, (name, v) in enumerate(vols.items(), start=1):
            gmsh.model.addPhysicalGroup(3, [v[1]], k)
            gmsh.model.setPhysicalName(3, k, name)
        for k, (name, (vol, where)) in enumerate(want.items(), start=101):
            tags = []
            for _, s in gmsh.model.getBoundary([vols[vol]], oriented=False):
                x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, s)
                flat = z1 - z0 < 1e-6
                if where == "bore":
                    if not flat and x1 - x0 < 2.01 * d["disc_r"][0]:
                        tags.append(s)
                elif flat and abs(occ.getCenterOfMass(2, s)[2] - where) < 1e-6:
                    tags.append(s)
            if not tags:
                raise RuntimeError(f"brake_gmsh: face {name} not found")
            gmsh.model.addPhysicalGroup(2, tags, k)
            gmsh.model.setPhysicalName(2, k, name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.25 * mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.model.mesh.generate(3)
        gmsh.model.mesh.setOrder(2)
        gmsh.model.mesh.optimize("HighOrderElastic")     # untangles curved elements in the thin parts
        gmsh.option.setNumber("Mesh.SaveAll", 0)
        gmsh.write(str(path))
        n = sum(len(t) for et, t in zip(*gmsh.model.mesh.getElements(3)[:2]) if et == 11)
    finally:
        gmsh.finalize()
    return n
