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
from typing import NamedTuple

import numpy as np
from mpi4py import MPI

from geometry.gmsh_io import MeshData

#: meshio cell types that are read as volumes, and what each is called in the files.
TETRA = {"tetra": 4, "tetra4": 4, "tetra10": 10}
SUPPORTED = "linear and quadratic tetrahedra (Abaqus C3D4/C3D10*, Nastran CTETRA 4/10, gmsh 4/11, VTK 10/24)"
OTHER_VOLUMES = ("hexahedron", "hexahedron20", "hexahedron24", "hexahedron27", "wedge", "wedge12", "wedge15",
                 "wedge18", "pyramid", "pyramid13", "pyramid14", "tetra14", "polyhedron")
TRIANGLES = {"triangle": 3, "triangle6": 6, "triangle7": 7}
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

    @property
    def degree(self) -> int:
        return 2 if self.cells.shape[1] == 10 else 1

    @functools.cached_property
    def face_index(self) -> _FaceIndex:
        """The boundary faces of ``cells`` (built once: reading, mapping and writing all need it)."""
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


def read_mesh_file(path: str | Path, fmt: str = "", id_field: str = "") -> MeshFile:
    """Read a tetrahedral mesh and its sets; ``id_field`` names the integer cell data that holds set
    numbers (default: ``nastran:ref`` or ``gmsh:physical``, else the only integer cell data)."""
    path = Path(path)
    if not path.is_file():
        raise MeshImportError(f"geometry.file: {path} does not exist")
    fmt = file_format(path, fmt)
    scan = _scan_abaqus(path) if fmt == "abaqus" else None
    # meshio.read prints and calls sys.exit on a ReadError; its format readers raise
    from meshio._helpers import reader_map

    if fmt not in reader_map:
        raise MeshImportError(f"geometry.format: unknown meshio format {fmt!r}; "
                              f"e.g. {sorted(set(FORMATS.values()))}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = reader_map[fmt](str(path))
    except Exception as e:  # meshio raises ReadError, KeyError, ValueError, AssertionError ...
        raise MeshImportError(f"geometry.file: cannot read {path.name} as {fmt}: "
                              f"{type(e).__name__}: {e}") from None

    volume_blocks = [i for i, b in enumerate(m.cells) if b.type in TETRA]
    other = sorted({b.type for b in m.cells if b.type in OTHER_VOLUMES or b.type.startswith("polyhedron")})
    if other:
        counts = ", ".join(f"{t} ({sum(len(b.data) for b in m.cells if b.type == t)} elements)" for t in other)
        raise MeshImportError(f"geometry.file: {path.name} has unsupported volume elements: {counts}; "
                              f"supported: {SUPPORTED}")
    if not volume_blocks:
        raise MeshImportError(f"geometry.file: {path.name} has no volume elements; supported: {SUPPORTED}")
    sizes = {TETRA[m.cells[i].type] for i in volume_blocks}
    if len(sizes) > 1:
        raise MeshImportError(f"geometry.file: {path.name} mixes linear and quadratic tetrahedra; use one order")
    if fmt == "nastran" and "nastran:ref" in m.point_data and np.any(m.point_data["nastran:ref"] != 0):
        bad = np.flatnonzero(m.point_data["nastran:ref"])[:5]
        raise MeshImportError(f"geometry.file: GRID points {[int(m.points_id[i]) for i in bad]} use a coordinate "
                              "system (CP field); only the basic system is supported")

    offsets = np.cumsum([0] + [len(m.cells[i].data) for i in volume_blocks])
    cells = np.concatenate([m.cells[i].data for i in volume_blocks]).astype(np.int64)
    if getattr(m, "cells_id", None) is not None:           # Nastran element numbers
        cell_ids = np.concatenate([np.asarray(m.cells_id[i]) for i in volume_blocks])
    else:
        cell_ids = np.arange(1, len(cells) + 1)
    out = MeshFile(np.asarray(m.points, dtype=float)[:, :3], cells, cell_ids.astype(np.int64), format=fmt)

    def volume_indices(per_block) -> np.ndarray:
        return np.concatenate([np.asarray(per_block[i], dtype=np.int64) + offsets[k]
                               for k, i in enumerate(volume_blocks)] or [np.zeros(0, np.int64)])

    faces = out.face_index
    triangle_blocks = [i for i, b in enumerate(m.cells) if b.type in TRIANGLES]

    def surface_of(per_block, name) -> np.ndarray:
        tris = [m.cells[i].data[np.asarray(per_block[i], dtype=np.int64)] for i in triangle_blocks]
        tris = [t[:, :3] for t in tris if len(t)]
        return faces.locate(np.concatenate(tris), name) if tris else np.zeros((0, 2), np.int64)

    # named sets: Abaqus ELSET, gmsh physical names (meshio keeps them as cell_sets)
    for name, per_block in m.cell_sets.items():
        if name.startswith("gmsh:"):
            continue
        if len(per_block) != len(m.cells):
            continue
        cs = volume_indices(per_block)
        if len(cs):
            out.cell_sets[name] = cs
        surf = surface_of(per_block, name)
        if len(surf):
            out.surfaces[name] = surf
    # numbered sets: integer cell data (Nastran PIDs, gmsh physical numbers, VTU arrays)
    key = _id_field(m, id_field, path)
    if key:
        data = m.cell_data[key]
        ids = np.concatenate([np.asarray(data[i]).reshape(len(m.cells[i].data), -1)[:, 0] for i in volume_blocks])
        for v in np.unique(ids):
            out.cell_sets.setdefault(str(int(v)), np.flatnonzero(ids == v))
        for i in triangle_blocks:
            vals = np.asarray(data[i]).reshape(len(m.cells[i].data), -1)[:, 0]
            for v in np.unique(vals):
                name = str(int(v))
                surf = faces.locate(m.cells[i].data[vals == v][:, :3], name)
                out.surfaces[name] = np.concatenate([out.surfaces[name], surf]) if name in out.surfaces else surf
    for name, nodes in m.point_sets.items():
        out.node_sets[name] = np.asarray(nodes, dtype=np.int64)
    names = {}
    if fmt == "nastran":
        names = _hypermesh_names(path)
    else:   # gmsh-style field data {name: [number, dim]} (gmsh files, and VTU written by fem-squeal convert)
        names = {str(int(v[0])): k for k, v in m.field_data.items() if np.asarray(v).size == 2}
    if names:
        for pid, name in names.items():
            for table in (out.cell_sets, out.surfaces):
                if pid in table and name not in table:
                    table[name] = table[pid]
    if fmt == "abaqus":
        out.cell_ids, surfaces = _abaqus_surfaces(path, scan, out)
        out.surfaces.update(surfaces)
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


_ABQ_KEYWORD = re.compile(r"^\s*\*\s*([A-Za-z ]+?)\s*(,|$)")


def _abaqus_keywords(path: Path):
    """(keyword upper-case, parameters dict, data lines) of each keyword block of an .inp file."""
    block = None
    with open(path, errors="replace") as f:
        for line in f:
            if line.startswith("**"):
                continue
            mk = _ABQ_KEYWORD.match(line)
            if mk:
                if block:
                    yield block
                params = {}
                for item in line.split(",")[1:]:
                    k, _, v = item.partition("=")
                    params[k.strip().upper()] = v.strip()
                block = (mk.group(1).upper(), params, [])
            elif block and line.strip():
                block[2].append(line)
    if block:
        yield block


class _AbaqusScan(NamedTuple):
    ids: list[int]                                  # element numbers of the tetrahedra, in file order
    elsets: dict[str, list[int]]                    # upper-case name -> element numbers
    surfaces: dict[str, list[tuple[str, str]]]      # name -> (element or ELSET, face label)


def _scan_abaqus(path: Path) -> _AbaqusScan:
    """One pass over an .inp for what meshio does not keep: element numbers, element sets and
    ``*SURFACE, TYPE=ELEMENT``.  meshio reads one *NODE block and ignores assemblies, so those are
    refused here, before it reads them wrongly."""
    ids: list[int] = []
    elsets: dict[str, list[int]] = {}
    surfaces: dict[str, list[tuple[str, str]]] = {}
    nodes = instances = 0
    for kw, params, lines in _abaqus_keywords(path):
        nodes += kw == "NODE"
        instances += kw == "INSTANCE"
        if kw == "ELEMENT":
            etype = params.get("TYPE", "").upper()
            if not etype.startswith("C3D4") and not etype.startswith("C3D10"):
                continue
            values = [int(v) for ln in lines for v in ln.replace(",", " ").split()]
            n = 5 if etype.startswith("C3D4") else 11
            new = values[::n]
            ids += new
            if "ELSET" in params:
                elsets.setdefault(params["ELSET"].upper(), []).extend(new)
        elif kw == "ELSET":
            items = [v.strip() for ln in lines for v in ln.split(",") if v.strip()]
            if "GENERATE" in params:
                a, b, *s = (int(v) for v in items)
                items = [str(v) for v in range(a, b + 1, s[0] if s else 1)]
            members = elsets.setdefault(params.get("ELSET", "").upper(), [])
            for it in items:
                members.extend([int(it)] if it.lstrip("-").isdigit() else elsets.get(it.upper(), []))
        elif kw == "SURFACE":
            name = params.get("NAME", "")
            if params.get("TYPE", "ELEMENT").upper() != "ELEMENT":
                raise MeshImportError(f"geometry.file: *SURFACE {name}: TYPE={params['TYPE']} is not supported; "
                                      "use an element-based surface or a node set")
            surfaces[name] = [tuple(v.strip() for v in ln.split(",")[:2]) for ln in lines]
    if nodes > 1 or instances:
        raise MeshImportError(f"geometry.file: {path.name} is an Abaqus assembly ({nodes} *NODE blocks, "
                              f"{instances} *INSTANCE); write a flat input file (one *NODE block, "
                              "no parts/instances)")
    return _AbaqusScan(ids, elsets, surfaces)


def _abaqus_surfaces(path: Path, scan: _AbaqusScan, mf: MeshFile) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Element numbers of the volume elements, and the scanned surfaces as (cell, face)."""
    elsets = scan.elsets
    cell_ids = np.asarray(scan.ids, dtype=np.int64)
    if len(cell_ids) != len(mf.cells):
        raise MeshImportError(f"geometry.file: {path.name}: read {len(cell_ids)} element numbers for "
                              f"{len(mf.cells)} tetrahedra")
    index = {int(e): i for i, e in enumerate(cell_ids)}
    out = {}
    for name, rows in scan.surfaces.items():
        pairs = []
        for ref, label in rows:
            lab = label.upper()
            if not re.fullmatch(r"S[1-4]", lab):
                raise MeshImportError(f"geometry.file: *SURFACE {name}: face label {label!r}; "
                                      "tetrahedra have S1-S4")
            elems = [int(ref)] if ref.lstrip("-").isdigit() else elsets.get(ref.upper())
            if elems is None:
                raise MeshImportError(f"geometry.file: *SURFACE {name}: unknown element set {ref!r}")
            for e in elems:
                if e not in index:
                    raise MeshImportError(f"geometry.file: *SURFACE {name}: element {e} is not a tetrahedron")
                pairs.append((index[e], int(lab[1]) - 1))
        out[name] = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    return cell_ids, out


def _hypermesh_names(path: Path) -> dict[str, str]:
    """``$HMNAME COMP <id> "name"`` comments (HyperMesh, and fem-squeal convert): property ID -> name."""
    names = {}
    pattern = re.compile(r'^\$HMNAME\s+(?:COMP|PROP)\s+(\d+)\s*"([^"]+)"')
    with open(path, errors="replace") as f:
        for line in f:
            if line.startswith("$"):
                mt = pattern.match(line)
                if mt:
                    names[mt.group(1)] = mt.group(2)
    return names


def _lookup(name, table: dict):
    """``table[name]``: exact, else the one case-insensitive match (Abaqus names are case-insensitive)."""
    key = str(name)
    if key in table:
        return table[key]
    hits = [k for k in table if k.upper() == key.upper()]
    return table[hits[0]] if len(hits) == 1 else None


def map_sets(mf: MeshFile, parts: dict[str, list], faces: dict[str, list]) -> MappedMesh:
    """Part tags 1, 2, ... and face tags 101, 102, ... in the order of the mapping."""
    from fem_squeal.tags import mesh_file_tags

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
    width = 6 if mf.degree == 2 else 3
    return MappedMesh(mf.points, mf.cells, cell_values, np.asarray(facets, dtype=np.int64).reshape(-1, width),
                      np.asarray(values, dtype=np.int32), volumes, face_tags)


def _facet_nodes(cell: np.ndarray, face: int) -> np.ndarray:
    """VTK triangle (3 nodes) or triangle6 (corners, then mid-edges 01, 12, 20) of a tetrahedron face."""
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
    """dolfinx mesh and tags from rank 0's arrays, exactly as ``gmshio.model_to_mesh`` builds them."""
    import ufl
    from dolfinx import cpp
    from dolfinx.mesh import CellType, create_mesh, meshtags_from_entities

    nodes, fnodes = comm.bcast(None if mapped is None else (mapped.cells.shape[1], mapped.facets.shape[1]), root=0)
    if comm.rank == 0:
        x, cells, cv = mapped.points, mapped.cells, mapped.cell_values
        facets, fv = mapped.facets, mapped.facet_values
    else:
        x, cells, cv = np.zeros((0, 3)), np.zeros((0, nodes), np.int64), np.zeros(0, np.int32)
        facets, fv = np.zeros((0, fnodes), np.int64), np.zeros(0, np.int32)
    degree = 2 if nodes == 10 else 1
    element = ufl.VectorElement(ufl.FiniteElement("Lagrange", ufl.tetrahedron, degree, variant="equispaced"))
    domain = ufl.Mesh(element)
    cells = cells[:, cpp.io.perm_vtk(CellType.tetrahedron, nodes)]
    facets = facets[:, cpp.io.perm_vtk(CellType.triangle, fnodes)]
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
            max_aspect_ratio: float = 10.0) -> tuple[MappedMesh, dict]:
    """Read, scale and turn, check the elements and map the sets (one process).  Returns the mapped
    mesh and a summary (sizes, bounding box, quality, warnings) for the results."""
    from geometry.quality import tet_quality

    mf = read_mesh_file(path, fmt, id_field)
    mf.points = transform_points(mf.points, scale, center, axis)
    info: dict = {"file": str(path), "format": mf.format, "nodes": len(mf.points), "elements": len(mf.cells),
                  "element": "tetra10" if mf.degree == 2 else "tetra", "scale": scale, "warnings": []}
    lo, hi = mf.points.min(axis=0), mf.points.max(axis=0)
    info["bounding_box"] = [lo.tolist(), hi.tolist()]
    extent = float(np.max(hi - lo))
    if extent > MM_SUSPECT_EXTENT:
        info["warnings"].append(
            f"geometry.scale: the mesh spans {extent:.4g} m after scaling by {scale:g}; a brake is well under "
            f"{MM_SUSPECT_EXTENT:g} m, so the file is probably in millimetres: set geometry.scale = 0.001")
    q = tet_quality(mf.points, mf.cells, max_aspect_ratio)
    info["quality"] = {"worst_aspect_ratio": float(np.max(q.aspect_ratio)),
                       "worst_aspect_element": int(mf.cell_ids[np.argmax(q.aspect_ratio)]),
                       "min_jacobian_ratio": float(np.min(q.jacobian_ratio)),
                       "poor_elements": len(q.poor), "max_aspect_ratio": max_aspect_ratio}
    for what, idx in (("inverted (det J <= 0)", q.inverted), ("degenerate (zero volume or aspect ratio > 1e4)",
                                                                q.degenerate)):
        if len(idx):
            raise MeshImportError(f"geometry.file: {len(idx)} {what} elements: {mf.cell_ids[idx[:20]].tolist()}"
                                  + (" ..." if len(idx) > 20 else ""))
    if len(q.poor):
        worst = q.poor[np.argsort(q.aspect_ratio[q.poor])[::-1][:10]]
        info["warnings"].append(
            f"geometry.max_aspect_ratio: {len(q.poor)} elements have an aspect ratio above {max_aspect_ratio:g} "
            f"(worst {q.aspect_ratio[worst[0]]:.3g}; elements {mf.cell_ids[worst].tolist()})")
    mapped = map_sets(mf, parts, faces)
    info["parts"] = {p: int(np.count_nonzero(mapped.cell_values == t)) for p, t in mapped.volumes.items()}
    info["faces"] = {f: int(np.count_nonzero(mapped.facet_values == t)) for f, t in mapped.faces.items()}
    return mapped, info


def mesh_file_mesh(comm: MPI.Comm, *, file: str, parts: dict[str, list], faces: dict[str, list],
                   format: str = "", scale: float = 1.0, center=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0),
                   id_field: str = "", max_aspect_ratio: float = 10.0) -> MeshData:
    """Distributed mesh of a mesh file (scene ``geometry.builder = "mesh_file"``); rank 0 reads it.
    Warnings (units, poorly shaped elements) are issued with :func:`warnings.warn` and kept in ``info``."""
    mapped, info, error = None, None, None
    if comm.rank == 0:
        try:
            mapped, info = prepare(file, parts=parts, faces=faces, fmt=format, scale=scale, center=center,
                                   axis=axis, id_field=id_field, max_aspect_ratio=max_aspect_ratio)
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
