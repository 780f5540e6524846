"""Meshes from files (gmsh ``.msh``, Abaqus ``.inp``, Nastran ``.bdf``/``.nas``, VTU) through meshio.

Reading gives a :class:`MeshFile`: NumPy arrays on one process, tetrahedra in VTK node order, and
the file's named sets:

- **cell sets**: Abaqus ``*ELSET``, gmsh physical volumes/surfaces (by name and by number), Nastran
  property IDs (``"1"``, and the ``$HMNAME COMP`` names HyperMesh writes), VTU integer cell data
  (by value);
- **node sets**: Abaqus ``*NSET``;
- **surfaces**: Abaqus ``*SURFACE, TYPE=ELEMENT`` (element + face label S1-S4) and triangle
  elements (gmsh physical surfaces, Nastran ``CTRIA3``/``CTRIA6`` by property ID, VTU triangles).

:func:`map_sets` turns the scene's mapping (part -> cell sets, face -> surfaces or node sets) into
one tag per tetrahedron and one per boundary facet; :func:`distribute` hands the arrays to dolfinx
exactly as ``gmshio.model_to_mesh`` does with a gmsh-built mesh.  Every failure is a
:class:`MeshImportError` whose message starts with the scene key or the file.
"""
from __future__ import annotations

import functools
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mpi4py import MPI

from geometry.abaqus import AbaqusError, AbaqusSyntaxError, read_deck
from geometry.gmsh_io import MeshData
from geometry.hexahedra import (
    DEGENERATE,
    HEXAHEDRA,
    HexFaceIndex,
    HexPathError,
    choose_path,
    complete_hex27,
    face_label,
    facet_nodes,
    hex_quality,
    integration_rule,
)
from geometry.nastran import NastranError, hypermesh_names
from geometry.nastran import scan as scan_nastran
from geometry.quality import tet_quality
from geometry.split import ELEMENTS, FACES, SplitError, split_mesh
from geometry.tags import mesh_file_tags

#: meshio cell types that are read as volumes (split into tetrahedra by :mod:`geometry.split`).
TETRA = {"tetra": 4, "tetra4": 4, "tetra10": 10}
VOLUMES = ELEMENTS
SUPPORTED = ("linear and quadratic tetrahedra, hexahedra, wedges and pyramids (Abaqus C3D4/C3D10, C3D8/C3D20/"
             "C3D27, C3D6/C3D15, C3D5/C3D13; Nastran CTETRA, CHEXA, CPENTA, CPYRAM 4-20 nodes; gmsh; VTK)")
OTHER_VOLUMES = ("hexahedron24", "wedge12", "wedge18", "pyramid14", "tetra14", "polyhedron")
TRIANGLES = {"triangle": 3, "triangle6": 6, "triangle7": 7}
#: Skin elements that name faces: triangles and quadrilaterals (corners first).
SKINS = {**TRIANGLES, "quad": 4, "quad8": 8, "quad9": 9}
FORMATS = {".msh": "gmsh", ".inp": "abaqus", ".bdf": "nastran", ".nas": "nastran", ".fem": "nastran",
           ".vtu": "vtu"}

#: Corners of the four faces of a tetrahedron, in the Abaqus face order S1..S4 (outward normals).
TET_FACES = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
#: VTK tetra10 mid-edge node of each corner pair.
_MID = {(0, 1): 4, (1, 2): 5, (0, 2): 6, (0, 3): 7, (1, 3): 8, (2, 3): 9}


class MeshImportError(ValueError):
    """A mesh file that cannot be used; the message names the file or scene key and the reason."""


@dataclass
class MeshFile:
    """A tetrahedral mesh read from a file, on one process (VTK node order)."""

    points: np.ndarray                      # (n, 3)
    cells: np.ndarray                       # (m, 4) or (m, 10)
    cell_ids: np.ndarray                    # (m,) element numbers of the file (or 1-based positions)
    cell_sets: dict[str, np.ndarray] = field(default_factory=dict)     # name -> cell indices
    surfaces: dict[str, np.ndarray] = field(default_factory=dict)      # name -> (k, 2) [cell, face 0..3]
    node_sets: dict[str, np.ndarray] = field(default_factory=dict)     # name -> node indices
    format: str = ""
    origin: np.ndarray | None = None        # (m,) index of the file's element each tetrahedron comes from
    split: dict = field(default_factory=dict)   # element counts by the file's type and the split

    @property
    def degree(self) -> int:
        return 2 if self.cells.shape[1] == 10 else 1

    @property
    def hexahedral(self) -> bool:
        """Hexahedra (8 or 27 nodes) read as they are (the native path, :mod:`geometry.hexahedra`)."""
        return self.cells.shape[1] in (8, 27)

    @functools.cached_property
    def face_index(self) -> _FaceIndex:
        """The boundary faces of ``cells`` (built once: reading, mapping and writing all need it)."""
        if self.hexahedral:
            return HexFaceIndex(self.cells)
        return _FaceIndex(self.cells)


@dataclass
class MappedMesh:
    """A :class:`MeshFile` with one tag per cell (the part) and per tagged boundary facet (the face)."""

    points: np.ndarray
    cells: np.ndarray
    cell_values: np.ndarray                 # (m,) part tags
    facets: np.ndarray                      # (k, 3|6) VTK triangle nodes
    facet_values: np.ndarray                # (k,) face tags
    volumes: dict[str, int]
    faces: dict[str, int]


