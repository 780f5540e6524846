"""gmsh (OCC) builders that write tagged, curved second-order tetrahedral meshes.

Each builder is a small typed function that adds one geometry to the current gmsh model and
creates physical groups with the tags of :mod:`fem_squeal.tags`.  :func:`geometry.gmsh_io.to_dolfinx`
builds on rank 0 and distributes with ``gmshio.model_to_mesh``.
"""
from geometry.annular_disc import annular_disc_mesh, build_annular_disc
from geometry.brake_corner import BrakeCornerParams, brake_corner_mesh, build_brake_corner
from geometry.gmsh_io import MeshData, to_dolfinx

BUILDERS = {"annular_disc": annular_disc_mesh, "brake_corner": brake_corner_mesh}

__all__ = ["BUILDERS", "BrakeCornerParams", "MeshData", "annular_disc_mesh", "brake_corner_mesh",
           "build_annular_disc", "build_brake_corner", "to_dolfinx"]
