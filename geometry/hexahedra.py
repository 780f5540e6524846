"""Native hexahedral meshes from files: an all-hexahedral deck read as dolfinx hexahedra, not split.

- **Which path.**  :func:`choose_path` takes the scene's ``discretisation.hexahedra`` ("auto",
  "native", "split"), the file's element types and the scene features that need tetrahedra, and
  returns the path and the reason; "native" on a mesh that cannot take it is a named error.
- **Geometry.**  Eight-node hexahedra keep the trilinear map (Q1 coordinate element).  Twenty-node
  hexahedra get the 27-node Q2 coordinate element: each face centre and the body centre are the
  images of the reference centres under the element's own 20-node serendipity map
  (:func:`geometry.split.shape_functions`), which is exact, because the serendipity space lies in Q2:
  the Q2 map through these 27 points is the serendipity map itself.  A face centre depends on the
  face's eight nodes only and is made once per face, so neighbours share it.  27-node decks are
  taken as they are.
- **Sets.**  Element sets tag cells one to one; ``*SURFACE`` faces (S1..S6), quadrilateral skins
  and node sets (faces whose four corners are in the set) tag the boundary quadrilaterals.

Node orders are VTK's (as :mod:`geometry.split`); :func:`distribute` permutes them to dolfinx's.
"""
from __future__ import annotations

import re

import numpy as np

from geometry.quality import DEGENERATE  # noqa: F401 (re-exported: the same bound on both paths)
from geometry.split import FACES, HEX27_CENTRE, HEX27_FACE_NODE, reference_nodes, shape_functions

#: meshio hexahedron types -> degree of the coordinate element on the native path.
HEXAHEDRA = {"hexahedron": 1, "hexahedron20": 2, "hexahedron27": 2}
PATHS = ("auto", "native", "split")
#: VTK hexahedron20 mid-edge node of each corner pair of a face (FACES order: edges 01, 12, 23, 30).
_HEX_EDGES = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
_MID = {frozenset(e): 8 + i for i, e in enumerate(_HEX_EDGES)}


class HexPathError(ValueError):
    """``discretisation.hexahedra = "native"`` on a mesh or scene the native path cannot take."""


def choose_path(mode: str, types: list[str], blockers: list[str] = ()) -> tuple[str, str]:
    """("native" | "split", reason) for ``mode`` on a file of element ``types`` (meshio names) in a
    scene whose ``blockers`` name the features that need the split (e.g. contact interfaces)."""
    if mode not in PATHS:
        raise HexPathError(f"discretisation.hexahedra: must be one of {list(PATHS)} (got {mode!r})")
    kinds = sorted(set(types))
    hexes = [t for t in kinds if t in HEXAHEDRA]
    if mode == "split":
        return "split", "discretisation.hexahedra = 'split'" if hexes else "no hexahedra in the file"
    if not hexes:
        if mode == "native":
            raise HexPathError(f"discretisation.hexahedra = 'native': the file has no hexahedra "
                               f"(elements: {kinds})")
        return "split", "no hexahedra in the file"
    why = ""
    if len(hexes) != len(kinds):
        why = f"mixed elements {kinds}: the conforming split into tetrahedra"
    elif len({HEXAHEDRA[t] for t in hexes}) > 1:
        why = f"hexahedra of both orders {hexes}: the conforming split into tetrahedra"
    elif blockers:
        why = "; ".join(blockers) + " (not supported on hexahedra): the split into tetrahedra"
    if why:
        if mode == "native":
            raise HexPathError(f"discretisation.hexahedra = 'native' is not possible: {why}; "
                               "use 'auto' or 'split'")
        return "split", why
    return "native", ("discretisation.hexahedra = 'native'" if mode == "native" else
                      f"every element is a {hexes[0]} and every feature of the scene is supported on hexahedra")


