"""Conforming split of hexahedra, wedges and pyramids (linear and quadratic) into tetrahedra.

dolfinx 0.5.2 takes one cell type per mesh, so every volume element of a file becomes tetrahedra:

- **Face diagonals.**  Each quadrilateral face is cut along one diagonal: the one a tetrahedral
  neighbour already uses (its triangles lie on the quadrilateral), else the one through the face's
  smallest global node number.  Both rules depend on the face alone, so the two elements sharing a
  face cut it the same way: no cracks, no hanging nodes.
- **Local splits.**  For every combination of face diagonals the split of the reference element is
  found once, by an exhaustive search over the tetrahedra on its corners (interiors disjoint, volumes
  summing to the element, face-to-face inside, no tetrahedron edge on the other diagonal of a face),
  preferring the fewest tetrahedra: a hexahedron gives 5 or 6, a wedge 3, a pyramid 2 (Dompierre et
  al. 1999).  A combination with no such split (the cyclic ones; the smallest-node rule never makes
  them, tetrahedral neighbours can) takes an interior node at the element centre and a pyramid of
  two tetrahedra on every quadrilateral face (one tetrahedron per triangular face).
- **Quadratic elements keep their geometry.**  A tetrahedron edge on an element edge takes that
  edge's mid-node; one on a face diagonal takes the image of the face centre (the parametric
  mid-point of either diagonal) under the face's map -- the 9th node of a 9-node face, else the
  8-node serendipity value, a function of the face's nodes only, created once per face so that
  neighbours share it; an edge through the interior takes the element map's image of its parametric
  mid-point (shape functions from the element's polynomial space, :func:`shape_functions`).

Node orders are VTK's (meshio's): ``hexahedron`` 0-3 bottom, 4-7 top; ``hexahedron20`` mid-edges
8-11 bottom (01, 12, 23, 30), 12-15 top, 16-19 vertical (04, 15, 26, 37); ``hexahedron27`` then the
face centres -x, +x, -y, +y, -z, +z and the body centre; ``wedge`` 0-2 one triangle, 3-5 the other;
``wedge15`` mid-edges 01, 12, 20, 34, 45, 53, 03, 14, 25; ``pyramid`` base 0-3, apex 4;
``pyramid13`` 01, 12, 23, 30, 04, 14, 24, 34.  Wedges are accepted in either handedness (VTK's
reference wedge is the mirror image of gmsh's and Abaqus's); hexahedra, pyramids and tetrahedra must
have a positive Jacobian in the usual order (1-2-3-4 counter-clockwise seen from 5-6-7-8).
"""
from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, field

import numpy as np

from geometry.split_tables import SPLITS

#: meshio type -> (kind, order, nodes)
ELEMENTS = {
    "tetra": ("tetra", 1, 4), "tetra4": ("tetra", 1, 4), "tetra10": ("tetra", 2, 10),
    "hexahedron": ("hexahedron", 1, 8), "hexahedron20": ("hexahedron", 2, 20),
    "hexahedron27": ("hexahedron", 2, 27),
    "wedge": ("wedge", 1, 6), "wedge15": ("wedge", 2, 15),
    "pyramid": ("pyramid", 1, 5), "pyramid13": ("pyramid", 2, 13),
}

