"""Build a gmsh model on rank 0 and distribute it as a dolfinx mesh with cell and facet tags."""
from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

from mpi4py import MPI

#: accepted worst signed inverse condition number (SICN) of the curved second-order tetrahedra
MIN_SICN = 0.1
#: (Mesh.Algorithm3D, Mesh.RandomSeed) tried in turn when the default mesh has a worse element
RETRY = ((10, 1), (1, 2), (1, 3))


class MeshData(NamedTuple):
    """A distributed mesh with its tags and the name -> tag maps of its geometry."""

    mesh: object            # dolfinx.mesh.Mesh
    cell_tags: object       # dolfinx.mesh.MeshTags (volumes = parts)
    facet_tags: object      # dolfinx.mesh.MeshTags (named faces)
    volumes: dict[str, int]
    faces: dict[str, int]
    info: dict | None = None   # what the builder reports (mesh_file: source, units, quality, warnings)


class GmshModel(NamedTuple):
    """What a builder hands to :func:`to_dolfinx` or :func:`write_msh`: ``build(gmsh.model)`` adds the
    geometry, the physical groups and the size fields; ``volumes``/``faces`` are the tags it must create."""

    build: Callable[[object], None]
    order: int
    volumes: dict[str, int]
    faces: dict[str, int]


def min_sicn(model) -> float:
    """Smallest signed inverse condition number over the current 3D mesh (curved elements: min over each).

    gmsh 4.8 has no ``getElementQualities``; this runs ``Plugin(AnalyseMeshQuality)`` and removes its view.
    """
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    before = set(gmsh.view.getTags())
    for name, value in (("ICNMeasure", 1), ("JacobianDeterminant", 0), ("IGEMeasure", 0), ("CreateView", 1),
                        ("Recompute", 1), ("DimensionOfElements", 3)):
        gmsh.plugin.setNumber("AnalyseMeshQuality", name, value)
    gmsh.plugin.run("AnalyseMeshQuality")
    worst = math.inf
    for v in set(gmsh.view.getTags()) - before:
        _, _, data, _, _ = gmsh.view.getModelData(v, 0)
        worst = min([worst] + [min(d) for d in data])
        gmsh.view.remove(v)
    return worst


def mesh_with(model, attempt: tuple[int, int]) -> bool:
    """Mesh afresh with ``(Mesh.Algorithm3D, Mesh.RandomSeed) = attempt``; True if every entity got elements."""
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    model.mesh.clear()
    for name, value in (("Mesh.Algorithm3D", attempt[0]), ("Mesh.RandomSeed", attempt[1]),
                        ("Mesh.MaxNumThreads3D", 1), ("Mesh.Optimize", 1), ("Mesh.MeshOnlyEmpty", 0)):
        gmsh.option.setNumber(name, value)
    model.mesh.generate(3)
    if not all(len(model.mesh.getElements(d, t)[1]) for d in (2, 3) for _, t in model.getEntities(d)):
        return False
    gmsh.option.setNumber("Mesh.MeshOnlyEmpty", 1)   # a repeated generate(3) keeps this mesh ...
    gmsh.option.setNumber("Mesh.Optimize", 0)        # ... and does not re-optimise it
    return True


def search_meshes(model, attempts, order: int, quality: dict | None = None,
                  judge: bool = True) -> tuple[tuple[int, int] | None, dict[tuple[int, int], float]]:
    """Mesh with each ``(Mesh.Algorithm3D, Mesh.RandomSeed)`` of ``attempts`` in turn until one
    meshes every entity and, elevated to ``order``, has a worst element with SICN >= :data:`MIN_SICN`
    (``judge=False``: until one meshes every entity), and return it.  If none passes, the best is
    re-meshed and None returned.  The mesh is left at order 1 (``setOrder(order)`` reproduces the
    judged one).  ``quality`` maps each attempt judged (and any passed in, judged before) to its SICN.

    gmsh 4.8 stays locked after an error raised as an exception, so the attempts run with
    ``General.AbortOnError = 0`` and are judged by their elements."""
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    quality = dict(quality or {})
    abort = gmsh.option.getNumber("General.AbortOnError")
    gmsh.option.setNumber("General.AbortOnError", 0)
    current = None                       # the attempt whose mesh the model holds
    try:
        for attempt in attempts:
            if attempt in quality:
                continue
            current = attempt if mesh_with(model, attempt) else None
            if current is None:
                continue
            if not judge:
                return attempt, quality
            if order == 2:
                model.mesh.setOrder(2)
            quality[attempt] = min_sicn(model)
            if order == 2:
                model.mesh.setOrder(1)
            if quality[attempt] >= MIN_SICN:
                return attempt, quality
        if quality and current != (best := max(quality, key=quality.get)):
            mesh_with(model, best)
    finally:
        gmsh.option.setNumber("General.AbortOnError", abort)
    return None, quality


