"""Forms compiled by the JIT (real literals lifted into constants) and assembled into PETSc matrices with
the Dirichlet rows and columns of the operators; the vector masses from one scalar mass."""
from __future__ import annotations

import logging

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc
from ufl.algorithms.map_integrands import map_integrand_dags
from ufl.corealg.multifunction import MultiFunction

from fem_squeal.fe import cell_assembly, hexahedra, kernels

# The JIT's compiler driver logs INFO lines through the root logger: keep only warnings from it.
logging.getLogger().addFilter(lambda rec: rec.name != "root" or rec.levelno >= logging.WARNING)


JIT_PARAMS = {"cffi_extra_compile_args": ["-O2"]}


class _LiftFloats(MultiFunction):
    """Each real literal of a form (material values, k_n, μ, ... given as Python floats) becomes a
    ``fem.Constant`` holding it: the form's signature, which keys FFCx's compiled-form cache
    (``~/.cache/fenics``, or ``$XDG_CACHE_HOME/fenics``), then depends on the form's structure only, so
    a scene run with another E or μ, in this process or another, reuses the compiled code."""

    expr = MultiFunction.reuse_if_untouched

    def __init__(self, domain):
        super().__init__()
        self.domain = domain

    def float_value(self, o):
        return fem.Constant(self.domain, PETSc.ScalarType(float(o)))


def _compile(a, quadrature_degree):
    """JIT-compile ``a``; ``quadrature_degree`` (``discretisation.quadrature_degree``) goes into each
    integral's metadata: FFCx 0.5 ignores it as a form-compiler parameter (it was silently unused).
    Real literals are lifted into constants (:class:`_LiftFloats`): compiled once per form structure.
    Not set, on a hexahedral mesh: the 2 × 2 × 2 Gauss rule on the cell integrals
    (:mod:`~fem_squeal.fe.hexahedra`)."""
    if quadrature_degree is not None:
        a = ufl.Form([itg.reconstruct(metadata={"quadrature_degree": quadrature_degree, **itg.metadata()})
                      for itg in a.integrals()])
    else:
        a = hexahedra.with_cell_rule(a)
    a = map_integrand_dags(_LiftFloats(a.ufl_domain()), a)
    return fem.form(a, form_compiler_params={}, jit_params=JIT_PARAMS)


def _assemble(form, pattern: fem.FormMetaClass, bcs, diagonal: float, bc_dofs: np.ndarray | None = None
              ) -> PETSc.Mat:
    """The matrix of ``form`` on the sparsity of ``pattern``, Dirichlet rows and columns of ``bcs``
    zero with ``diagonal`` on them.  A cell-integral form on its own pattern goes through
    :mod:`fem_squeal.fe.cell_assembly` (on one rank the same matrix, bit for bit, without PETSc's
    per-entry insertion; on N ranks each rank's rows whole); it needs the unrolled DOFs of ``bcs``
    as ``bc_dofs``."""
    if pattern is form and (not bcs or bc_dofs is not None):
        A = cell_assembly.assemble_matrix(form, bc_dofs if bcs else np.zeros(0, dtype=np.int32), diagonal)
        if A is not None:
            kernels.note("assembly", "compiled" if A.getComm().getSize() == 1 else "compiled, rank-local rows")
            return A
    kernels.note("assembly", "dolfinx")
    A = fem_petsc.create_matrix(pattern)
    fem_petsc.assemble_matrix(A, form, bcs=bcs, diagonal=diagonal)
    A.assemble()
    return A


def assemble_form(a: ufl.Form, quadrature_degree, bcs, diagonal: float, bc_dofs: np.ndarray
                  ) -> tuple[PETSc.Mat, fem.FormMetaClass | None]:
    """The matrix of the UFL form ``a`` on its own pattern (Dirichlet rows and columns of ``bcs``,
    unrolled DOFs ``bc_dofs``, zero with ``diagonal`` on them), its cell integrals by the compiled
    path (:func:`_assemble`) and its exterior-facet integrals (springs, plates) then added by dolfinx
    into that matrix, where their cells are among the cell integrals' (so their entries are in the
    pattern): dolfinx's own order, cells then facets, so on one rank the matrix is dolfinx's bit for
    bit.  Anything else (interior facets, a cell-only or facet-only form) is :func:`_assemble` of
    the whole form.  Returns the matrix and the whole form compiled (None where it was split: the
    caller compiles it only where it needs its pattern)."""
    cells = [itg for itg in a.integrals() if itg.integral_type() == "cell"]
    rest = [itg for itg in a.integrals() if itg.integral_type() != "cell"]
    if cells and rest and all(itg.integral_type() == "exterior_facet" for itg in rest):
        fc = _compile(ufl.Form(cells), quadrature_degree)
        A = _assemble(fc, fc, bcs, diagonal, bc_dofs)
        fr = _compile(ufl.Form(rest), quadrature_degree)
        cell_t, facet_t = fem.IntegralType.cell, fem.IntegralType.exterior_facet
        covered = np.concatenate([fc.domains(cell_t, i) for i in fc.integral_ids(cell_t)])
        facet_cells = [np.asarray(fr.domains(facet_t, i)).reshape(-1, 2)[:, 0] for i in fr.integral_ids(facet_t)]
        inside = all(np.isin(c, covered).all() for c in facet_cells)
        if A.getComm().tompi4py().allreduce(bool(inside), op=MPI.LAND):
            # the Dirichlet rows are zero in the facet element matrices; their diagonal is inserted again
            fem_petsc.assemble_matrix(A, fr, bcs=bcs, diagonal=diagonal)
            A.assemble()
            return A, None
        A.destroy()
    f = _compile(a, quadrature_degree)
    return _assemble(f, f, bcs, diagonal, bc_dofs), f