def file_format(path: Path, fmt: str = "") -> str:
    """The meshio format of ``path``: ``fmt`` if given, else from the extension."""
    if fmt:
        return fmt
    try:
        return FORMATS[path.suffix.lower()]
    except KeyError:
        raise MeshImportError(f"geometry.file: unknown mesh format {path.suffix!r} of {path.name}; known: "
                              f"{sorted(FORMATS)} (or set geometry.format to a meshio format name)") from None


@dataclass
class _Raw:
    """What a file holds before the split: element blocks and sets on the file's elements."""

    points: np.ndarray
    blocks: list                                    # (meshio type, connectivity (k, n) node indices)
    ids: np.ndarray                                 # element numbers of the concatenated blocks
    cell_sets: dict = field(default_factory=dict)   # name -> element indices
    faces: dict = field(default_factory=dict)       # name -> [(element index, face 0.., where)]
    skins: dict = field(default_factory=dict)       # name -> [(k, 3|4) corner nodes]
    node_sets: dict = field(default_factory=dict)   # name -> node indices
    element_types: list = field(default_factory=list)   # the file's own type of each block (Abaqus: C3D20R)


def read_mesh_file(path: str | Path, fmt: str = "", id_field: str = "") -> MeshFile:
    """Read a mesh and its sets, its hexahedra, wedges and pyramids split into tetrahedra
    (:mod:`geometry.split`); ``id_field`` names the integer cell data that holds set numbers
    (default: ``nastran:ref`` or ``gmsh:physical``, else the only integer cell data)."""
    path, fmt, raw = _read_raw(path, fmt, id_field)
    return _split(path, fmt, raw)


def _read_raw(path: str | Path, fmt: str = "", id_field: str = "", skip_sets=(), deck: bool = False
              ) -> tuple[Path, str, _Raw]:
    """The file's elements and sets as they are (before any split), without the elements of
    ``skip_sets`` (Abaqus decks: rigid parts that the scene gives as rigid_plate interfaces)."""
    path = Path(path)
    if not path.is_file():
        raise MeshImportError(f"geometry.file: {path} does not exist")
    fmt = file_format(path, fmt)
    if (skip_sets or deck) and fmt != "abaqus":
        raise MeshImportError(f"geometry.{'skip_sets' if skip_sets else 'deck'}: only for Abaqus decks "
                              f"(.inp); {path.name} is {fmt}")
    return path, fmt, _read_abaqus(path, skip_sets, deck) if fmt == "abaqus" else _read_meshio(path, fmt, id_field)