def integration_rule(mtype: str, element_types: list[str]) -> tuple[str, str]:
    """("reduced" | "full", reason): the cell rule a native hexahedral mesh runs with, from the file's own
    element types (Abaqus/CalculiX TYPE names; empty for files that do not name them).

    20-node hexahedra: C3D20R is the 2 × 2 × 2 Gauss rule ("reduced"), C3D20 the 3 × 3 × 3 one ("full");
    a deck of both runs with the reduced rule (the one most squeal decks use), and says so; a file
    without Abaqus types (gmsh, Nastran, VTK) too.  8-node hexahedra: C3D8's 2 × 2 × 2 rule ("full"); a
    deck of C3D8R only: "one-point", CalculiX's C3D8R (one mean-strain point with hourglass control,
    ``fem_squeal.fe.c3d8r``) at discretisation.degree = 1; a deck of both: C3D8's rule for all, said so."""
    named = sorted({t for t in element_types if t})
    if mtype == "hexahedron":
        reduced = [t for t in named if t.endswith("R")]
        if reduced and len(reduced) == len(named):
            return "one-point", (f"{', '.join(named)}: one point with hourglass control (CalculiX C3D8R) at "
                                 "discretisation.degree = 1; degree 2 runs S2 with 2x2x2 Gauss points")
        if reduced:
            return "full", (f"both {', '.join(named)} in the file: C3D8's 2x2x2 Gauss rule for all (C3D8R's one "
                            "point with hourglass control needs a deck of C3D8R only)")
        return "full", "2x2x2 Gauss points (CalculiX/Abaqus C3D8)"
    if not named:
        return "reduced", "the file does not name the integration: 2x2x2 Gauss points (C3D20R)"
    reduced = [t for t in named if t.endswith("R")]
    if len(reduced) == len(named):
        return "reduced", f"{', '.join(named)}: 2x2x2 Gauss points"
    if not reduced:
        return "full", f"{', '.join(named)}: 3x3x3 Gauss points"
    return "reduced", (f"both {', '.join(named)} in the file: 2x2x2 Gauss points (C3D20R) for all; "
                       "set discretisation.quadrature_degree = 5 for the 3x3x3 rule")


def complete_hex27(points: np.ndarray, conn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and VTK hexahedron27 connectivity of twenty-node hexahedra ``conn`` (m, 20): the face
    and body centres are the 20-node serendipity map's images of the reference centres (one node
    per face, shared by the two elements on it)."""
    conn = np.asarray(conn, dtype=np.int64)
    ref = reference_nodes("hexahedron27")
    N = shape_functions("hexahedron20", ref[20:])          # (7, 20): the six face centres, the body centre
    x = np.einsum("pa,mad->mpd", N, points[conn])          # (m, 7, 3)
    m = len(conn)
    out = np.empty((m, 27), dtype=np.int64)
    out[:, :20] = conn
    faces = FACES["hexahedron"]
    keys = np.concatenate([np.sort(conn[:, f], axis=1) for f in faces])          # (6m, 4), face-major
    uniq, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    # the value of each face's first element (the same map restricted to the face, up to rounding)
    vtk_face = np.array(HEX27_FACE_NODE)                                         # FACES index -> VTK node
    face_of_key = first // m
    elem_of_key = first % m
    centres = x[elem_of_key, vtk_face[face_of_key] - 20]
    new = len(points) + np.arange(len(uniq))
    for f in range(6):
        out[:, HEX27_FACE_NODE[f]] = new[inverse.ravel()[f * m:(f + 1) * m]]
    out[:, HEX27_CENTRE] = len(points) + len(uniq) + np.arange(m)
    return np.vstack([points, centres, x[:, 6]]), out


def _lagrange_1d(nodes: np.ndarray, t: np.ndarray):
    """Values and derivatives (len(t), len(nodes)) of the 1D Lagrange polynomials on ``nodes``."""
    v = np.ones((len(t), len(nodes)))
    d = np.zeros((len(t), len(nodes)))
    for a, xa in enumerate(nodes):
        others = [xb for b, xb in enumerate(nodes) if b != a]
        den = np.prod([xa - xb for xb in others])
        v[:, a] = np.prod([t - xb for xb in others], axis=0) / den
        d[:, a] = sum(np.prod([t - xc for xc in others if xc != xb], axis=0) for xb in others) / den
    return v, d


def jacobians(points: np.ndarray, cells: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """det J of the Q1 (8 nodes) or Q2 (27 nodes, VTK order) element maps at reference points ``xi``
    in [0, 2]³: (m, len(xi))."""
    mtype = "hexahedron" if cells.shape[1] == 8 else "hexahedron27"
    ref = reference_nodes(mtype)
    grid = np.unique(ref[:, 0])
    vals, ders = zip(*(_lagrange_1d(grid, xi[:, i]) for i in range(3)))
    idx = np.searchsorted(grid, ref).T                                       # (3, n) 1D index per axis
    dN = np.empty((len(xi), len(ref), 3))
    for i in range(3):
        f = [ders[j] if j == i else vals[j] for j in range(3)]
        dN[:, :, i] = f[0][:, idx[0]] * f[1][:, idx[1]] * f[2][:, idx[2]]
    J = np.einsum("mad,pai->mpdi", points[cells], dN)
    return np.linalg.det(J)


def hex_quality(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Jacobian ratio min det J / max det J over the corners, the 2×2×2 Gauss points and the centre;
    aspect ratio longest / shortest corner edge) of each hexahedron."""
    g = 1.0 + np.array([-1.0, 1.0]) / np.sqrt(3.0)
    xi = np.vstack([reference_nodes("hexahedron"), np.array(np.meshgrid(g, g, g)).reshape(3, -1).T, [[1, 1, 1]]])
    det = jacobians(points, cells, xi)
    ratio = det.min(axis=1) / np.abs(det).max(axis=1)
    c = points[cells[:, :8]]
    edges = np.stack([np.linalg.norm(c[:, a] - c[:, b], axis=1) for a, b in _HEX_EDGES], axis=1)
    return ratio, edges.max(axis=1) / np.maximum(edges.min(axis=1), 1e-300)