#: Corner coordinates of the reference elements (integers: the search below is exact).
REF = {
    "tetra": np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2]]),
    "hexahedron": np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0],
                            [0, 0, 2], [2, 0, 2], [2, 2, 2], [0, 2, 2]]),
    "wedge": np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2], [2, 0, 2], [0, 2, 2]]),
    "pyramid": np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [1, 1, 2]]),
}
#: Faces in the Abaqus order S1, S2, ... (tetrahedra as geometry.mesh_file.TET_FACES; pyramids base first).
FACES = {
    "tetra": [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]],
    "hexahedron": [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]],
    "wedge": [[0, 1, 2], [3, 5, 4], [0, 3, 4, 1], [1, 4, 5, 2], [2, 5, 3, 0]],
    "pyramid": [[0, 3, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]],
}
#: Mid-edge nodes of the quadratic elements: corner pair -> local node.
EDGES = {
    "tetra": [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)],
    "hexahedron": [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)],
    "wedge": [(0, 1), (1, 2), (2, 0), (3, 4), (4, 5), (5, 3), (0, 3), (1, 4), (2, 5)],
    "pyramid": [(0, 1), (1, 2), (2, 3), (3, 0), (0, 4), (1, 4), (2, 4), (3, 4)],
}
#: hexahedron27: the face-centre node of each face of FACES["hexahedron"] (S1..S6 = -z, +z, -y, +x, +y, -x).
HEX27_FACE_NODE = [24, 25, 22, 21, 23, 20]
HEX27_CENTRE = 26
#: tetra10 (VTK): mid-edge node of each corner pair.
TET10_MID = {(0, 1): 4, (1, 2): 5, (0, 2): 6, (0, 3): 7, (1, 3): 8, (2, 3): 9}


class SplitError(ValueError):
    """Elements that cannot be split; ``elements`` are indices into the concatenated input blocks."""

    def __init__(self, message: str, elements=()):
        super().__init__(message)
        self.elements = list(elements)


def quad_faces(kind: str) -> list[list[int]]:
    return [f for f in FACES[kind] if len(f) == 4]


# --- local splits of the reference elements ---------------------------------------------------------
def _signed6v(p: np.ndarray) -> int:
    return int(np.dot(np.cross(p[1] - p[0], p[2] - p[0]), p[3] - p[0]))


def _disjoint(p: np.ndarray, q: np.ndarray) -> bool:
    """Interiors of two tetrahedra (4x3 integer corners) disjoint: a weakly separating axis exists."""
    ep = [p[j] - p[i] for i, j in itertools.combinations(range(4), 2)]
    eq = [q[j] - q[i] for i, j in itertools.combinations(range(4), 2)]
    axes = [np.cross(a, b) for a, b in itertools.combinations(ep, 2)] + \
           [np.cross(a, b) for a, b in itertools.combinations(eq, 2)] + [np.cross(a, b) for a in ep for b in eq]
    for n in axes:
        if not n.any():
            continue
        a, b = p @ n, q @ n
        if a.max() <= b.min() or b.max() <= a.min():
            return True
    return False


@functools.cache
def _candidates(kind: str):
    ref = REF[kind]
    tets = [t for t in itertools.combinations(range(len(ref)), 4) if _signed6v(ref[list(t)]) != 0]
    compat = np.array([[i != j and _disjoint(ref[list(a)], ref[list(b)]) for j, b in enumerate(tets)]
                       for i, a in enumerate(tets)])
    return tets, compat


def _conforming(kind: str, tets) -> bool:
    """Every face of the split is a face of two of its tetrahedra or lies on a face of the element."""
    ref = REF[kind]
    count: dict = {}
    for t in tets:
        for f in itertools.combinations(sorted(t), 3):
            count[f] = count.get(f, 0) + 1
    for f, n in count.items():
        on_face = any(set(f) <= set(face) for face in FACES[kind])
        if (n != 1) if on_face else (n != 2):
            return False
    return all(_signed6v(ref[list(t)]) != 0 for t in tets)


