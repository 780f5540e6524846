"""gmsh (OCC) builders that write tagged, curved second-order tetrahedral meshes.

Each builder is a small typed function that adds one geometry to the current gmsh model and
creates physical groups with the tags of :mod:`fem_squeal.tags`.  :func:`geometry.gmsh_io.to_dolfinx`
builds on rank 0 and distributes with ``gmshio.model_to_mesh``.  :mod:`geometry.mesh_file` reads
meshes from files (gmsh, Abaqus, Nastran, VTU) and distributes them the same way.
"""
from pathlib import Path

from geometry.annular_disc import annular_disc_mesh, annular_disc_model, build_annular_disc
from geometry.brake_corner import BrakeCornerParams, brake_corner_mesh, brake_corner_model, build_brake_corner
from geometry.gmsh_io import MeshData, to_dolfinx, write_msh
from geometry.mesh_convert import convert
from geometry.mesh_file import mesh_file_mesh

BUILDERS = {"annular_disc": annular_disc_mesh, "brake_corner": brake_corner_mesh, "mesh_file": mesh_file_mesh}
MODELS = {"annular_disc": annular_disc_model, "brake_corner": brake_corner_model}


def write_geometry(comm, geometry: dict, path: str | Path, scale: float = 1.0) -> list[str]:
    """Write the mesh of a scene's geometry section to ``path`` (any format of ``geometry.mesh_file``)
    with its named parts and faces; coordinates multiplied by ``scale``.  Returns the writer's warnings."""
    import tempfile

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

__all__ = ["BUILDERS", "MODELS", "BrakeCornerParams", "MeshData", "annular_disc_mesh", "annular_disc_model",
           "brake_corner_mesh", "brake_corner_model", "build_annular_disc", "build_brake_corner", "convert",
           "mesh_file_mesh", "to_dolfinx", "write_geometry", "write_msh"]
