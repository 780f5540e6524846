"""Nonlinear static preload with unilateral penalty contact, and its linearisation.

Seed 000 eq. 4: K u + F_nl(u) = F_ext, then eq. 6 linearises about the equilibrium.  At every
slave quadrature point q of a contact interface the normal gap is g = g₀ + (G_n u)_q and the
penalty law gives the normal traction σ(g) = k_n g + k₃ g³ for g < 0 (closed), 0 for g ≥ 0
(open); the pressure is p = −σ.  Sliding friction pulls the slave along the master's motion s
with μ p, so the internal force and its Jacobian are

    R(u) = K u + Σ_i [G_nᵀ + μ G_sᵀ] (w σ(g)) + G_t₂ᵀ diag(w k_t χ) G_t₂ u − f,
    J(u) = K + Σ_i [G_nᵀ + μ G_sᵀ] diag(w σ'(g)) G_n + G_t₂ᵀ diag(w k_t χ) G_t₂,

with χ = 1 on the closed points (σ' > 0) and k_t the tangential penalty across the sliding
direction t₂ = n × t₁ (both tangents, t₁ too, for sliding = 0; k_t = 0 by default).  The
tangential relative displacement is measured from the undeformed state (contact at u = 0).

Newton on R is the semi-smooth (active-set) Newton method: with k₃ = 0 each step solves the
problem exactly for the current set of closed points, and it stops when the set no longer changes
and ‖R‖ ≤ tol‖f‖.  The Jacobian at the solution, restricted to the closed points, is the
stiffness of the "partial nonlinear perturbed" CEA (``linearise`` with the active sets).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.assembly import Operators, _owned_global_rows, contact_matrices
from fem_squeal.fe.eigen import set_options
from fem_squeal.reduced.laws.contact import UnilateralLaw
from fem_squeal.util.errors import ModelError, PreloadError


class PreloadResult(NamedTuple):
    u: PETSc.Vec                      # static displacement
    active: dict[str, np.ndarray]     # closed quadrature points per contact interface (rank-local)
    gap: dict[str, np.ndarray]        # normal gap g at the quadrature points
    pressure: dict[str, np.ndarray]   # contact pressure p = −σ(g) ≥ 0
    normal_force: dict[str, float]    # ∫ p dA per interface (global)
    friction_force: dict[str, float]  # ∫ μ p dA per interface (global)
    contact_area: dict[str, float]    # closed area per interface (global)
    iterations: int
    history: list[tuple[int, float]]  # (closed points, ‖R‖/‖f‖) per iteration


def _traction(g: np.ndarray, kn: float, k3: float) -> tuple[np.ndarray, np.ndarray]:
    """Normal traction σ = −p (≤ 0) per unit area and dσ/dg at gaps ``g``, from the cubic unilateral law
    of the reduced layer (one definition: p = k_n δ + k_3 δ³ for the closure δ = −g > 0, else 0)."""
    law = UnilateralLaw(k_l=kn, k_nl=k3)
    return 0.0 - law.force(-g), law.stiffness(-g)   # 0.0 - F: open points give +0.0, not -0.0


def _lu(A: PETSc.Mat, options: dict | None, prefix: str) -> PETSc.KSP:
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    set_options(prefix, options, {"ksp_type": "preonly", "pc_type": "lu",
                                  "pc_factor_mat_solver_type": "mumps"})
    ksp.setOperators(A)
    ksp.setFromOptions()
    return ksp


def solve_preload(ops: Operators, *, friction: bool = True, k3: float = 0.0, tol: float = 1e-9,
                  max_iterations: int = 25, options: dict | None = None,
                  prefix: str = "preload_") -> PreloadResult:
    """Static equilibrium under ``ops.f`` with unilateral contact on ``ops.contacts`` (module doc).

    Starts from u = 0 with the touching points (g₀ ≤ 0) closed.  Raises :class:`PreloadError`
    with the per-iteration history if it does not converge in ``max_iterations``."""
    if ops.f is None:
        raise ModelError("loads: the preload needs a load (e.g. loads.pressure on the piston)")
    comm = ops.K.getComm().tompi4py()
    bc_rows = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
    u = ops.K.createVecRight()
    u.set(0.0)
    R, du, t = u.duplicate(), u.duplicate(), u.duplicate()
    fnorm = ops.f.norm()
    if fnorm == 0:
        raise ModelError("loads: the load vector is zero")
    # size of the model, for the "touching" tolerance of the initial gaps
    h = comm.allreduce(max([float(np.max(np.abs(op.x), initial=0.0)) for _, op in ops.contacts] + [0.0]),
                       op=MPI.MAX) or 1.0
    prev = None
    history: list[tuple[int, float]] = []
    gaps: dict[str, np.ndarray] = {}
    J: PETSc.Mat | None = None
    ksp: PETSc.KSP | None = None
    for k in range(max_iterations + 1):
        # gaps, tractions and residual at u
        ops.K.mult(u, R)
        R.axpy(-1.0, ops.f)
        tangents, closed = {}, {}
        for it, op in ops.contacts:
            gn = op.Gn.createVecLeft()
            op.Gn.mult(u, gn)
            g = op.gap0 + gn.array
            # first step: the touching points (g₀ ≈ 0, where σ = 0 still) start closed
            closed[it.name] = op.gap0 <= 1e-12 * h if k == 0 else g < 0.0
            gaps[it.name] = g
            sig, dsig = _traction(g, it.kn, k3)
            if k == 0:
                dsig = np.where(closed[it.name], it.kn, 0.0)
            gn.array[:] = op.weight * sig
            op.Gn.multTransposeAdd(gn, R, R)
            if friction and it.has_friction:
                op.Gt1.multTranspose(gn, t)
                R.axpy(it.mu, t)
            if it.kt > 0:   # tangential penalty on the closed points: G_t₂ᵀ W k_t (G_t₂ u) (+ t₁ if stuck)
                rows = [op.Gt2] if it.sliding != 0 else [op.Gt2, op.Gt1]
                for Gt in rows:
                    gt = Gt.createVecLeft()
                    Gt.mult(u, gt)
                    gt.array[:] *= op.weight * it.kt * (dsig > 0)
                    Gt.multTransposeAdd(gt, R, R)
                    gt.destroy()
            tangents[it.name] = dsig
            gn.destroy()
        R.setValues(bc_rows, np.zeros(len(bc_rows)))
        R.assemble()
        rel = R.norm() / fnorm
        n_closed = comm.allreduce(int(sum(int(c.sum()) for c in closed.values())), op=MPI.SUM)
        history.append((n_closed, rel))
        same = prev is not None and comm.allreduce(
            int(all(np.array_equal(prev[n], closed[n]) for n in closed)), op=MPI.MIN) == 1
        if k > 0 and same and rel <= tol:
            break
        if k == max_iterations:
            raise PreloadError(f"preload: no convergence in {max_iterations} Newton iterations; "
                               f"(closed points, ‖R‖/‖f‖) per iteration: {history}")
        prev = closed
        # Jacobian and Newton step.  The contact matrices keep their sparsity whatever the closed
        # points (open ones carry explicit zeros), so J is built once and refilled: the LU then
        # reuses its symbolic analysis (ordering) and only refactorises numerically.
        if J is None:                      # first step: J takes the union of the sparsity patterns
            J = ops.K.copy()
            pattern = PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN
        else:
            J.zeroEntries()
            pattern = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN
            J.axpy(1.0, ops.K, structure=pattern)
        for A in contact_matrices(ops, tangents, friction):
            if A is not None:
                J.axpy(1.0, A, structure=pattern)
                A.destroy()
        if ksp is None:                    # later steps: PETSc sees J's new values and refactorises
            ksp = _lu(J, options, prefix)
        R.scale(-1.0)
        ksp.solve(R, du)
        if ksp.getConvergedReason() < 0:
            raise PreloadError(f"preload: linear solve failed (reason {ksp.getConvergedReason()}) "
                               f"at Newton iteration {k}")
        u.axpy(1.0, du)
    for obj in (R, du, t, ksp, J):
        if obj is not None:
            obj.destroy()
    pressure, normal, fric, area = {}, {}, {}, {}
    for it, op in ops.contacts:
        pressure[it.name] = p = UnilateralLaw(k_l=it.kn, k_nl=k3).force(-gaps[it.name])
        normal[it.name] = comm.allreduce(float(op.weight @ p), op=MPI.SUM)
        fric[it.name] = it.mu * normal[it.name] if it.has_friction and friction else 0.0
        area[it.name] = comm.allreduce(float(op.weight @ (gaps[it.name] < 0)), op=MPI.SUM)
    active = {n: g < 0.0 for n, g in gaps.items()}
    return PreloadResult(u, active, gaps, pressure, normal, fric, area, len(history) - 1, history)
