"""Writing tetrahedral meshes with their sets (``fem-squeal convert`` and ``fem-squeal mesh``).

Each format keeps the sets its own way: Abaqus ``*ELSET``/``*NSET``/``*SURFACE``; gmsh physical
groups with names; Nastran property IDs (``CTETRA``, ``CTRIA3``/``CTRIA6`` for surfaces) with
``$HMNAME COMP`` name comments; VTU integer cell data ``set_id`` with the names in field data.
:func:`geometry.mesh_file.read_mesh_file` reads every one of them back.
"""
from __future__ import annotations

import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from fem_squeal.util.atomic import atomic_path
from fem_squeal.util.errors import MeshError, MeshingError
from fem_squeal.util.vtu import add_vtu_field_data
from geometry import MODELS, write_msh
from geometry.mesh_file import MeshFile, MeshImportError, _facet_nodes, file_format, read_mesh_file


@contextmanager
def mesh_errors() -> Iterator[None]:
    """Re-raise the errors of ``geometry`` (which imports nothing from fem_squeal) as the application's,
    with the same message: a file that cannot be read (:class:`MeshImportError`) or a builder's refused
    input (``ValueError``, e.g. ``geometry: need 0 < inner_radius < outer_radius``) as
    :class:`~fem_squeal.util.errors.MeshError` (exit 2), a builder that failed (``RuntimeError``) as
    :class:`~fem_squeal.util.errors.MeshingError` (exit 3)."""
    try:
        yield
    except (MeshImportError, ValueError) as e:
        raise MeshError(str(e)) from e
    except RuntimeError as e:
        raise MeshingError(str(e)) from e


def _partition(sets: dict[str, np.ndarray], key) -> tuple[dict[str, np.ndarray], list[str]]:
    """Disjoint sets for formats that give each element one number: named sets first, then numbered
    ones; a set equal to one already kept (a number aliasing a name) is dropped silently, one that
    overlaps partly is dropped with a warning."""
    kept: dict[str, np.ndarray] = {}
    used: set = set()
    dropped = []
    for name in sorted(sets, key=lambda n: (n.isdigit(), int(n) if n.isdigit() else 0, n)):
        members = {key(r) for r in sets[name]}
        if any(members == {key(r) for r in v} for v in kept.values()):
            continue
        if members & used:
            dropped.append(name)
            continue
        kept[name] = sets[name]
        used |= members
    return kept, dropped