def local_split(kind: str, diagonals: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    """The split of :func:`search_split`, from the table it generated (:mod:`geometry.split_tables`)."""

    return SPLITS[kind][tuple(diagonals)]


@functools.cache
def search_split(kind: str, diagonals: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    """Tetrahedra (local corner numbers, positively oriented; ``len(REF[kind])`` is the centre node)
    of the reference element whose quadrilateral faces (in :func:`quad_faces` order) are cut along
    the diagonal through their local corner 0 and 2 (``diagonals[f] == 0``) or 1 and 3 (``1``)."""
    ref = REF[kind]
    quads = quad_faces(kind)
    forbidden = {frozenset((q[1 - d], q[3 - d])) for q, d in zip(quads, diagonals)}
    tets, compat = _candidates(kind)
    ok = [i for i, t in enumerate(tets)
          if not any(frozenset(e) in forbidden for e in itertools.combinations(t, 2))]
    vol = {i: abs(_signed6v(ref[list(tets[i])])) for i in ok}
    total = sum(abs(_signed6v(ref[list(t)])) for t in _fan(kind, diagonals, centre=False))
    best: list = []

    def search(chosen: list, start: int, left: int):
        nonlocal best
        if best and len(chosen) >= len(best):
            return
        if left == 0:
            if _conforming(kind, [tets[i] for i in chosen]):
                best = list(chosen)
            return
        for k in range(start, len(ok)):
            i = ok[k]
            if vol[i] <= left and all(compat[i, j] for j in chosen):
                search(chosen + [i], k + 1, left - vol[i])

    search([], 0, total)
    if best:
        return tuple(_orient(ref, tets[i]) for i in best)
    return _fan(kind, diagonals, centre=True)


def _orient(ref: np.ndarray, t) -> tuple[int, ...]:
    a, b, c, d = t
    pts = np.vstack([ref, ref.mean(axis=0)])
    return (a, b, c, d) if _signed6v(pts[[a, b, c, d]].astype(float)) > 0 else (a, c, b, d)


def _face_triangles(face, d: int):
    if len(face) == 3:
        return [tuple(face)]
    a, b, c, e = face
    return [(a, b, c), (a, c, e)] if d == 0 else [(a, b, e), (b, c, e)]


def _fan(kind: str, diagonals, centre: bool) -> tuple[tuple[int, ...], ...]:
    """Tetrahedra of the face triangles with the centre (``centre``), or with corner 0 -- the
    latter only to measure the element's volume."""
    ref = REF[kind]
    apex = len(ref)
    dq = iter(diagonals)
    out = []
    for face in FACES[kind]:
        tris = _face_triangles(face, next(dq) if len(face) == 4 else 0)
        for tri in tris:
            if not centre and 0 in tri:
                continue
            out.append(_orient(ref, (*tri, apex if centre else 0)))
    return tuple(out)


# --- shape functions of the quadratic elements -------------------------------------------------------
def reference_nodes(mtype: str) -> np.ndarray:
    """Reference coordinates of all nodes of a meshio element type (corners as :data:`REF`)."""
    kind, order, n = ELEMENTS[mtype]
    ref = REF[kind].astype(float)
    if order == 1:
        return ref
    pts = [*ref, *[(ref[a] + ref[b]) / 2 for a, b in EDGES[kind]]]
    if mtype == "hexahedron27":
        centres = {HEX27_FACE_NODE[f]: ref[face].mean(axis=0) for f, face in enumerate(FACES[kind])}
        pts += [centres[i] for i in range(20, 26)] + [ref.mean(axis=0)]
    return np.array(pts)


def _monomials(mtype: str) -> list[tuple[int, int, int]]:
    if mtype == "hexahedron20":          # serendipity: superlinear degree <= 2
        return [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (2, 0, 0), (0, 2, 0), (0, 0, 2), (1, 1, 0), (0, 1, 1),
                (1, 0, 1), (2, 1, 0), (2, 0, 1), (1, 2, 0), (0, 2, 1), (1, 0, 2), (0, 1, 2), (1, 1, 1), (2, 1, 1),
                (1, 2, 1), (1, 1, 2)]
    if mtype == "hexahedron27":
        return [(i, j, k) for i in range(3) for j in range(3) for k in range(3)]
    if mtype == "wedge15":
        tri = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
        return [(i, j, k) for i, j in tri for k in (0, 1)] + [(i, j, 2) for i, j in tri[:3]]
    if mtype == "tetra10":
        return [(i, j, k) for i in range(3) for j in range(3) for k in range(3) if i + j + k <= 2]
    if ELEMENTS[mtype][1] == 1 and ELEMENTS[mtype][0] == "hexahedron":
        return [(i, j, k) for i in range(2) for j in range(2) for k in range(2)]
    if mtype == "wedge":
        return [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1)]
    raise KeyError(mtype)


@functools.cache
def _coefficients(mtype: str) -> np.ndarray:
    mons = _monomials(mtype)
    x = reference_nodes(mtype)
    v = np.array([[np.prod(p ** np.array(m)) for m in mons] for p in x])
    return np.linalg.inv(v)                       # N_a(ξ) = Σ_m ξ^m C[m, a]


def shape_functions(mtype: str, xi: np.ndarray) -> np.ndarray:
    """Values (k, n) of the nodal shape functions of ``mtype`` at reference points ``xi`` (k, 3)."""
    xi = np.atleast_2d(np.asarray(xi, dtype=float))
    mons = _monomials(mtype)
    v = np.array([[np.prod(p ** np.array(m)) for m in mons] for p in xi])
    return v @ _coefficients(mtype)


# --- the split ---------------------------------------------------------------------------------------
@dataclass
class Split:
    """Tetrahedra of a mesh of mixed elements."""

    points: np.ndarray                  # input points, then the new nodes
    cells: np.ndarray                   # (m, 4|10) VTK order
    origin: np.ndarray                  # (m,) index of the input element of each tetrahedron
    first: np.ndarray                   # (elements + 1,) tetrahedra of element e: first[e]:first[e+1]
    diagonals: dict = field(default_factory=dict)   # sorted quad corners -> diagonal (a, b) node pair
    stats: dict = field(default_factory=dict)

    def tets_of(self, elements) -> np.ndarray:
        e = np.asarray(elements, dtype=np.int64)
        if len(e) == 0:
            return np.zeros(0, np.int64)
        lo, hi = self.first[e], self.first[e + 1]
        n = hi - lo
        return np.repeat(lo - np.concatenate([[0], np.cumsum(n)[:-1]]), n) + np.arange(n.sum())

    def face_triangles(self, corners: np.ndarray) -> np.ndarray:
        """Triangles (k, 3) of faces given by corner nodes (k, 3) or (k, 4) (cyclic), quadrilaterals
        cut along the diagonal the split used (the smallest-node rule for faces it does not know)."""
        corners = np.asarray(corners, dtype=np.int64)
        if corners.shape[1] == 3:
            return corners
        d = _diagonal_choice(corners, self.diagonals)
        return _quad_triangles(corners, d)


def _quad_triangles(q: np.ndarray, d: np.ndarray) -> np.ndarray:
    a, b, c, e = q.T
    t0 = np.where(d[:, None] == 0, np.column_stack([a, b, c]), np.column_stack([a, b, e]))
    t1 = np.where(d[:, None] == 0, np.column_stack([a, c, e]), np.column_stack([b, c, e]))
    return np.stack([t0, t1], axis=1).reshape(-1, 3)


def _min_rule(q: np.ndarray) -> np.ndarray:
    """0 if the smallest node of each quadrilateral (k, 4) is its corner 0 or 2, else 1."""
    return (np.argmin(q, axis=1) % 2).astype(np.int64)


def _diagonal_choice(q: np.ndarray, forced: dict) -> np.ndarray:
    d = _min_rule(q)
    if forced:
        keys = [tuple(r) for r in np.sort(q, axis=1).tolist()]
        for i, k in enumerate(keys):
            pair = forced.get(k)
            if pair is not None:
                d[i] = 0 if {int(q[i, 0]), int(q[i, 2])} == set(pair) else 1
    return d


def _tri_keys(tris: np.ndarray, n: int) -> np.ndarray:
    s = np.sort(tris, axis=1).astype(np.int64)
    return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]