def _generate_checked(model, order: int) -> str | None:
    """Mesh (3D, elevated to ``order``) a model whose builder did not mesh it, and check the worst
    element: an element with SICN < :data:`MIN_SICN` (a sliver, or one inverted by curving its
    boundary nodes onto the CAD surface) is re-meshed with the alternatives of :data:`RETRY`; the
    best is kept, with a warning (returned) if none reaches MIN_SICN."""
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    default = (int(gmsh.option.getNumber("Mesh.Algorithm3D")), int(gmsh.option.getNumber("Mesh.RandomSeed")))
    model.mesh.generate(3)
    if order == 2:
        model.mesh.setOrder(2)
    first = min_sicn(model)
    if first >= MIN_SICN:
        return None
    accepted, quality = search_meshes(model, RETRY, order, {default: first})
    if order == 2:
        model.mesh.setOrder(2)
    if accepted is not None:
        return None
    return (f"mesh: worst element has SICN {max(quality.values()):.3g} < {MIN_SICN} with every "
            f"(Algorithm3D, RandomSeed) tried ({quality}); results may be inaccurate; try a slightly different "
            "mesh_size")


@contextmanager
def _built(comm: MPI.Comm, model: GmshModel, verbose: bool) -> Iterator[None]:
    """gmsh initialised, the model built and meshed on rank 0 (3D, elevated to ``order``: curved P2
    geometry for ``order=2``) and every requested tag checked; ``ValueError`` names missing tags."""
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    if model.order not in (1, 2):
        raise ValueError(f"order: must be 1 or 2 (got {model.order})")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 1 if verbose else 0)
        gmsh.model.add("fem_squeal")
        error = warning = None
        if comm.rank == 0:
            try:
                model.build(gmsh.model)
                if any(len(gmsh.model.mesh.getElements(3, tag)[1]) for _, tag in gmsh.model.getEntities(3)):
                    gmsh.model.mesh.generate(3)          # meshed (and checked) by the builder: a no-op
                    if model.order == 2:
                        gmsh.model.mesh.setOrder(2)
                else:
                    warning = _generate_checked(gmsh.model, model.order)
                groups = {(d, t) for d, t in gmsh.model.getPhysicalGroups()}
                missing = [f"volume {n}={t}" for n, t in model.volumes.items() if (3, t) not in groups]
                missing += [f"face {n}={t}" for n, t in model.faces.items() if (2, t) not in groups]
                if missing:
                    error = f"gmsh model lacks physical groups: {', '.join(missing)}"
            except Exception as e:  # broadcast, or the other ranks would wait forever
                error = f"geometry: {e}"
        error, warning = comm.bcast((error, warning), root=0)
        if error:
            raise ValueError(error)
        if warning:

            warnings.warn(warning, RuntimeWarning, stacklevel=3)
        yield
    finally:
        gmsh.finalize()


def to_dolfinx(comm: MPI.Comm, model: GmshModel, verbose: bool = False) -> MeshData:
    """Build ``model`` on rank 0 and distribute it with ``gmshio.model_to_mesh``."""
    from dolfinx.io import gmshio  # heavy: FE stack

    with _built(comm, model, verbose):
        import gmsh  # heavy: gmsh (not needed to read mesh files)

        mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    mesh.name = "mesh"
    return MeshData(mesh, cell_tags, facet_tags, dict(model.volumes), dict(model.faces))


def write_msh(comm: MPI.Comm, model: GmshModel, path: Path, verbose: bool = False) -> None:
    """Build ``model`` on rank 0 and save it as a gmsh ``.msh`` (physical groups named, tagged elements
    only); ``fem-squeal convert`` takes it on to Abaqus, Nastran or VTU."""
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    with _built(comm, model, verbose):
        if comm.rank == 0:
            for dim, tags in ((3, model.volumes), (2, model.faces)):
                for name, tag in tags.items():
                    gmsh.model.setPhysicalName(dim, tag, name)
            gmsh.option.setNumber("Mesh.SaveAll", 0)
            gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
            gmsh.write(str(path))
    comm.barrier()