def _without_number_aliases(sets: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Drop the numbered sets that repeat a named one (a gmsh physical number, a Nastran PID)."""
    return {n: v for n, v in sets.items()
            if not (n.isdigit() and any(k != n and np.array_equal(v, w) for k, w in sets.items()))}


def _numbers(names: list[str], start: int, taken: set[int]) -> dict[str, int]:
    """Set numbers: a numeric name keeps its number, the others get the next free ones."""
    out = {n: int(n) for n in names if n.isdigit()}
    taken = taken | set(out.values())
    nxt = start
    for n in names:
        if n not in out:
            while nxt in taken:
                nxt += 1
            out[n] = nxt
            taken.add(nxt)
    return out


def write_mesh_file(mf: MeshFile, path: str | Path, fmt: str = "") -> list[str]:
    """Write ``mf`` with its sets: Abaqus ELSET/NSET/*SURFACE; gmsh physical groups (named); Nastran
    property IDs (CTETRA, CTRIA3/6 for surfaces) with ``$HMNAME COMP`` names; VTU integer cell data
    ``set_id`` with the names in field data.  Node sets become surfaces where a format has none.
    Written atomically.  Returns warnings about sets that could not be kept."""
    import meshio  # heavy: meshio (0.15 s import; only to write a mesh file)
    import meshio.nastran._nastran as nastran  # heavy: as above

    path = Path(path)
    fmt = file_format(path, fmt)
    tet = "tetra10" if mf.degree == 2 else "tetra"
    tri = "triangle6" if mf.degree == 2 else "triangle"
    warns: list[str] = []
    surfaces = dict(mf.surfaces)
    if fmt != "abaqus":
        index = mf.face_index
        for name, nodes in mf.node_sets.items():
            if name in surfaces:
                continue
            faces = index.of_nodes(nodes)
            if len(faces):
                surfaces[name] = faces
            else:
                warns.append(f"node set {name!r} covers no boundary face; {fmt} has no node sets, dropped")
    if fmt == "abaqus":
        cell_sets = _without_number_aliases(mf.cell_sets)
        mesh = meshio.Mesh(mf.points, [(tet, mf.cells)], cell_sets={n: [v] for n, v in cell_sets.items()},
                           point_sets=dict(mf.node_sets))
        surf_kept = _without_number_aliases(surfaces)
        with atomic_path(path) as tmp:
            meshio.write(tmp, mesh, file_format="abaqus")
            text = Path(tmp).read_text()    # meshio 7.0 names tetra10 C3D10MH (hybrid); the plain element is C3D10
            Path(tmp).write_text(text.replace("*ELEMENT, TYPE=C3D10MH\n", "*ELEMENT, TYPE=C3D10\n"))
            with open(tmp, "a") as f:
                for name, pairs in surf_kept.items():
                    f.write(f"*SURFACE, NAME={name}, TYPE=ELEMENT\n")
                    for c, face in pairs:
                        f.write(f"{c + 1}, S{face + 1}\n")
        return warns
    cell_sets, dropped = _partition(mf.cell_sets, int)
    warns += [f"element set {n!r} overlaps another set; {fmt} gives each element one number, dropped"
              for n in dropped]
    surf_sets, dropped = _partition(surfaces, lambda r: (int(r[0]), int(r[1])))
    warns += [f"surface {n!r} overlaps another surface; {fmt} gives each face one number, dropped"
              for n in dropped]
    cell_no = _numbers(list(cell_sets), 1, set())
    surf_no = _numbers(list(surf_sets), max(cell_no.values(), default=0) + 1, set(cell_no.values()))
    cell_ids = np.zeros(len(mf.cells), dtype=np.int64)
    for n, idx in cell_sets.items():
        cell_ids[idx] = cell_no[n]
    tris = [_facet_nodes(mf.cells[c], f) for n in surf_sets for c, f in surf_sets[n]]
    tri_ids = np.concatenate([np.full(len(surf_sets[n]), surf_no[n]) for n in surf_sets]
                             or [np.zeros(0, np.int64)])
    blocks = [(tet, mf.cells)] + ([(tri, np.asarray(tris))] if tris else [])
    ids = [cell_ids] + ([tri_ids.astype(np.int64)] if tris else [])
    names = {**{n: (cell_no[n], 3) for n in cell_sets}, **{n: (surf_no[n], 2) for n in surf_sets}}
    if fmt == "gmsh":
        mesh = meshio.Mesh(mf.points, blocks, cell_data={"gmsh:physical": ids, "gmsh:geometrical": ids},
                           field_data={n: np.array([t, d]) for n, (t, d) in names.items() if not n.isdigit()})
        with atomic_path(path) as tmp:
            meshio.write(tmp, mesh, file_format="gmsh22", binary=False)   # 4.1 needs entities
    elif fmt == "nastran":

        mesh = meshio.Mesh(mf.points, blocks, cell_data={"nastran:ref": ids})
        original = nastran._float_to_nastran_string
        nastran._float_to_nastran_string = _nastran_float    # meshio 7.0's fails on negative numbers
        try:
            with atomic_path(path) as tmp:
                meshio.write(tmp, mesh, file_format="nastran")
                text = Path(tmp).read_text()
                head = "".join(f'$HMNAME COMP {t:>16d}"{n}"\n' for n, (t, _) in names.items() if not n.isdigit())
                Path(tmp).write_text(text.replace("BEGIN BULK\n", "BEGIN BULK\n" + head, 1))
        finally:
            nastran._float_to_nastran_string = original
    else:
        mesh = meshio.Mesh(mf.points, blocks, cell_data={"set_id": ids})
        with atomic_path(path) as tmp:
            meshio.write(tmp, mesh, file_format=fmt)
            if fmt == "vtu":    # meshio 7.0 reads VTU field data but does not write it
                add_vtu_field_data(tmp, {n: list(v) for n, v in names.items() if not n.isdigit()})
    return warns


def _nastran_float(value: float, length: int = 16) -> str:
    """A large-field real (``GRID*``): the most digits that fit in ``length`` characters."""
    for precision in range(length - 5, 0, -1):
        out = np.format_float_scientific(value, exp_digits=1, precision=precision).replace("e", "E")
        if len(out) <= length:
            return out
    raise ValueError(f"cannot write {value} in {length} characters")


def convert(src: str | Path, dst: str | Path, *, scale: float = 1.0, fmt_in: str = "", fmt_out: str = "",
            id_field: str = "") -> tuple[MeshFile, list[str]]:
    """Read ``src`` and write ``dst`` with the same sets, coordinates multiplied by ``scale``."""
    with mesh_errors():
        mf = read_mesh_file(src, fmt_in, id_field)
        mf.points = mf.points * scale
        return mf, write_mesh_file(mf, dst, fmt_out)


def write_geometry(comm, geometry: dict, path: str | Path, scale: float = 1.0) -> list[str]:
    """Write the mesh of a scene's geometry section to ``path`` (any format of ``geometry.mesh_file``)
    with its named parts and faces; coordinates multiplied by ``scale``.  Returns the writer's warnings."""
    g = dict(geometry)
    builder = g.pop("builder")
    if builder == "mesh_file":
        warns = convert(g["file"], path, scale=scale * g["scale"], fmt_in=g["format"], id_field=g["id_field"])[1] \
            if comm.rank == 0 else []
        return comm.bcast(warns, root=0)
    with tempfile.TemporaryDirectory() as tmp:
        msh = Path(comm.bcast(tmp if comm.rank == 0 else None, root=0)) / "model.msh"
        write_msh(comm, MODELS[builder](**g), msh)
        warns = convert(msh, path, scale=scale)[1] if comm.rank == 0 else []
        comm.barrier()
    return comm.bcast(warns, root=0)