def _read_meshio(path: Path, fmt: str, id_field: str) -> _Raw:
    # meshio.read prints and calls sys.exit on a ReadError; its format readers raise
    from meshio._helpers import reader_map  # heavy: meshio (0.15 s import; only to read a mesh file)

    if fmt not in reader_map:
        raise MeshImportError(f"geometry.format: unknown meshio format {fmt!r}; "
                              f"e.g. {sorted(set(FORMATS.values()))}")
    try:
        nastran = scan_nastran(path) if fmt == "nastran" else None
    except NastranError as e:
        raise MeshImportError(f"geometry.file: {e}") from None
    _teach_meshio()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = reader_map[fmt](str(path))
    except Exception as e:  # meshio raises ReadError, KeyError, ValueError, AssertionError ...
        raise MeshImportError(f"geometry.file: cannot read {path.name} as {fmt}: "
                              f"{type(e).__name__}: {e}") from None

    volume_blocks = [i for i, b in enumerate(m.cells) if b.type in VOLUMES]
    other = sorted({b.type for b in m.cells if b.type in OTHER_VOLUMES or b.type.startswith("polyhedron")})
    if other:
        counts = ", ".join(f"{t} ({sum(len(b.data) for b in m.cells if b.type == t)} elements)" for t in other)
        raise MeshImportError(f"geometry.file: {path.name} has unsupported volume elements: {counts}; "
                              f"supported: {SUPPORTED}")
    if not volume_blocks:
        raise MeshImportError(f"geometry.file: {path.name} has no volume elements; supported: {SUPPORTED}")
    if fmt == "nastran" and "nastran:ref" in m.point_data and np.any(m.point_data["nastran:ref"] != 0):
        bad = np.flatnonzero(m.point_data["nastran:ref"])[:5]
        raise MeshImportError(f"geometry.file: GRID points {[int(m.points_id[i]) for i in bad]} use a coordinate "
                              "system (CP field); only the basic system is supported")

    offsets = np.cumsum([0] + [len(m.cells[i].data) for i in volume_blocks])
    blocks = [(m.cells[i].type, np.asarray(m.cells[i].data, dtype=np.int64)) for i in volume_blocks]
    if getattr(m, "cells_id", None) is not None:           # Nastran element numbers
        cell_ids = np.concatenate([np.asarray(m.cells_id[i]) for i in volume_blocks])
    else:
        cell_ids = np.arange(1, offsets[-1] + 1)
    raw = _Raw(np.asarray(m.points, dtype=float)[:, :3], blocks, cell_ids.astype(np.int64))

    def volume_indices(per_block) -> np.ndarray:
        return np.concatenate([np.asarray(per_block[i], dtype=np.int64) + offsets[k]
                               for k, i in enumerate(volume_blocks)] or [np.zeros(0, np.int64)])

    skin_blocks = [i for i, b in enumerate(m.cells) if b.type in SKINS]

    def skins_of(rows_of) -> list[np.ndarray]:
        out = []
        for i in skin_blocks:
            rows = np.asarray(m.cells[i].data)[rows_of(i)]
            if len(rows):
                out.append(rows[:, :4 if m.cells[i].type.startswith("quad") else 3].astype(np.int64))
        return out

    # named sets: gmsh physical names, VTU (meshio keeps them as cell_sets)
    for name, per_block in m.cell_sets.items():
        if name.startswith("gmsh:") or len(per_block) != len(m.cells):
            continue
        cs = volume_indices(per_block)
        if len(cs):
            raw.cell_sets[name] = cs
        skins = skins_of(lambda i: np.asarray(per_block[i], dtype=np.int64))  # noqa: B023
        if skins:
            raw.skins[name] = skins
    # numbered sets: integer cell data (Nastran PIDs, gmsh physical numbers, VTU arrays)
    key = _id_field(m, id_field, path)
    if key:
        data = m.cell_data[key]
        ids = np.concatenate([np.asarray(data[i]).reshape(len(m.cells[i].data), -1)[:, 0] for i in volume_blocks])
        for v in np.unique(ids):
            raw.cell_sets.setdefault(str(int(v)), np.flatnonzero(ids == v))
        vals = {i: np.asarray(data[i]).reshape(len(m.cells[i].data), -1)[:, 0] for i in skin_blocks}
        for v in np.unique(np.concatenate(list(vals.values()) or [np.zeros(0, int)])):
            raw.skins.setdefault(str(int(v)), []).extend(skins_of(lambda i: vals[i] == v))  # noqa: B023
    for name, nodes in m.point_sets.items():
        raw.node_sets[name] = np.asarray(nodes, dtype=np.int64)
    if nastran is not None:
        index = {int(g): i for i, g in enumerate(np.asarray(m.points_id))}
        for name, (grids, where) in nastran.items():
            missing = [g for g in grids if g not in index]
            if missing:
                raise MeshImportError(f"geometry.file: {path.name} {where}: SET1 {name}: GRID {missing[0]} "
                                      "is not defined")
            raw.node_sets[name] = np.asarray([index[g] for g in grids], dtype=np.int64)
    names = {}
    if fmt == "nastran":
        names = hypermesh_names(path)
    else:   # gmsh-style field data {name: [number, dim]} (gmsh files, and VTU written by fem-squeal convert)
        names = {str(int(v[0])): k for k, v in m.field_data.items() if np.asarray(v).size == 2}
    for pid, name in names.items():
        for table in (raw.cell_sets, raw.skins):
            if pid in table and name not in table:
                table[name] = table[pid]
    return raw


def _teach_meshio() -> None:
    """meshio 5.0 (Debian bookworm) lists wedge15 and pyramid13 in its readers but not in the table
    of cell dimensions that every cell block looks up: add them."""
    from meshio import _mesh  # heavy: meshio (0.15 s import; only to read a mesh file)

    for t in ("wedge15", "pyramid13"):
        _mesh.topological_dimension.setdefault(t, 3)


def _read_abaqus(path: Path, skip_sets=(), model: bool = False) -> _Raw:
    """A flat Abaqus deck (:mod:`geometry.abaqus`): volume blocks, element sets (volume members),
    surface elements in sets as skins, ``*SURFACE`` faces, node sets and node surfaces; the elements
    of ``skip_sets`` left out (with the surfaces on them and their nodes); ``model``: the deck's model
    keywords are the scene's (:func:`geometry.abaqus.read_deck`)."""

    try:
        deck = read_deck(path, model=model)
    except AbaqusSyntaxError as e:
        raise MeshImportError(f"geometry.file: cannot read {path.name} as abaqus: {e}") from None
    except AbaqusError as e:
        raise MeshImportError(f"geometry.file: {e}") from None
    vol = [(t, c, ids) for t, c, ids in deck.blocks if t in VOLUMES]
    vol_types = [e for (t, _, _), e in zip(deck.blocks, deck.element_types) if t in VOLUMES]
    skin = [(t, c, ids) for t, c, ids in deck.blocks if t in SKINS]
    if not vol:
        raise MeshImportError(f"geometry.file: {path.name} has no volume elements; supported: {SUPPORTED}")
    ids = np.concatenate([b[2] for b in vol])
    if skip_sets:
        deck, vol, vol_types, skin = _without_sets(path, deck, vol, vol_types, skin, skip_sets)
        ids = np.concatenate([b[2] for b in vol])
    raw = _Raw(deck.points, [(t, c) for t, c, _ in vol], ids.astype(np.int64), element_types=vol_types)
    vindex = {int(e): i for i, e in enumerate(ids)}
    sindex = {int(e): (k, i) for k, (_, _, sid) in enumerate(skin) for i, e in enumerate(sid)}
    for key, members in deck.elsets.items():
        name = deck.names[key]
        v = [vindex[e] for e in members if e in vindex]
        s = [sindex[e] for e in members if e in sindex]
        unknown = [e for e in members if e not in vindex and e not in sindex]
        if unknown:
            raise MeshImportError(f"geometry.file: {path.name}: *ELSET {name}: element {unknown[0]} "
                                  "is not defined")
        if v:
            raw.cell_sets[name] = np.asarray(v, dtype=np.int64)
        if s:
            raw.skins[name] = [skin[k][1][[i for kk, i in s if kk == k]][:, :4 if skin[k][0].startswith("quad")
                                                                             else 3]
                               for k in sorted({k for k, _ in s})]
    for key, nodes in deck.nsets.items():
        raw.node_sets[deck.names[key]] = nodes
    for key, nodes in deck.node_surfaces.items():
        raw.node_sets[deck.names[key]] = nodes
    for key, rows in deck.surfaces.items():
        name = deck.names[key]
        out = []
        for e, label, where in rows:
            if e not in vindex:
                raise MeshImportError(f"geometry.file: {where}: *SURFACE {name}: element {e} is not a volume "
                                      "element")
            out.append((vindex[e], label, where))
        raw.faces[name] = out
    return raw