def split_mesh(points: np.ndarray, blocks: list[tuple[str, np.ndarray]]) -> Split:
    """Tetrahedra of the elements ``blocks`` [(meshio type, connectivity (k, n) of node indices)],
    all linear or all quadratic; element e of the concatenated blocks gives ``first[e]:first[e+1]``."""
    points = np.asarray(points, dtype=float)
    n_nodes = len(points)
    kinds = [ELEMENTS[t] for t, _ in blocks]
    orders = {o for _, o, _ in kinds}
    if len(orders) > 1:
        raise SplitError("mixes linear and quadratic elements; use one order")
    quadratic = orders == {2}
    sizes = [len(c) for _, c in blocks]
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)

    # repeated nodes: a collapsed element (a hexahedron written as a wedge, ...)
    for (mtype, conn), s in zip(blocks, starts):
        corners = np.sort(np.asarray(conn)[:, :len(REF[ELEMENTS[mtype][0]])], axis=1)
        bad = np.flatnonzero(np.any(corners[:, 1:] == corners[:, :-1], axis=1))
        if len(bad):
            raise SplitError(f"{len(bad)} {mtype} elements have repeated corner nodes (collapsed elements; "
                             "write them as the element type they are)", s + bad)

    # quadrilateral faces cut as a tetrahedral (or triangle-faced) neighbour already cuts them
    tri_faces = [np.asarray(c)[:, f] for (t, c) in blocks for f in FACES[ELEMENTS[t][0]] if len(f) == 3]
    tri_keys = np.unique(_tri_keys(np.concatenate(tri_faces), n_nodes)) if tri_faces else np.zeros(0, np.int64)
    forced: dict = {}
    for (mtype, conn), s in zip(blocks, starts):
        kind = ELEMENTS[mtype][0]
        for face in quad_faces(kind):
            q = np.asarray(conn)[:, face].astype(np.int64)
            if not len(tri_keys):
                continue
            hit = [np.isin(_tri_keys(q[:, list(t)], n_nodes), tri_keys)
                   for t in ((0, 1, 2), (0, 2, 3), (0, 1, 3), (1, 2, 3))]
            d0, d1 = hit[0] | hit[1], hit[2] | hit[3]
            both = np.flatnonzero(d0 & d1)
            if len(both):
                raise SplitError(f"{len(both)} quadrilateral faces of {mtype} elements meet triangles cut along "
                                 "both diagonals (overlapping elements)", s + both)
            for i in np.flatnonzero(d0 | d1):
                pair = (int(q[i, 0]), int(q[i, 2])) if d0[i] else (int(q[i, 1]), int(q[i, 3]))
                forced[tuple(sorted(q[i].tolist()))] = pair

    new_points: list[np.ndarray] = []
    face_node: dict = {}                                     # sorted quad corners -> its centre node
    if quadratic and forced:           # a forced diagonal is a tetrahedron's edge: take its mid-node
        pairs = np.array(sorted({tuple(sorted(p)) for p in forced.values()}), dtype=np.int64)
        want = pairs[:, 0] * n_nodes + pairs[:, 1]
        for mtype, conn in blocks:
            kind = ELEMENTS[mtype][0]
            conn = np.asarray(conn, dtype=np.int64)
            nc = len(REF[kind])
            for (a, b), m in ((e, nc + i) for i, e in enumerate(EDGES[kind])):
                lo, hi = np.minimum(conn[:, a], conn[:, b]), np.maximum(conn[:, a], conn[:, b])
                hit = np.flatnonzero(np.isin(lo * n_nodes + hi, want))
                for i in hit:
                    face_node.setdefault(("edge", int(lo[i]), int(hi[i])), int(conn[i, m]))
        for key, (a, b) in forced.items():
            node = face_node.get(("edge", min(a, b), max(a, b)))
            if node is not None:
                face_node[key] = node
    cells, origin = [], []
    stats: dict = {"by_type": {}, "face_nodes": 0, "interior_nodes": 0, "centre_nodes": 0}
    next_node = n_nodes

    def add_points(x: np.ndarray) -> np.ndarray:
        nonlocal next_node
        ids = np.arange(next_node, next_node + len(x))
        new_points.append(np.asarray(x, dtype=float))
        next_node += len(x)
        return ids

    for (mtype, conn), s in zip(blocks, starts):
        kind, order, nn = ELEMENTS[mtype]
        conn = np.asarray(conn, dtype=np.int64)
        k = len(conn)
        bstats = stats["by_type"].setdefault(mtype, {"elements": 0, "tetrahedra": {}})
        bstats["elements"] += k
        if kind == "tetra":
            cells.append(conn)
            origin.append(s + np.arange(k))
            bstats["tetrahedra"]["1"] = bstats["tetrahedra"].get("1", 0) + k
            continue
        quads = quad_faces(kind)
        nc = len(REF[kind])
        diag = np.column_stack([_diagonal_choice(conn[:, q], forced) for q in quads])
        config = diag @ (1 << np.arange(len(quads)))
        for cfg in np.unique(config):
            members = np.flatnonzero(config == cfg)
            t = np.array(local_split(kind, tuple(int(v) for v in diag[members[0]])))
            key = str(len(t))
            bstats["tetrahedra"][key] = bstats["tetrahedra"].get(key, 0) + len(members)
            c = conn[members]
            glob = np.column_stack([c[:, :nc], np.full(len(c), -1)])
            if np.any(t == nc):                                       # the interior node
                if mtype == "hexahedron27":
                    glob[:, nc] = c[:, HEX27_CENTRE]
                else:
                    xi = REF[kind].astype(float).mean(axis=0)[None, :]
                    glob[:, nc] = add_points(_map(mtype, c, xi, points)[:, 0])
                    stats["centre_nodes"] += len(c)
            tc = glob[:, t]                                            # (k, T, 4)
            flip = np.zeros(len(c), bool)
            if kind == "wedge":                                        # either handedness
                allx = np.vstack([points, *new_points]) if new_points else points
                x = allx[tc]
                v = np.einsum("ktj,ktj->kt", np.cross(x[:, :, 1] - x[:, :, 0], x[:, :, 2] - x[:, :, 0]),
                              x[:, :, 3] - x[:, :, 0])
                flip = v.sum(axis=1) < 0
                tc[flip] = tc[flip][:, :, [0, 2, 1, 3]]
            if quadratic:
                mids = np.empty(tc.shape[:2] + (6,), np.int64)
                cache: dict = {}
                for i, tet in enumerate(t):
                    for j, (p, q) in enumerate(((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))):
                        a, b = sorted((int(tet[p]), int(tet[q])))
                        if (a, b) not in cache:
                            cache[a, b] = _mid_nodes(mtype, kind, c, a, b, points, face_node, add_points, stats,
                                                     new_points)
                        mids[:, i, j] = cache[a, b]
                mids[flip] = mids[flip][:, :, [2, 1, 0, 3, 5, 4]]
                tc = np.concatenate([tc, mids], axis=2)
            cells.append(tc.reshape(-1, tc.shape[2]))
            origin.append(np.repeat(s + members, len(t)))
    out_cells = np.concatenate(cells) if cells else np.zeros((0, 10 if quadratic else 4), np.int64)
    out_origin = np.concatenate(origin) if origin else np.zeros(0, np.int64)
    order_ = np.argsort(out_origin, kind="stable")                # tetrahedra of each element together
    out_cells, out_origin = out_cells[order_], out_origin[order_]
    first = np.zeros(starts[-1] + 1, np.int64)
    np.add.at(first, out_origin + 1, 1)
    first = np.cumsum(first)
    all_points = np.vstack([points, *new_points]) if new_points else points
    stats["tetrahedra"] = len(out_cells)
    stats["new_nodes"] = len(all_points) - n_nodes
    split = Split(all_points, out_cells, out_origin, first, forced, stats)
    if quadratic:
        _check_edges(split)
    return split