def _owned_global_rows(A: PETSc.Mat, V, local_dofs: np.ndarray) -> np.ndarray:
    bs = V.dofmap.index_map_bs
    n_owned = V.dofmap.index_map.size_local * bs
    lo = A.getOwnershipRange()[0]
    local_dofs = np.asarray(local_dofs)
    return (local_dofs[local_dofs < n_owned] + lo).astype(PETSc.IntType)


def _add(A: PETSc.Mat, B: PETSc.Mat, alpha: float = 1.0) -> None:
    A.axpy(alpha, B, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)


def _block_masses(V, a_scalar, quadrature_degree, weights: list[np.ndarray], bc_dofs: np.ndarray,
                  pattern: PETSc.Mat) -> list[PETSc.Mat] | None:
    """The vector masses M_W = M_s ⊗ W (one per b×b weight W) from ONE assembly of the scalar mass
    M_s = ∫ ρ φ_i φ_j dx (``a_scalar``, on the scalar space of V's element): ∫ ρ (W u)·v dx has
    the block W M_s(i, j) between nodes i and j.  W = I gives M = ∫ ρ u·v dx, W = a aᵀ the axial
    mass ∫ ρ (u·a)(v·a) dx.  Only W's non-zero entries are stored (M: b× fewer than on K's 3×3
    blocks), and the rows and columns of ``bc_dofs`` are left out (as a Dirichlet assembly with
    diagonal 0 leaves them zero).  Inserting the b²× smaller element matrices of the scalar form is
    what saves the time: 255k DOFs, P2: 0.17 s for M_s against 1.0 s for each vector mass; the
    expansion (:func:`fem_squeal.fe.cell_assembly.kronecker`) takes 0.05 s.

    On more than one rank the expansion is made from each rank's own rows of the parallel M_s
    (:func:`fem_squeal.fe.cell_assembly.kronecker_rows`): the 255k-DOF disc's two vector masses on
    2 ranks took 2.1 s through dolfinx's assembly (scratch profile, 2026-11-28).  None when the
    scalar space does not number its nodes as V numbers its blocks, or where the compiled expansion
    cannot be had."""
    S = fem.FunctionSpace(V.mesh, V.ufl_element().sub_elements()[0])
    bs = V.dofmap.index_map_bs
    im_s, im_v = S.dofmap.index_map, V.dofmap.index_map
    n_nodes = im_v.size_local + im_v.num_ghosts
    same = (np.array_equal(S.dofmap.list.array, V.dofmap.list.array) and im_s.size_local == im_v.size_local
            and np.array_equal(im_s.ghosts, im_v.ghosts) and im_s.local_range == im_v.local_range)
    if not V.mesh.comm.allreduce(same, op=MPI.LAND):
        return None
    u, v = ufl.TrialFunction(S), ufl.TestFunction(S)
    f = _compile(a_scalar(u, v), quadrature_degree)
    Ms = _assemble(f, f, [], 0.0)
    flag = np.zeros(bs * n_nodes, dtype=bool)   # the Dirichlet DOFs (owned, then ghost)
    flag[bc_dofs] = True
    if V.mesh.comm.size > 1:
        owned = np.flatnonzero(flag[:bs * im_v.size_local]) + bs * im_v.local_range[0]
        drop = np.sort(np.concatenate(V.mesh.comm.allgather(owned)))
        out = [cell_assembly.kronecker_rows(Ms, W, drop, pattern) for W in weights]
        kernels.note("assembly", "kronecker, rank-local rows")
    else:
        out = [cell_assembly.kronecker(Ms, W, flag, pattern) for W in weights]
    Ms.destroy()
    if any(M is None for M in out):
        for M in out:
            if M is not None:
                M.destroy()
        return None
    return out