def _without_sets(path: Path, deck, vol, vol_types, skin, skip_sets):
    """The deck without the elements of ``skip_sets``: their element sets, the surfaces on them and the
    nodes no kept element uses (node sets keep their other nodes; one left empty is dropped)."""
    skip: set[int] = set()
    for s in skip_sets:
        if s.upper() not in deck.elsets:
            raise MeshImportError(f"geometry.skip_sets: no element set {s!r} in {path.name}")
        skip |= set(deck.elsets[s.upper()])
    keep = [(t, c[~np.isin(ids, list(skip))], ids[~np.isin(ids, list(skip))]) for t, c, ids in vol]
    types = [e for (_, _, ids), e in zip(keep, vol_types) if len(ids)]
    keep = [b for b in keep if len(b[2])]
    if not keep:
        raise MeshImportError(f"geometry.skip_sets: {list(skip_sets)} leave no volume element in {path.name}")
    used = np.unique(np.concatenate([c.ravel() for _, c, _ in keep]))
    new = np.full(len(deck.points), -1, dtype=np.int64)
    new[used] = np.arange(len(used))
    keep = [(t, new[c], ids) for t, c, ids in keep]
    skin = [(t, new[c], ids) for t, c, ids in skin if np.all(new[c] >= 0)]
    deck.points = deck.points[used]
    deck.node_ids = deck.node_ids[used]
    deck.elsets = {k: [e for e in v if e not in skip] for k, v in deck.elsets.items()}
    deck.elsets = {k: v for k, v in deck.elsets.items() if v}
    deck.surfaces = {k: v for k, v in deck.surfaces.items() if not any(e in skip for e, _, _ in v)}
    for table in (deck.nsets, deck.node_surfaces):
        for k in list(table):
            n = new[table[k]]
            if np.any(n >= 0):
                table[k] = n[n >= 0]
            else:
                del table[k]
    return deck, keep, types, skin


def _split(path: Path, fmt: str, raw: _Raw) -> MeshFile:
    """The tetrahedra of ``raw`` with its sets; errors name the file's element numbers."""
    sizes = [len(c) for _, c in raw.blocks]
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    types = np.repeat(np.arange(len(raw.blocks)), sizes)
    try:
        sp = split_mesh(raw.points, raw.blocks)
    except SplitError as e:
        elems = raw.ids[np.asarray(e.elements[:10], dtype=np.int64)].tolist()
        raise MeshImportError(f"geometry.file: {path.name}: {e}: elements {elems}") from None
    out = MeshFile(sp.points, sp.cells, raw.ids[sp.origin], format=fmt, origin=sp.origin)
    counts: dict[str, int] = {}
    for t, c in raw.blocks:
        counts[t] = counts.get(t, 0) + len(c)
    out.split = {"file_elements": counts, "tetrahedra": int(len(sp.cells)),
                 "tetrahedra_per_element": {t: v["tetrahedra"] for t, v in sp.stats["by_type"].items()},
                 "new_nodes": int(sp.stats["new_nodes"]), "face_nodes": int(sp.stats["face_nodes"]),
                 "interior_nodes": int(sp.stats["interior_nodes"]), "centre_nodes": int(sp.stats["centre_nodes"])}
    for name, idx in raw.cell_sets.items():
        out.cell_sets[name] = np.sort(sp.tets_of(idx))
    faces = out.face_index
    for name, skins in raw.skins.items():
        tris = [sp.face_triangles(q) for q in skins if len(q)]
        if tris:
            out.surfaces[name] = faces.locate(np.concatenate(tris), name)
    for name, rows in raw.faces.items():
        pairs, tris = [], []
        for e, label, where in rows:
            mtype = raw.blocks[types[e]][0]
            kind = ELEMENTS[mtype][0]
            n_faces = len(FACES[kind])
            if not re.fullmatch(rf"S[1-{n_faces}]", label):
                raise MeshImportError(f"geometry.file: {where}: *SURFACE {name}: face label {label!r}; "
                                      f"{kind} elements have S1-S{n_faces}")
            f = int(label[1]) - 1
            conn = raw.blocks[types[e]][1][e - starts[types[e]]]
            if kind == "tetra":
                pairs.append((int(sp.first[e]), f))
            else:
                tris.append(sp.face_triangles(conn[FACES[kind][f]][None, :]))
        surf = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        if tris:
            surf = np.concatenate([surf, faces.locate(np.concatenate(tris), name)])
        out.surfaces[name] = surf
    out.node_sets.update(raw.node_sets)
    return out


