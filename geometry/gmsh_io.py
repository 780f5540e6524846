"""Build a gmsh model on rank 0 and distribute it as a dolfinx mesh with cell and facet tags."""
from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

from mpi4py import MPI


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


@contextmanager
def _built(comm: MPI.Comm, model: GmshModel, verbose: bool) -> Iterator[None]:
    """gmsh initialised, the model built and meshed on rank 0 (3D, elevated to ``order``: curved P2
    geometry for ``order=2``) and every requested tag checked; ``ValueError`` names missing tags."""
    import gmsh

    if model.order not in (1, 2):
        raise ValueError(f"order: must be 1 or 2 (got {model.order})")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 1 if verbose else 0)
        gmsh.model.add("fem_squeal")
        error = None
        if comm.rank == 0:
            try:
                model.build(gmsh.model)
                gmsh.model.mesh.generate(3)
                if model.order == 2:
                    gmsh.model.mesh.setOrder(2)
                groups = {(d, t) for d, t in gmsh.model.getPhysicalGroups()}
                missing = [f"volume {n}={t}" for n, t in model.volumes.items() if (3, t) not in groups]
                missing += [f"face {n}={t}" for n, t in model.faces.items() if (2, t) not in groups]
                if missing:
                    error = f"gmsh model lacks physical groups: {', '.join(missing)}"
            except Exception as e:  # broadcast, or the other ranks would wait forever
                error = f"geometry: {e}"
        error = comm.bcast(error, root=0)
        if error:
            raise ValueError(error)
        yield
    finally:
        gmsh.finalize()


def to_dolfinx(comm: MPI.Comm, model: GmshModel, verbose: bool = False) -> MeshData:
    """Build ``model`` on rank 0 and distribute it with ``gmshio.model_to_mesh``."""
    from dolfinx.io import gmshio

    with _built(comm, model, verbose):
        import gmsh

        mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    mesh.name = "mesh"
    return MeshData(mesh, cell_tags, facet_tags, dict(model.volumes), dict(model.faces))


def write_msh(comm: MPI.Comm, model: GmshModel, path: Path, verbose: bool = False) -> None:
    """Build ``model`` on rank 0 and save it as a gmsh ``.msh`` (physical groups named, tagged elements
    only); ``fem-squeal convert`` takes it on to Abaqus, Nastran or VTU."""
    import gmsh

    with _built(comm, model, verbose):
        if comm.rank == 0:
            for dim, tags in ((3, model.volumes), (2, model.faces)):
                for name, tag in tags.items():
                    gmsh.model.setPhysicalName(dim, tag, name)
            gmsh.option.setNumber("Mesh.SaveAll", 0)
            gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
            gmsh.write(str(path))
    comm.barrier()