def _map(mtype: str, conn: np.ndarray, xi: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Images (k, p, 3) of reference points ``xi`` (p, 3) under the maps of elements ``conn`` (k, n)."""
    return np.einsum("pn,knj->kpj", shape_functions(mtype, xi), points[conn])


def _mid_nodes(mtype, kind, conn, a, b, points, face_node, add_points, stats, new_points) -> np.ndarray:
    """Nodes (k,) on the tetrahedron edge between local corners a < b of elements ``conn`` (k, n)."""
    nc = len(REF[kind])
    if b < nc:
        for i, (p, q) in enumerate(EDGES[kind]):
            if {p, q} == {a, b}:
                return conn[:, nc + i]
        for f, face in enumerate(FACES[kind]):
            if len(face) == 4 and a in face and b in face:                    # a face diagonal
                if mtype == "hexahedron27":
                    return conn[:, HEX27_FACE_NODE[f]]
                keys = [tuple(r) for r in np.sort(conn[:, face], axis=1).tolist()]
                out = np.array([face_node.get(kk, -1) for kk in keys], dtype=np.int64)
                new = np.flatnonzero(out < 0)
                if len(new):
                    mids = [nc + i for i, (p, q) in enumerate(EDGES[kind])
                            for u, v in zip(face, face[1:] + face[:1]) if {p, q} == {u, v}]
                    cn = conn[new]
                    # the 8-node serendipity face at its centre: -1/4 Σ corners + 1/2 Σ mid-edges
                    x = -0.25 * points[cn[:, face]].sum(axis=1) + 0.5 * points[cn[:, mids]].sum(axis=1)
                    for j, i in enumerate(new):                       # one node per face, shared
                        node = face_node.get(keys[i])
                        if node is None:
                            node = int(add_points(x[j][None, :])[0])
                            face_node[keys[i]] = node
                            stats["face_nodes"] += 1
                        out[i] = node
                return out
    # through the interior: the element map at the parametric mid-point (one node per element)
    ref = np.vstack([REF[kind].astype(float), REF[kind].astype(float).mean(axis=0)])
    xi = 0.5 * (ref[a] + ref[b])
    stats["interior_nodes"] += len(conn)
    return add_points(_map(mtype, conn, xi[None, :], points)[:, 0])


def _check_edges(split: Split) -> None:
    """Every tetrahedron edge has one mid-node: two elements that give an edge different mid-nodes
    do not match (the mesh would crack along the edge)."""
    c = split.cells
    pairs = [(0, 1, 4), (1, 2, 5), (0, 2, 6), (0, 3, 7), (1, 3, 8), (2, 3, 9)]
    e = np.concatenate([np.column_stack([np.minimum(c[:, a], c[:, b]), np.maximum(c[:, a], c[:, b]), c[:, m],
                                         np.arange(len(c))]) for a, b, m in pairs])
    order = np.lexsort((e[:, 2], e[:, 1], e[:, 0]))
    e = e[order]
    same_edge = (e[1:, 0] == e[:-1, 0]) & (e[1:, 1] == e[:-1, 1])
    clash = np.flatnonzero(same_edge & (e[1:, 2] != e[:-1, 2]))
    if len(clash):
        i = clash[0]
        elements = sorted({int(split.origin[e[i, 3]]), int(split.origin[e[i + 1, 3]])})
        raise SplitError(f"{len(clash)} edges have different mid-nodes in the elements that share them (elements "
                         "do not match: a crack)", elements)


def write_tables(path) -> None:
    """Write :mod:`geometry.split_tables` from :func:`search_split` (a minute: the search is exhaustive)."""
    lines = ['"""Splits of the reference hexahedron, wedge and pyramid into tetrahedra for every combination of',
             'quadrilateral face diagonals, found by :func:`geometry.split.search_split` (generated by',
             '``python -m geometry.split``; ``tests/unit/geometry/test_mesh_hex.py`` checks the table',
             'against the search).',
             '',
             'kind -> diagonals (0/1 per quadrilateral face, ``geometry.split.quad_faces`` order) -> tetrahedra',
             'as local corner numbers; the number of corners stands for the interior (centre) node."""',
             '', 'SPLITS = {']
    for kind, nq in (("hexahedron", 6), ("wedge", 3), ("pyramid", 1)):
        lines.append(f'    "{kind}": {{')
        for d in itertools.product((0, 1), repeat=nq):
            tets = [str(tuple(int(v) for v in t)) for t in search_split(kind, d)]
            lines.append(f"        {d}: (")
            for i in range(0, len(tets), 6):
                lines.append("            " + ", ".join(tets[i:i + 6]) + ",")
            lines.append("        ),")
        lines.append("    },")
    lines.append("}")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    import sys

    write_tables(sys.argv[1] if len(sys.argv) > 1 else __file__.replace("split.py", "split_tables.py"))
