"""gmsh (OCC) builders that write tagged, curved second-order tetrahedral meshes.

Each builder is a small typed function that adds one geometry to the current gmsh model and
creates physical groups with the tags of :mod:`geometry.tags`.  :func:`geometry.gmsh_io.to_dolfinx`
builds on rank 0 and distributes with ``gmshio.model_to_mesh``.  :mod:`geometry.mesh_file` reads
meshes from files (gmsh, Abaqus, Nastran, VTU) and distributes them the same way.  The package
imports nothing from ``fem_squeal``: writing meshes with their sets is ``fem_squeal.app.convert``.
"""
from geometry.annular_disc import annular_disc_mesh, annular_disc_model, build_annular_disc
from geometry.brake_corner import BrakeCornerParams, brake_corner_mesh, brake_corner_model, build_brake_corner
from geometry.gmsh_io import MeshData, to_dolfinx, write_msh
from geometry.mesh_file import mesh_file_mesh

BUILDERS = {"annular_disc": annular_disc_mesh, "brake_corner": brake_corner_mesh, "mesh_file": mesh_file_mesh}
MODELS = {"annular_disc": annular_disc_model, "brake_corner": brake_corner_model}


__all__ = ["BUILDERS", "MODELS", "BrakeCornerParams", "MeshData", "annular_disc_mesh", "annular_disc_model",
           "brake_corner_mesh", "brake_corner_model", "build_annular_disc", "build_brake_corner",
           "mesh_file_mesh", "to_dolfinx", "write_msh"]