class HexFaceIndex:
    """Boundary quadrilaterals of a hexahedral mesh: sorted corner quadruple -> (cell, face S1..S6 - 1)."""

    def __init__(self, cells: np.ndarray):
        corners = cells[:, :8][:, FACES["hexahedron"]]                 # (m, 6, 4)
        keys = np.sort(corners.reshape(-1, 4), axis=1)
        _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        once = counts[inverse.ravel()] == 1
        self.boundary = {tuple(k): divmod(int(i), 6) for i, k in zip(np.flatnonzero(once), keys[once].tolist())}
        self.interior = {tuple(k) for k in keys[~once].tolist()}

    def locate(self, quads: np.ndarray, name: str) -> np.ndarray:
        """(cell, face) of each quadrilateral given by its corner nodes."""
        out, interior, missing = [], 0, 0
        for q in np.sort(np.asarray(quads)[:, :4], axis=1).tolist():
            hit = self.boundary.get(tuple(q))
            if hit is None:
                inside = tuple(q) in self.interior
                interior += inside
                missing += not inside
            else:
                out.append(hit)
        if interior:
            raise ValueError(f"surface {name!r}: {interior} quadrilaterals lie between two hexahedra; faces "
                             "must be on the boundary of the mesh")
        if missing:
            raise ValueError(f"surface {name!r}: {missing} quadrilaterals are not faces of any hexahedron")
        return np.asarray(out, dtype=np.int64).reshape(-1, 2)

    def of_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """Boundary faces whose four corners are all in ``nodes``."""
        inside = set(np.asarray(nodes).tolist())
        hits = [cf for q, cf in self.boundary.items() if all(v in inside for v in q)]
        return np.asarray(sorted(hits), dtype=np.int64).reshape(-1, 2)


def facet_nodes(cell: np.ndarray, face: int) -> np.ndarray:
    """VTK quad (4 nodes) or quad9 (corners, mid-edges 01, 12, 23, 30, centre) of face ``face``
    (0..5 = S1..S6) of a hexahedron or hexahedron27."""
    f = FACES["hexahedron"][face]
    if len(cell) == 8:
        return cell[f]
    mids = [_MID[frozenset((f[i], f[(i + 1) % 4]))] for i in range(4)]
    return cell[[*f, *mids, HEX27_FACE_NODE[face]]]


def face_label(label: str, name: str, where: str) -> int:
    """0..5 of an Abaqus hexahedron face label S1..S6."""
    if not re.fullmatch(r"S[1-6]", label):
        raise ValueError(f"{where}: *SURFACE {name}: face label {label!r}; hexahedron elements have S1-S6")
    return int(label[1]) - 1
