"""Assemble the PETSc operators of a model: K (elastic + contact springs), K_f, M, C.

All matrices are assembled into the cell sparsity pattern of K, so K − K_f is a cheap
subset-pattern AXPY (facet-only forms keep fewer entries after PETSc's assembly
squeeze).  Dirichlet (clamped) DOFs get 1 on the diagonal of K and 0 on those of
M, C and K_f: they become infinite eigenvalues that shift-invert never returns.
"""
from __future__ import annotations

import logging
import warnings
from typing import NamedTuple

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_squeal import forms
from fem_squeal.model import ModelSpec

# The JIT's compiler driver logs INFO lines through the root logger: keep only warnings from it.
logging.getLogger().addFilter(lambda rec: rec.name != "root" or rec.levelno >= logging.WARNING)

JIT_PARAMS = {"cffi_extra_compile_args": ["-O2"]}


class Operators(NamedTuple):
    """Assembled operators of λ²M + λC + (K − K_f) (all PETSc ``aij``, same pattern)."""

    V: fem.FunctionSpace
    K: PETSc.Mat          # elasticity + contact springs (symmetric), 1 on clamped diagonals
    Kf: PETSc.Mat | None  # friction stiffness incl. μ and sliding sign (asymmetric) or None
    M: PETSc.Mat
    C: PETSc.Mat | None   # Rayleigh damping or None
    M_axial: PETSc.Mat    # mass of the motion along the axis, for in-plane/out-of-plane shares
    bc_dofs: np.ndarray   # local indices of clamped DOFs (blocked x bs)

    def K_total(self) -> PETSc.Mat:
        """K − K_f as a new matrix (K itself when there is no friction)."""
        if self.Kf is None:
            return self.K
        A = self.K.copy()
        # K_f is assembled into K's pattern, but PETSc squeezes its unused slots at assembly:
        # its pattern is a subset of K's, never the same (SAME_NONZERO_PATTERN gives wrong sums).
        A.axpy(-1.0, self.Kf, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return A


def _compile(a, quadrature_degree):
    params = {} if quadrature_degree is None else {"quadrature_degree": quadrature_degree}
    return fem.form(a, form_compiler_params=params, jit_params=JIT_PARAMS)


def _assemble(form, pattern: fem.FormMetaClass, bcs, diagonal: float) -> PETSc.Mat:
    A = fem_petsc.create_matrix(pattern)
    fem_petsc.assemble_matrix(A, form, bcs=bcs, diagonal=diagonal)
    A.assemble()
    return A


def assemble_operators(mesh_data, spec: ModelSpec) -> Operators:
    """Build V = [P_degree]³ on the mesh and assemble K, K_f, M, C and M_axial (see module doc)."""
    mesh, cell_tags, facet_tags = mesh_data.mesh, mesh_data.cell_tags, mesh_data.facet_tags
    if spec.degree == 1:
        warnings.warn("degree 1: P1 tetrahedra lock in bending (ring frequencies +2 % at 158k DOFs, "
                      "degenerate pairs split by as much as the friction effect); use degree 2",
                      stacklevel=2)
    elif spec.degree != 2:
        raise ValueError(f"discretisation.degree: must be 1 or 2 (got {spec.degree})")
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", spec.degree))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=cell_tags)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags)
    present_cells = set(np.concatenate(mesh.comm.allgather(np.unique(cell_tags.values))).tolist())
    present_faces = set(np.concatenate(mesh.comm.allgather(np.unique(facet_tags.values))).tolist())

    a_K = a_M = a_C = a_Mz = None
    axis_c = fem.Constant(mesh, np.asarray(spec.axis, dtype=PETSc.ScalarType))
    for part, mat in spec.materials.items():
        if part not in mesh_data.volumes:
            raise KeyError(f"materials.{part}: no such part; parts of this mesh: {sorted(mesh_data.volumes)}")
        tag = mesh_data.volumes[part]
        if tag not in present_cells:
            raise ValueError(f"materials.{part}: mesh has no cells tagged {tag}")
        dxp = dx(tag)
        k = forms.stiffness_form(u, v, mat.E, mat.nu, dxp)
        m = forms.mass_form(u, v, mat.rho, dxp)
        mz = forms.axial_mass_form(u, v, mat.rho, dxp, axis_c)
        a_K = k if a_K is None else a_K + k
        a_M = m if a_M is None else a_M + m
        a_Mz = mz if a_Mz is None else a_Mz + mz
        if mat.rayleigh_alpha > 0 or mat.rayleigh_beta > 0:
            c = mat.rayleigh_alpha * forms.mass_form(u, v, mat.rho, dxp) + \
                mat.rayleigh_beta * forms.stiffness_form(u, v, mat.E, mat.nu, dxp)
            a_C = c if a_C is None else a_C + c
    missing = sorted(set(mesh_data.volumes) - set(spec.materials))
    if missing:
        raise KeyError(f"materials: no material for part(s) {missing}")

    n = ufl.FacetNormal(mesh)
    x = ufl.SpatialCoordinate(mesh)
    a_f = None
    for plate in spec.plates:
        if plate.face not in mesh_data.faces:
            raise KeyError(f"interfaces: face {plate.face!r} not in mesh; faces: {sorted(mesh_data.faces)}")
        ftag = mesh_data.faces[plate.face]
        if ftag not in present_faces:
            raise ValueError(f"interfaces: mesh has no facets tagged {ftag} ({plate.face})")
        if plate.kn > 0:
            a_K = a_K + forms.contact_form(u, v, plate.kn, n, ds(ftag))
            if plate.mu > 0 and plate.sliding != 0:
                s = forms.circumferential_direction(x, float(plate.sliding))
                f = forms.friction_form(u, v, plate.kn, plate.mu, n, s, ds(ftag))
                a_f = f if a_f is None else a_f + f

    bcs, bc_dofs = [], np.zeros(0, dtype=np.int32)
    if spec.clamped:
        fdim = mesh.topology.dim - 1
        facets = []
        for face in spec.clamped:
            if face not in mesh_data.faces:
                raise KeyError(f"boundary.clamped: face {face!r} not in mesh; faces: {sorted(mesh_data.faces)}")
            facets.append(facet_tags.indices[facet_tags.values == mesh_data.faces[face]])
        facets = np.unique(np.concatenate(facets))
        dofs = fem.locate_dofs_topological(V, fdim, facets)
        zero = np.zeros(3, dtype=PETSc.ScalarType)
        bcs = [fem.dirichletbc(zero, dofs, V)]
        bs = V.dofmap.index_map_bs
        bc_dofs = (dofs[:, None] * bs + np.arange(bs)[None, :]).ravel()

    qd = spec.quadrature_degree
    fK = _compile(a_K, qd)
    K = _assemble(fK, fK, bcs, 1.0)
    M = _assemble(_compile(a_M, qd), fK, bcs, 0.0)
    Mz = _assemble(_compile(a_Mz, qd), fK, bcs, 0.0)
    C = _assemble(_compile(a_C, qd), fK, bcs, 0.0) if a_C is not None else None
    Kf = _assemble(_compile(a_f, qd), fK, bcs, 0.0) if a_f is not None else None
    return Operators(V, K, Kf, M, C, Mz, bc_dofs)
