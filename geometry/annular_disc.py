"""Annular disc (flat ring) for the Poisson-contraction squeal case of seed 003 (Ryzhik).

The disc's mid-plane is z = 0 and its axis is z.  Faces: ``top`` (z = +h/2), ``bottom``
(z = -h/2), ``inner`` (r = r_i) and ``outer`` (r = r_o); volume ``disc``.
"""
from __future__ import annotations

import math

from mpi4py import MPI

from geometry.gmsh_io import GmshModel, MeshData, to_dolfinx
from geometry.tags import ANNULAR_DISC_FACES, ANNULAR_DISC_VOLUMES


def _face_radius(model, tag: int) -> float:
    """Radius of a point in the middle of the parametric domain of a face (OCC-exact)."""
    lo, hi = model.getParametrizationBounds(2, tag)
    x, y, _ = model.getValue(2, tag, [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])])
    return math.hypot(x, y)


def build_annular_disc(model, inner_radius: float, outer_radius: float, thickness: float,
                       mesh_size: float) -> None:
    """Add the ring r_i <= r <= r_o, |z| <= h/2 to ``model`` with physical groups and sizes.

    Flat faces are told apart by the z of their centre of mass, cylindrical faces by the radius
    of a point on them (their centres of mass both lie on the axis; OCC bounding boxes are padded).
    """
    if not 0 < inner_radius < outer_radius:
        raise ValueError(f"geometry: need 0 < inner_radius < outer_radius (got {inner_radius}, {outer_radius})")
    if thickness <= 0 or mesh_size <= 0:
        raise ValueError(f"geometry: thickness and mesh_size must be > 0 (got {thickness}, {mesh_size})")
    occ = model.occ
    h = thickness
    outer = occ.addCylinder(0, 0, -h / 2, 0, 0, h, outer_radius)
    inner = occ.addCylinder(0, 0, -h / 2, 0, 0, h, inner_radius)
    (vol,), _ = occ.cut([(3, outer)], [(3, inner)])
    occ.synchronize()
    surfaces = [t for d, t in model.getBoundary([vol], oriented=False) if d == 2]
    named: dict[str, list[int]] = {k: [] for k in ANNULAR_DISC_FACES}
    r_mid = 0.5 * (inner_radius + outer_radius)
    for s in surfaces:
        z = occ.getCenterOfMass(2, s)[2]
        if abs(z - h / 2) < 1e-6 * h:
            named["top"].append(s)
        elif abs(z + h / 2) < 1e-6 * h:
            named["bottom"].append(s)
        else:
            named["inner" if _face_radius(model, s) < r_mid else "outer"].append(s)
    for name, tags in named.items():
        if not tags:
            raise RuntimeError(f"annular disc: face {name!r} not identified")
        model.addPhysicalGroup(2, tags, ANNULAR_DISC_FACES[name])
        model.setPhysicalName(2, ANNULAR_DISC_FACES[name], name)
    model.addPhysicalGroup(3, [vol[1]], ANNULAR_DISC_VOLUMES["disc"])
    model.setPhysicalName(3, ANNULAR_DISC_VOLUMES["disc"], "disc")
    import gmsh  # heavy: gmsh (not needed to read mesh files)
    gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.25 * mesh_size)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)


def annular_disc_model(*, mean_radius: float, width: float, thickness: float, mesh_size: float,
                       order: int = 2) -> GmshModel:
    """The ring of mean radius R, radial width b and axial thickness h, as a gmsh model to build."""
    r_i, r_o = mean_radius - width / 2, mean_radius + width / 2
    return GmshModel(lambda m: build_annular_disc(m, r_i, r_o, thickness, mesh_size), order,
                     dict(ANNULAR_DISC_VOLUMES), dict(ANNULAR_DISC_FACES))


def annular_disc_mesh(comm: MPI.Comm, **params) -> MeshData:
    """Distributed ring mesh; ``params`` as :func:`annular_disc_model`."""
    return to_dolfinx(comm, annular_disc_model(**params))