def _id_field(m, id_field: str, path: Path) -> str:
    ints = [k for k, v in m.cell_data.items() if all(np.issubdtype(np.asarray(a).dtype, np.integer) for a in v)
            and k not in ("gmsh:geometrical",)]
    if id_field:
        if id_field not in m.cell_data:
            raise MeshImportError(f"geometry.id_field: {path.name} has no cell data {id_field!r}; "
                                  f"integer cell data: {ints}")
        return id_field
    for k in ("nastran:ref", "gmsh:physical"):
        if k in ints:
            return k
    if len(ints) > 1 and m.cell_sets == {}:
        raise MeshImportError(f"geometry.id_field: {path.name} has several integer cell data {ints}; "
                              "name the one that holds the set numbers")
    return ints[0] if ints else ""


class _FaceIndex:
    """Boundary faces of a tetrahedral mesh: sorted corner triple -> (cell, local face)."""

    def __init__(self, cells: np.ndarray):
        corners = cells[:, :4][:, TET_FACES]                     # (m, 4, 3)
        keys = np.sort(corners.reshape(-1, 3), axis=1)
        order = np.lexsort(keys.T[::-1])
        k = keys[order]
        same_next = np.all(k[1:] == k[:-1], axis=1)
        unique = np.ones(len(k), bool)
        unique[1:] &= ~same_next
        unique[:-1] &= ~same_next
        self._interior = k[~unique][::2]            # each interior face twice: keep one (sorted rows)
        self.boundary = {tuple(r): divmod(int(i), 4) for r, i in zip(k[unique].tolist(), order[unique])}

    def _is_interior(self, t: tuple) -> bool:
        rows = [("a", self._interior.dtype), ("b", self._interior.dtype), ("c", self._interior.dtype)]
        keys = np.ascontiguousarray(self._interior).view(rows).ravel()
        i = int(np.searchsorted(keys, np.array([t], dtype=self._interior.dtype).view(rows).ravel())[0])
        return i < len(keys) and tuple(self._interior[i].tolist()) == t

    def locate(self, triangles: np.ndarray, name: str) -> np.ndarray:
        """(cell, face) of each triangle given by its corner nodes."""
        out, missing, interior = [], 0, 0
        for t in np.sort(np.asarray(triangles)[:, :3], axis=1).tolist():
            hit = self.boundary.get(tuple(t))
            if hit is None:
                inside = self._is_interior(tuple(t))
                interior += inside
                missing += not inside
                continue
            out.append(hit)
        if interior:
            raise MeshImportError(f"surface {name!r}: {interior} triangles lie between two tetrahedra; faces "
                                  "must be on the boundary of the mesh (contact, clamps and loads act on ds)")
        if missing:
            raise MeshImportError(f"surface {name!r}: {missing} triangles are not faces of any tetrahedron")
        return np.asarray(out, dtype=np.int64).reshape(-1, 2)

    def of_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """Boundary faces whose three corners are all in ``nodes``."""
        inside = set(np.asarray(nodes).tolist())
        hits = [cf for t, cf in self.boundary.items() if t[0] in inside and t[1] in inside and t[2] in inside]
        return np.asarray(sorted(hits), dtype=np.int64).reshape(-1, 2)


def _lookup(name, table: dict):
    """``table[name]``: exact, else the one case-insensitive match (Abaqus names are case-insensitive)."""
    key = str(name)
    if key in table:
        return table[key]
    hits = [k for k in table if k.upper() == key.upper()]
    return table[hits[0]] if len(hits) == 1 else None


