"""Build a gmsh model on rank 0 and distribute it as a dolfinx mesh with cell and facet tags."""
from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from mpi4py import MPI


class MeshData(NamedTuple):
    """A distributed mesh with its tags and the name -> tag maps of its geometry."""

    mesh: object            # dolfinx.mesh.Mesh
    cell_tags: object       # dolfinx.mesh.MeshTags (volumes = parts)
    facet_tags: object      # dolfinx.mesh.MeshTags (named faces)
    volumes: dict[str, int]
    faces: dict[str, int]


def to_dolfinx(comm: MPI.Comm, build: Callable[[object], None], *, order: int,
               volumes: dict[str, int], faces: dict[str, int], verbose: bool = False) -> MeshData:
    """Run ``build(gmsh.model)`` on rank 0, mesh to ``order``, and distribute with ``model_to_mesh``.

    The builder must add the geometry, the physical groups and the size fields; this function
    generates the 3D mesh, elevates it to ``order`` (curved P2 geometry for ``order=2``) and
    checks that every requested tag is present, raising ``ValueError`` naming missing tags.
    """
    import gmsh
    from dolfinx.io import gmshio

    if order not in (1, 2):
        raise ValueError(f"order: must be 1 or 2 (got {order})")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 1 if verbose else 0)
        gmsh.model.add("fem_squeal")
        error = None
        if comm.rank == 0:
            try:
                build(gmsh.model)
                gmsh.model.mesh.generate(3)
                if order == 2:
                    gmsh.model.mesh.setOrder(2)
                groups = {(d, t) for d, t in gmsh.model.getPhysicalGroups()}
                missing = [f"volume {n}={t}" for n, t in volumes.items() if (3, t) not in groups]
                missing += [f"face {n}={t}" for n, t in faces.items() if (2, t) not in groups]
                if missing:
                    error = f"gmsh model lacks physical groups: {', '.join(missing)}"
            except Exception as e:  # broadcast, or the other ranks would wait forever
                error = f"geometry: {e}"
        error = comm.bcast(error, root=0)
        if error:
            raise ValueError(error)
        mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    finally:
        gmsh.finalize()
    mesh.name = "mesh"
    return MeshData(mesh, cell_tags, facet_tags, dict(volumes), dict(faces))
