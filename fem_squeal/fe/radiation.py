"""Equivalent radiated power (ERP) of modes from the normal velocity of the outer surface.

For a mode with complex displacement amplitude x (velocity v = iωx) on the radiating surface S,

    ERP = ½ ρc Σ_faces σ ∫_S |v·n|² dA        [W]   (the time average for Re(v e^{iωt}))

with ρc the characteristic impedance of air (415 Pa·s/m: 1.21 kg/m³ × 343 m/s) and σ the radiation
efficiency (1: every surface radiates as a baffled piston; a value per part).  Assembled once as the
symmetric surface matrix A with xᵀAx = ∫_S σ (x·n)² dA (a facet form on the exterior facets of S),
|v_n|² = ω²(xrᵀA xr + xiᵀA xi) for x = xr + i xi.

The norm: each mode scaled to the modal kinetic energy T = ½ ∫ρ|v|² dV = ½ ω² x^H M x (default
1 J), which gives

    ERP_T = ρc T (x^H A x) / (x^H M x)                (ω cancels)

a property of the shape alone: how much of the mode's motion is normal motion of the outer surface.

The surface S: the boundary facets of the mesh except those covered by a contact partner: the faces
of rigid plates, both faces of spring and bonded interfaces, the slave faces of contact interfaces
(the pad linings), and of their master faces (the disc's friction faces) the facets under the
slave: a facet whose midpoint lies within the size of its cell (longest edge) of a slave quadrature
point; plus the
faces the scene names (``exclude_faces``).
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from fem_squeal.fe.assembly import _compile
from fem_squeal.fe.dense import apply
from fem_squeal.fe.penalty import cell_size
from fem_squeal.util.errors import UnknownNameError

#: characteristic impedance of air [Pa·s/m]: ρ = 1.21 kg/m³ × c = 343 m/s (20 °C)
RHO_C_AIR = 1.21 * 343.0
_MARK = 1


def radiating_facets(mesh_data, spec, exclude_faces=(), contacts=()) -> np.ndarray:
    """Local indices of the exterior facets that radiate (module docstring): the mesh's boundary less
    the faces of ``spec.plates``, both faces of non-contact interfaces, the slave faces of contact
    interfaces, the facets of their master faces under the slave points (``contacts``: the
    (Interface, InterfaceOperator) pairs of :class:`fem_squeal.fe.assembly.Operators`) and
    ``exclude_faces`` (names)."""
    mesh, ft = mesh_data.mesh, mesh_data.facet_tags
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = np.asarray(dmesh.exterior_facet_indices(mesh.topology), dtype=np.int32)

    def tag_of(face: str, where: str) -> int:
        if face not in mesh_data.faces:
            raise UnknownNameError(f"{where}: face {face!r} not in mesh; faces: {sorted(mesh_data.faces)}")
        return mesh_data.faces[face]

    excluded = {tag_of(f, "analyses.cea.radiation.exclude_faces") for f in exclude_faces}
    excluded |= {tag_of(p.face, "interfaces") for p in spec.plates}
    masters = {}
    for it in spec.interfaces:
        excluded.add(tag_of(it.slave, f"interfaces.{it.name}"))
        if it.kind == "contact":
            masters[it.name] = tag_of(it.master, f"interfaces.{it.name}")
        else:
            excluded.add(tag_of(it.master, f"interfaces.{it.name}"))
    drop = np.isin(ft.values, list(excluded))
    covered = [ft.indices[drop]]
    for it, op in contacts:
        if it.name not in masters:
            continue
        cand = ft.indices[ft.values == masters[it.name]]
        points = np.concatenate(mesh.comm.allgather(np.asarray(op.x).reshape(-1, 3)))
        if not len(cand) or not len(points):
            continue
        mid = dmesh.compute_midpoints(mesh, tdim - 1, cand)
        f2c = mesh.topology.connectivity(tdim - 1, tdim)
        h = cell_size(mesh, np.array([f2c.links(f)[0] for f in cand], dtype=np.int32))
        dist = cKDTree(points).query(mid)[0]
        covered.append(cand[dist <= h])
    return np.setdiff1d(facets, np.concatenate(covered)).astype(np.int32)


def surface_matrix(V, mesh_data, facets: np.ndarray, efficiency: Mapping[str, float] | None = None,
                   default_efficiency: float = 1.0) -> tuple[PETSc.Mat, float]:
    """A with xᵀAx = ∫_S σ (x·n)² dA over ``facets`` (σ per part from ``efficiency``, else
    ``default_efficiency``), and the area of S (all ranks)."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    order = np.argsort(facets)
    tags = dmesh.meshtags(mesh, tdim - 1, facets[order], np.full(len(facets), _MARK, dtype=np.int32))
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags)
    n = ufl.FacetNormal(mesh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    sigma = fem.Function(fem.FunctionSpace(mesh, ("DG", 0)))
    sigma.x.array[:] = default_efficiency
    ct = mesh_data.cell_tags
    for part, value in (efficiency or {}).items():
        if part not in mesh_data.volumes:
            raise UnknownNameError(f"analyses.cea.radiation.efficiency.{part}: no such part; parts: "
                                   f"{sorted(mesh_data.volumes)}")
        sigma.x.array[ct.indices[ct.values == mesh_data.volumes[part]]] = value
    form = _compile(sigma * ufl.dot(u, n) * ufl.dot(v, n) * ds(_MARK), None)
    A = fem_petsc.create_matrix(form)
    fem_petsc.assemble_matrix(A, form)
    A.assemble()
    area = mesh.comm.allreduce(fem.assemble_scalar(_compile(fem.Constant(mesh, PETSc.ScalarType(1.0)) * ds(_MARK),
                                                             None)), op=MPI.SUM)
    return A, float(area)


def quadratic_forms(A: PETSc.Mat, modes: list[tuple[PETSc.Vec, PETSc.Vec | None]]) -> np.ndarray:
    """x^H A x = xrᵀA xr + xiᵀA xi of each x = xr + i xi of ``modes`` (A symmetric), over all ranks."""
    comm = A.getComm().tompi4py()
    X = np.zeros((A.getLocalSize()[1], 2 * len(modes)), order="F")
    for j, (xr, xi) in enumerate(modes):
        X[:, 2 * j] = xr.array_r
        if xi is not None:
            X[:, 2 * j + 1] = xi.array_r
    q = comm.allreduce(np.einsum("ij,ij->j", X, apply(A, X)), op=MPI.SUM) if len(modes) else np.zeros(0)
    return q[0::2] + q[1::2]


def erp(surface: np.ndarray, mass: np.ndarray, rho_c: float = RHO_C_AIR, energy: float = 1.0) -> np.ndarray:
    """ERP [W] of modes scaled to the kinetic energy ``energy`` [J]: ρc T (x^H A x)/(x^H M x)
    (module docstring); ``surface`` = x^H A x, ``mass`` = x^H M x."""
    return rho_c * energy * np.asarray(surface) / np.asarray(mass)


def radiated_power(V, mesh_data, spec, M: PETSc.Mat, modes, *, rho_c: float = RHO_C_AIR, energy: float = 1.0,
                   efficiency: Mapping[str, float] | None = None, default_efficiency: float = 1.0,
                   exclude_faces=(), contacts=()) -> tuple[np.ndarray, float]:
    """ERP [W] of each mode of ``modes`` ((xr, xi or None) pairs) at the kinetic energy ``energy``, and
    the radiating area [m²] (the surface of :func:`radiating_facets`)."""
    facets = radiating_facets(mesh_data, spec, exclude_faces, contacts)
    A, area = surface_matrix(V, mesh_data, facets, efficiency, default_efficiency)
    try:
        s = quadratic_forms(A, modes)
    finally:
        A.destroy()
    return erp(s, quadratic_forms(M, modes), rho_c, energy), area