def map_sets(mf: MeshFile, parts: dict[str, list], faces: dict[str, list]) -> MappedMesh:
    """Part tags 1, 2, ... and face tags 101, 102, ... in the order of the mapping."""
    volumes, face_tags = mesh_file_tags(list(parts), list(faces))
    avail_cells = sorted(mf.cell_sets)
    cell_values = np.zeros(len(mf.cells), dtype=np.int32)
    for part, sets in parts.items():
        for s in sets:
            idx = _lookup(s, mf.cell_sets)
            if idx is None:
                raise MeshImportError(f"geometry.parts.{part}: no element set {s!r} in the file; available: "
                                      f"{avail_cells}")
            if len(idx) == 0:
                raise MeshImportError(f"geometry.parts.{part}: element set {s!r} has no tetrahedra")
            taken = cell_values[idx]
            if np.any((taken != 0) & (taken != volumes[part])):
                other = [p for p, t in volumes.items() if t == taken[taken != 0][0]][0]
                raise MeshImportError(f"geometry.parts.{part}: set {s!r} shares elements with part {other!r} "
                                      f"(e.g. element {int(mf.cell_ids[idx[taken != 0][0]])})")
            cell_values[idx] = volumes[part]
    loose = np.flatnonzero(cell_values == 0)
    if len(loose):
        holders = sorted(n for n, ix in mf.cell_sets.items() if np.isin(loose[:1], ix).any())
        raise MeshImportError(f"geometry.parts: {len(loose)} elements belong to no part (e.g. elements "
                              f"{mf.cell_ids[loose[:5]].tolist()}, in sets {holders}); map them, available: "
                              f"{avail_cells}")

    index = mf.face_index
    avail_faces = sorted(set(mf.surfaces) | set(mf.node_sets))
    facet_owner: dict[tuple[int, int], str] = {}
    facets, values = [], []
    for face, sets in faces.items():
        chosen: set[tuple[int, int]] = set()
        for s in sets:
            surf = _lookup(s, mf.surfaces)
            if surf is None:
                nodes = _lookup(s, mf.node_sets)
                if nodes is None:
                    raise MeshImportError(f"geometry.faces.{face}: no surface or node set {s!r} in the file; "
                                          f"available: {avail_faces}")
                surf = index.of_nodes(nodes)
            if len(surf) == 0:
                raise MeshImportError(f"geometry.faces.{face}: set {s!r} covers no boundary face of the mesh")
            chosen |= {(int(c), int(f)) for c, f in surf}
        for cf in sorted(chosen):
            if cf in facet_owner:
                raise MeshImportError(f"geometry.faces.{face}: shares boundary faces with {facet_owner[cf]!r} "
                                      f"(element {int(mf.cell_ids[cf[0]])} S{cf[1] + 1}); faces must not overlap")
            facet_owner[cf] = face
            facets.append(_facet_nodes(mf.cells[cf[0]], cf[1]))
            values.append(face_tags[face])
    width = {4: 3, 10: 6, 8: 4, 27: 9}[mf.cells.shape[1]]
    return MappedMesh(mf.points, mf.cells, cell_values, np.asarray(facets, dtype=np.int64).reshape(-1, width),
                      np.asarray(values, dtype=np.int32), volumes, face_tags)


def _facet_nodes(cell: np.ndarray, face: int) -> np.ndarray:
    """VTK triangle (3 nodes) or triangle6 (corners, then mid-edges 01, 12, 20) of a tetrahedron face;
    quad or quad9 of a hexahedron's (:func:`geometry.hexahedra.facet_nodes`)."""
    if len(cell) in (8, 27):
        return facet_nodes(cell, face)
    a, b, c = TET_FACES[face]
    if len(cell) == 4:
        return cell[[a, b, c]]
    mids = [_MID[tuple(sorted(e))] for e in ((a, b), (b, c), (c, a))]
    return cell[[a, b, c, *mids]]


def transform_points(points: np.ndarray, scale: float, center, axis) -> np.ndarray:
    """x' = R (s x − c): scale to metres, move the axis point to the origin and turn ``axis`` onto +z
    (the physics takes the disc axis as z: sliding direction e_θ, nodal diameters)."""
    a = np.asarray(axis, dtype=float)
    a /= np.linalg.norm(a)
    x = scale * points - np.asarray(center, dtype=float)
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(a, z), float(a @ z)
    if np.linalg.norm(v) < 1e-14:
        return x if c > 0 else x * np.array([1.0, -1.0, -1.0])     # turn 180° about x
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    r = np.eye(3) + vx + vx @ vx / (1.0 + c)                         # Rodrigues: R a = z
    return x @ r.T


def distribute(comm: MPI.Comm, mapped: MappedMesh | None) -> MeshData:
    """dolfinx mesh and tags from rank 0's arrays, exactly as ``gmshio.model_to_mesh`` builds them:
    tetrahedra (4 or 10 nodes, triangle facets) or, on the native hexahedral path
    (:mod:`geometry.hexahedra`), hexahedra (8 or 27 nodes: the Q1 or Q2 coordinate element,
    quadrilateral facets)."""
    import ufl  # heavy: FE stack
    from dolfinx import cpp  # heavy: FE stack
    from dolfinx.mesh import CellType, create_mesh, meshtags_from_entities  # heavy: FE stack

    nodes, fnodes = comm.bcast(None if mapped is None else (mapped.cells.shape[1], mapped.facets.shape[1]), root=0)
    if comm.rank == 0:
        x, cells, cv = mapped.points, mapped.cells, mapped.cell_values
        facets, fv = mapped.facets, mapped.facet_values
    else:
        x, cells, cv = np.zeros((0, 3)), np.zeros((0, nodes), np.int64), np.zeros(0, np.int32)
        facets, fv = np.zeros((0, fnodes), np.int64), np.zeros(0, np.int32)
    if nodes in (8, 27):
        domain = ufl.Mesh(ufl.VectorElement("Q", ufl.hexahedron, 2 if nodes == 27 else 1))
        cell, facet = CellType.hexahedron, CellType.quadrilateral
    else:
        degree = 2 if nodes == 10 else 1
        domain = ufl.Mesh(ufl.VectorElement(ufl.FiniteElement("Lagrange", ufl.tetrahedron, degree,
                                                              variant="equispaced")))
        cell, facet = CellType.tetrahedron, CellType.triangle
    cells = cells[:, cpp.io.perm_vtk(cell, nodes)]
    facets = facets[:, cpp.io.perm_vtk(facet, fnodes)]
    mesh = create_mesh(comm, cells, x, domain)
    ents, vals = cpp.io.distribute_entity_data(mesh._mesh, 3, cells, cv)
    mesh.topology.create_connectivity(3, 0)
    ct = meshtags_from_entities(mesh, 3, cpp.graph.AdjacencyList_int32(ents), vals.astype(np.int32))
    ct.name = "Cell tags"
    ents, vals = cpp.io.distribute_entity_data(mesh._mesh, 2, facets, fv)
    mesh.topology.create_connectivity(2, 3)
    ft = meshtags_from_entities(mesh, 2, cpp.graph.AdjacencyList_int32(ents), vals.astype(np.int32))
    ft.name = "Facet tags"
    mesh.name = "mesh"
    volumes, faces = comm.bcast(None if mapped is None else (mapped.volumes, mapped.faces), root=0)
    return MeshData(mesh, ct, ft, volumes, faces)


#: A mesh whose bounding box exceeds this [m] after scaling is almost certainly in millimetres.
MM_SUSPECT_EXTENT = 5.0


def prepare(path: str | Path, *, parts: dict[str, list], faces: dict[str, list], fmt: str = "", scale: float = 1.0,
            center=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), id_field: str = "",
            max_aspect_ratio: float = 10.0, hexahedra: str = "split", blockers=(), skip_sets=(),
            deck: bool = False) -> tuple[MappedMesh, dict]:
    """Read, scale and turn, check the elements and map the sets (one process).  Returns the mapped
    mesh and a summary (sizes, bounding box, quality, warnings) for the results.  ``hexahedra``
    ("auto", "native", "split") and the scene features that need tetrahedra (``blockers``) choose
    the path of hexahedral files (:func:`geometry.hexahedra.choose_path`); the summary records it."""
    file, fmt, raw = _read_raw(path, fmt, id_field, skip_sets, deck)
    types = [t for t, _ in raw.blocks]
    try:
        route, reason = choose_path(hexahedra, types, list(blockers))
    except HexPathError as e:
        raise MeshImportError(str(e)) from None
    if route == "native":
        mapped, info = _prepare_native(str(path), file, fmt, raw, parts, faces, scale, center, axis,
                                       max_aspect_ratio)
    else:
        mapped, info = _prepare_split(str(path), _split(file, fmt, raw), parts, faces, scale, center, axis,
                                      max_aspect_ratio)
    if any(t in HEXAHEDRA for t in types):
        info["hexahedra"] = {"path": route, "reason": reason}
        if route == "native":
            rule, why = integration_rule(types[0], raw.element_types)
            info["hexahedra"].update(element=types[0], integration=rule, integration_reason=why)
    return mapped, info


def _bounding_box(points: np.ndarray, scale: float, info: dict) -> None:
    """The bounding box into ``info``, and the millimetre warning when it spans more than
    :data:`MM_SUSPECT_EXTENT` after scaling."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    info["bounding_box"] = [lo.tolist(), hi.tolist()]
    extent = float(np.max(hi - lo))
    if extent > MM_SUSPECT_EXTENT:
        info["warnings"].append(
            f"geometry.scale: the mesh spans {extent:.4g} m after scaling by {scale:g}; a brake is well under "
            f"{MM_SUSPECT_EXTENT:g} m, so the file is probably in millimetres: set geometry.scale = 0.001")


def _mapped(mf: MeshFile, parts, faces, info: dict) -> tuple[MappedMesh, dict]:
    """The sets of ``mf`` mapped to the scene's parts and faces, with their sizes in ``info``."""
    mapped = map_sets(mf, parts, faces)
    info["parts"] = {p: int(np.count_nonzero(mapped.cell_values == t)) for p, t in mapped.volumes.items()}
    info["faces"] = {f: int(np.count_nonzero(mapped.facet_values == t)) for f, t in mapped.faces.items()}
    return mapped, info


def _prepare_split(path: str, mf: MeshFile, parts, faces, scale, center, axis, max_aspect_ratio):
    mf.points = transform_points(mf.points, scale, center, axis)
    info: dict = {"file": str(path), "format": mf.format, "nodes": len(mf.points), "elements": len(mf.cells),
                  "element": "tetra10" if mf.degree == 2 else "tetra", "scale": scale, "warnings": []}
    if mf.split:
        info["file_elements"] = dict(mf.split["file_elements"])
        info["split"] = {k: v for k, v in mf.split.items() if k != "file_elements"}
    _bounding_box(mf.points, scale, info)
    q = tet_quality(mf.points, mf.cells, max_aspect_ratio)
    info["quality"] = {"worst_aspect_ratio": float(np.max(q.aspect_ratio)),
                       "worst_aspect_element": int(mf.cell_ids[np.argmax(q.aspect_ratio)]),
                       "min_jacobian_ratio": float(np.min(q.jacobian_ratio)),
                       "poor_elements": len(np.unique(mf.cell_ids[q.poor])), "max_aspect_ratio": max_aspect_ratio}
    split_note = ""
    if mf.split and set(mf.split["file_elements"]) - set(TETRA):
        split_note = " (the file's element numbers; checked on the tetrahedra they are split into)"
    for what, idx in (("inverted (det J <= 0)", q.inverted), ("degenerate (zero volume or aspect ratio > 1e4)",
                                                                q.degenerate)):
        if len(idx):
            ids = list(dict.fromkeys(mf.cell_ids[idx].tolist()))
            raise MeshImportError(f"geometry.file: {len(ids)} {what} elements: {ids[:20]}"
                                  + (" ..." if len(ids) > 20 else "") + split_note)
    if len(q.poor):
        worst = q.poor[np.argsort(q.aspect_ratio[q.poor])[::-1]]
        ids = list(dict.fromkeys(mf.cell_ids[worst].tolist()))
        info["warnings"].append(
            f"geometry.max_aspect_ratio: {len(ids)} elements have an aspect ratio above {max_aspect_ratio:g} "
            f"(worst {q.aspect_ratio[worst[0]]:.3g}; elements {ids[:10]}){split_note}")
    return _mapped(mf, parts, faces, info)


def _prepare_native(path: str, file: Path, fmt: str, raw: _Raw, parts, faces, scale, center, axis,
                    max_aspect_ratio):
    """The native path: hexahedra as they are (20-node ones completed to 27 nodes), checked and mapped."""
    mtype = raw.blocks[0][0]
    conn = np.vstack([c for _, c in raw.blocks]).astype(np.int64)
    points = raw.points
    if mtype == "hexahedron20":
        points, conn = complete_hex27(points, conn)
    points = transform_points(points, scale, center, axis)
    mf = MeshFile(points, conn, raw.ids, cell_sets=dict(raw.cell_sets), node_sets=dict(raw.node_sets), format=fmt)
    index: HexFaceIndex = mf.face_index
    try:
        for name, skins in raw.skins.items():
            quads = [q for q in skins if q.shape[1] == 4]
            if len(quads) != len(skins):
                raise MeshImportError(f"geometry.file: {file.name}: surface {name!r} has triangles; a mesh of "
                                      "hexahedra has quadrilateral faces")
            if quads:
                mf.surfaces[name] = index.locate(np.concatenate(quads), name)
        for name, rows in raw.faces.items():
            mf.surfaces[name] = np.asarray([(e, face_label(label, name, where)) for e, label, where in rows],
                                           dtype=np.int64).reshape(-1, 2)
    except MeshImportError:
        raise
    except ValueError as e:
        raise MeshImportError(f"geometry.file: {e}") from None
    info: dict = {"file": path, "format": fmt, "nodes": len(np.unique(conn)), "elements": len(conn),
                  "element": "hexahedron27" if conn.shape[1] == 27 else "hexahedron", "scale": scale,
                  "warnings": [], "file_elements": {mtype: len(conn)}}
    _bounding_box(points, scale, info)
    ratio, aspect = hex_quality(points, conn)
    info["quality"] = {"worst_aspect_ratio": float(np.max(aspect)),
                       "worst_aspect_element": int(raw.ids[np.argmax(aspect)]),
                       "min_jacobian_ratio": float(np.min(ratio)),
                       "poor_elements": int(np.count_nonzero(aspect > max_aspect_ratio)),
                       "max_aspect_ratio": max_aspect_ratio}
    for what, bad in (("inverted (det J <= 0)", ratio <= 0),
                      ("degenerate (aspect ratio > 1e4)", aspect > DEGENERATE)):
        ids = raw.ids[bad].tolist()
        if ids:
            raise MeshImportError(f"geometry.file: {len(ids)} {what} elements: {ids[:20]}"
                                  + (" ..." if len(ids) > 20 else ""))
    poor = np.flatnonzero(aspect > max_aspect_ratio)
    if len(poor):
        worst = poor[np.argsort(aspect[poor])[::-1]]
        info["warnings"].append(
            f"geometry.max_aspect_ratio: {len(poor)} elements have an aspect ratio above {max_aspect_ratio:g} "
            f"(worst {aspect[worst[0]]:.3g}; elements {raw.ids[worst[:10]].tolist()})")
    return _mapped(mf, parts, faces, info)


def mesh_file_mesh(comm: MPI.Comm, *, file: str, parts: dict[str, list], faces: dict[str, list],
                   format: str = "", scale: float = 1.0, center=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0),
                   id_field: str = "", max_aspect_ratio: float = 10.0, hexahedra: str = "split",
                   blockers=(), skip_sets=(), deck: bool = False) -> MeshData:
    """Distributed mesh of a mesh file (scene ``geometry.builder = "mesh_file"``); rank 0 reads it.
    Warnings (units, poorly shaped elements) are issued with :func:`warnings.warn` and kept in ``info``.
    ``hexahedra``, ``blockers``: the path of hexahedral files; ``skip_sets``, ``deck``: Abaqus decks
    (:func:`prepare`, :func:`_read_abaqus`)."""
    mapped, info, error = None, None, None
    if comm.rank == 0:
        try:
            mapped, info = prepare(file, parts=parts, faces=faces, fmt=format, scale=scale, center=center,
                                   axis=axis, id_field=id_field, max_aspect_ratio=max_aspect_ratio,
                                   hexahedra=hexahedra, blockers=blockers, skip_sets=skip_sets, deck=deck)
        except MeshImportError as e:
            error = str(e)
    error = comm.bcast(error, root=0)
    if error:
        raise MeshImportError(error)
    info = comm.bcast(info, root=0)
    if comm.rank == 0:
        for w in info["warnings"]:
            warnings.warn(w, stacklevel=2)
    md = distribute(comm, mapped)
    return md._replace(info=info)
