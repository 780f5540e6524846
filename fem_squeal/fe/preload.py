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

import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe import forms, kernels
from fem_squeal.fe import interface as itf
from fem_squeal.fe.assembly import (
    Operators,
    _compile,
    _owned_global_rows,
    contact_matrices,
    direct_solver,
    plate_friction_fields,
)
from fem_squeal.fe.assembly import static_displacement as assembly_static_displacement
from fem_squeal.fe.factorisation import refactorise, symmetric_solver
from fem_squeal.fe.kept_factorisation import (
    KRYLOV_RTOL,
    KRYLOV_STEPS_AHEAD,
    KRYLOV_STEPS_AHEAD_KEPT,
    KeptFactorisation,
    RankOneFamily,
)
from fem_squeal.fe.model import ModelSpec, sliding_speed, speed_friction
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
    factorisations: int = 0           # factorisations of the Jacobian, the first included (LU; "symmetric":
    #                                   Cholesky of its frictionless part, and LU after a fallback)
    update_columns: int = 0           # columns J_f⁻¹ a_q of the low-rank updates (fe.kept_factorisation)
    krylov_iterations: int = 0        # GMRES iterations of the steps preconditioned by the kept factorisation
    jacobian: str = ""                # how the steps were solved: "update", "refactorise", "symmetric"


def changed_points(a: PreloadResult, b: PreloadResult, comm) -> int:
    """How many contact points are closed in one of the states ``a``, ``b`` and open in the other (all
    ranks' points; collective)."""
    return comm.allreduce(int(sum(np.count_nonzero(a.active[n] != b.active[n]) for n in a.active)), op=MPI.SUM)


#: The loosest relative residual of an inexact Newton step's GMRES while the closed set still changes (1e-2
#: took 55 GMRES iterations at 348k DOFs, 0.1 took 46, the same Newton steps and state to 1e-12)
FORCING_MAX = 0.1
#: The closed set counts as settled for the forcing term (the next step exact, as the last one should be)
#: where at most this share of the closed points changed in the last step (the 348k brake's last change was
#: 1 point of 3554, after which an inexact step and an exact one took 37 GMRES iterations, against 24)
SETTLED_SHARE = 1e-3
#: A state an inexact step reached counts as converged only where ‖R‖/‖f‖ ≤ FORCING_FINAL × tol; else one
#: more step, exact (the 348k brake stopped at 5e-10 after an inexact last step, 4.4e-10 from the exact
#: steps' displacement; the exact ones reach 5e-12 … 7e-12)
FORCING_FINAL = 0.01


def forcing(residuals: list[float], tol: float, settled: bool) -> float:
    """The relative residual the next Newton step's GMRES on the kept factorisation must reach (an
    inexact Newton method, Eisenstat & Walker 1996, choice 2).  While the closed set still changes (not
    ``settled``: more than :data:`SETTLED_SHARE` of the points changed in the last step) a step only has
    to find the next one: η = min(FORCING_MAX, (‖R_k‖/‖R_{k−1}‖)²) (FORCING_MAX for the first), not
    finer than what brings ‖R‖/‖f‖ to a tenth of ``tol`` (``residuals``: ‖R_j‖/‖f‖ so far).  Once it
    stays, the step is exact as every step was before (:data:`~fem_squeal.fe.kept_factorisation.KRYLOV_RTOL`),
    and a state an inexact step reached is accepted only below :data:`FORCING_FINAL` × ``tol``, so the
    state is the exact steps' to round-off.  The brake at 348k DOFs (2 ranks): one LU instead of two
    (docs/validation.md)."""
    if settled or not residuals:
        return KRYLOV_RTOL
    rel = residuals[-1]
    eta = FORCING_MAX if len(residuals) < 2 else min(FORCING_MAX, (rel / residuals[-2]) ** 2)
    return float(max(KRYLOV_RTOL, eta, 0.1 * tol / rel if rel > 0 else 0.0))


def reached(rel: float, tol: float, step_eta: float) -> bool:
    """Whether ‖R‖/‖f‖ = ``rel`` after a step whose GMRES went to ``step_eta`` is converged (the closed set
    unchanged): ≤ ``tol`` after an exact step, ≤ :data:`FORCING_FINAL` × ``tol`` after an inexact one."""
    return rel <= (tol if step_eta <= KRYLOV_RTOL else FORCING_FINAL * tol)


def _traction(g: np.ndarray, kn: float, k3: float) -> tuple[np.ndarray, np.ndarray]:
    """Normal traction σ = −p (≤ 0) per unit area and dσ/dg at gaps ``g``, from the cubic unilateral law
    of the reduced layer (one definition: p = k_n δ + k_3 δ³ for the closure δ = −g > 0, else 0)."""
    law = UnilateralLaw(k_l=kn, k_nl=k3)
    return 0.0 - law.force(-g), law.stiffness(-g)   # 0.0 - F: open points give +0.0, not -0.0


class NewtonFactor:
    """The preload Newton's Jacobian J, its direct solver and kept factorisation (low-rank updates), held
    across the solves of a pressure continuation (:mod:`fem_squeal.fe.preload_continuation`): the next
    pressure's steps are updates of the factorisation of the last one.  Lifecycle: created empty, filled
    by the first :func:`solve_preload` it is given to, reused by the later ones, :meth:`destroy` at the end."""

    def __init__(self):
        self.J: PETSc.Mat | None = None
        self.ksp: PETSc.KSP | None = None
        self.kept: KeptFactorisation | None = None

    def load_rate(self, ops: Operators) -> PETSc.Vec | None:
        """du/ds = J⁻¹ f: the rate of the equilibrium R(u(s)) = K u + F_nl(u) − s f = 0 along the load
        scale, with J the Jacobian of the last Newton step (the kept factorisation and its last update;
        at a converged state, the state's own Jacobian).  None when nothing is kept or the update's
        residual check fails."""
        if self.ksp is None or (self.kept is not None and not self.kept.exact and not self.kept.has_update):
            return None                             # (a preconditioner alone is no solve)
        b = ops.f.copy()
        bc = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
        b.setValues(bc, np.zeros(len(bc)))          # J's clamped rows are identity rows (as R's)
        b.assemble()
        x = b.duplicate()
        if self.kept is not None and self.kept.has_update:
            ok = self.kept.solve(b, x)
        else:
            self.ksp.solve(b, x)
            ok = self.ksp.getConvergedReason() > 0
        b.destroy()
        if not ok:
            x.destroy()
            return None
        return x

    def destroy(self) -> None:
        for obj in (self.kept, self.ksp, self.J):
            if obj is not None:
                obj.destroy()
        self.J = self.ksp = self.kept = None


#: Newton's linear solves (:func:`solve_preload`).  The scene's "auto" is resolved by the pipeline
#: (:func:`fem_squeal.app.resources.preload_jacobian`: the memory model decides).
JACOBIANS = ("update", "refactorise", "symmetric")


def solve_preload(ops: Operators, *, friction: bool = True, k3: float = 0.0, tol: float = 1e-9,
                  max_iterations: int = 25, options: dict | None = None,
                  prefix: str = "preload_", jacobian: str = "update",
                  max_factorisations: int = 2,
                  progress: Callable[[str], None] | None = None,
                  scale: float = 1.0, start: PETSc.Vec | None = None,
                  factor: NewtonFactor | None = None) -> PreloadResult:
    """Static equilibrium under ``scale``·``ops.f`` with unilateral contact on ``ops.contacts`` (module doc).

    Starts from u = 0 with the touching points (g₀ ≤ 0) closed, or from ``start`` (a state, e.g. the
    converged one of another pressure) with its closed points (g < 0); a ``start`` already in equilibrium
    (‖R‖ ≤ tol‖f‖) is accepted without a Newton step.  ``factor`` (a :class:`NewtonFactor`) keeps the
    Jacobian and its factorisation after the solve for the next one (and uses those it holds), instead of
    destroying them.  Raises :class:`PreloadError` with the per-iteration history if it does not converge
    in ``max_iterations``.

    ``jacobian``: "refactorise" factorises J at every Newton step; "update" keeps a factorisation
    and solves the later steps by low-rank updates of it (the points whose stiffness changed) or by
    GMRES preconditioned by it (:mod:`fem_squeal.fe.kept_factorisation`), refactorising when the
    measured cost says it is cheaper, at most ``max_factorisations`` times (unless an update fails its
    residual check); "symmetric" factorises the frictionless Jacobian P = K + Σ G_nᵀ diag(w σ') G_n (+ the
    tangential penalty) by Cholesky (:func:`~fem_squeal.fe.factorisation.symmetric_solver`: half an LU's
    factor, so it stays in core where the LU would not) and solves every step, the first included, by
    GMRES on J preconditioned by it (J − P is the friction term μ G_t₁ᵀ diag(w σ') G_n and the points
    changed since; the step on a fresh factorisation exact, the later ones to the forcing), refactorising
    as "update" does; where GMRES does not converge on a fresh factorisation the solve goes on with LUs
    of J.  Out of core at 1,323,816 DOFs on one rank the preload took 937.7 s by "update" (2 LUs of 327
    and 317 s, every further solve reading the factor back, about 20 s) and 216.6 s by "symmetric" (one
    in-core CHOLMOD Cholesky, 60 GMRES iterations of 1.4 s), the same state (docs/validation.md).  All
    are Newton with exact steps: the same iterates, to round-off (Woodbury) or to GMRES's 1e-11 relative
    residual.  ``progress`` (if given) receives one line per Newton iteration: closed points, ‖R‖/‖f‖,
    how the step was solved and its seconds."""
    if jacobian not in JACOBIANS:
        raise ModelError(f"preload.jacobian: must be one of {', '.join(map(repr, JACOBIANS))} (got {jacobian!r})")
    if ops.f is None:
        raise ModelError("loads: the preload needs a load (e.g. loads.pressure on the piston)")
    comm = ops.K.getComm().tompi4py()
    if not (np.isfinite(scale) and scale > 0):
        raise ModelError(f"preload: the load scale must be > 0 (got {scale!r})")
    bc_rows = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
    u = ops.K.createVecRight()
    if start is None:
        u.set(0.0)
    else:
        start.copy(u)
    R, du, t = u.duplicate(), u.duplicate(), u.duplicate()
    f = ops.f
    if scale != 1.0:
        f = ops.f.copy()
        f.scale(scale)
    fnorm = f.norm()
    if fnorm == 0:
        raise ModelError("loads: the load vector is zero")
    # size of the model, for the "touching" tolerance of the initial gaps
    h = comm.allreduce(max([float(np.max(np.abs(op.x), initial=0.0)) for _, op in ops.contacts] + [0.0]),
                       op=MPI.MAX) or 1.0
    prev = None
    history: list[tuple[int, float]] = []
    gaps: dict[str, np.ndarray] = {}
    J, ksp, kept = (factor.J, factor.ksp, factor.kept) if factor is not None else (None, None, None)
    if kept is not None:
        kept.new_solve()
    cold = start is None               # the first step closes the touching points (else: the state's own)
    symmetric = jacobian == "symmetric" and (kept is None or not kept.exact)
    factorisations = 0
    how, t_step = "", time.perf_counter()         # the last Newton step: how it was solved, when it began
    step_eta = KRYLOV_RTOL                        # ... and its GMRES's relative residual (forcing)
    for k in range(max_iterations + 1):
        # gaps, tractions and residual at u
        ops.K.mult(u, R)
        R.axpy(-1.0, f)
        tangents, closed = {}, {}
        for it, op in ops.contacts:
            gn = op.Gn.createVecLeft()
            op.Gn.mult(u, gn)
            g = op.gap0 + gn.array
            # first step: the touching points (g₀ ≈ 0, where σ = 0 still) start closed
            closed[it.name] = op.gap0 <= 1e-12 * h if k == 0 and cold else g < 0.0
            gaps[it.name] = g
            sig, dsig = _traction(g, it.kn, k3)
            if k == 0 and cold:
                dsig = np.where(closed[it.name], it.kn, 0.0)
            gn.array[:] = op.weight * sig
            op.Gn.multTransposeAdd(gn, R, R)
            if friction and it.has_friction:
                if it.law is None:
                    op.Gt1.multTranspose(gn, t)
                    R.axpy(it.mu, t)
                else:                      # μ(V) per point, V = Ω r
                    gn.array[:] *= it.friction_coefficient(op.x)
                    op.Gt1.multTransposeAdd(gn, R, R)
            if it.kt > 0:   # tangential penalty on the closed points: G_t₂ᵀ W k_t (G_t₂ u) (+ t₁ if stuck)
                for _, Gt in _penalty_tangents(it, op):
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
        if progress is not None:
            progress(f"preload: iteration {k}, {n_closed} closed points, ‖R‖/‖f‖ = {rel:.2e}"
                     + (f"; step {k - 1} by {how} in {time.perf_counter() - t_step:.1f} s" if k else ""))
        changed = -1 if prev is None else comm.allreduce(
            int(sum(np.count_nonzero(prev[n] != closed[n]) for n in closed)), op=MPI.SUM)
        same = changed == 0
        if (same or (k == 0 and not cold)) and reached(rel, tol, step_eta):
            break
        if k == max_iterations:
            raise PreloadError(f"preload: no convergence in {max_iterations} Newton iterations; "
                               f"(closed points, ‖R‖/‖f‖) per iteration: {history}")
        prev = closed
        R.scale(-1.0)
        values = _family_values(ops, tangents) if jacobian != "refactorise" else {}
        t_step = time.perf_counter()
        step_eta = KRYLOV_RTOL    # the step's GMRES residual (exact: a factorisation or Woodbury's update)
        # an inexact step while the closed set moves; once it (nearly) stays, an exact one, and GMRES then
        # counted for this step only (the last, unless a continuation's next pressures follow)
        settled = 0 <= changed <= SETTLED_SHARE * n_closed
        ahead = KRYLOV_STEPS_AHEAD_KEPT if factor is not None else (1 if settled else KRYLOV_STEPS_AHEAD)
        if kept is not None and kept.prepare(values, forcing([r for _, r in history], tol, settled), ahead) \
                and kept.solve(R, du):
            u.axpy(1.0, du)
            woodbury = kept.route == "update"
            step_eta = KRYLOV_RTOL if woodbury else kept.rtol
            how = f"update ({kept.columns_computed} columns)" if woodbury else \
                f"GMRES on the kept factorisation ({kept.krylov_guess} iterations to {kept.rtol:.0e})"
            kernels.note("newton_step", f"kept {'' if kept.exact else 'symmetric '}factorisation, "
                         f"{'Woodbury columns' if woodbury else 'GMRES'}")
            continue
        # Jacobian and Newton step.  The contact matrices keep their sparsity whatever the closed
        # points (open ones carry explicit zeros), so J is built once and refilled: the LU then
        # reuses its symbolic analysis (ordering) and only refactorises numerically.
        Kc, Kf = contact_matrices(ops, tangents, friction)
        if symmetric:                      # P = K + K_c, the frictionless Jacobian, factorised instead of J
            P = _refilled(ksp.getOperators()[0] if ksp is not None else None, ops.K, Kc)
        else:
            J = _refilled(J, ops.K, Kc, Kf)
        for A in ((Kc,) if symmetric else (Kc, Kf)):
            if A is not None:
                A.destroy()
        if symmetric:
            if progress is not None:
                progress(f"preload: step {k} by factorisation {factorisations + 1} of the frictionless "
                         f"Jacobian (Cholesky, {P.getSize()[0]} rows)")
            t0 = time.perf_counter()
            if ksp is None:
                ksp = symmetric_solver(P, prefix, options)
            else:
                refactorise(ksp)
            J = _friction_added(J, ksp, Kf)    # J = P + K_f as products (it takes K_f)
            P.destroy()                    # the solver and J hold it
            factorisations += 1
            if kept is None:
                kept = KeptFactorisation(ksp, J, bc_rows, _families(ops, friction),
                                         max_factorisations=max_factorisations, options=options, exact=False)
            kept.reset(values, comm.allreduce(time.perf_counter() - t0, op=MPI.MAX))
            # the step on a fresh factorisation is exact, as an LU's is: an inexact one from a state far
            # from equilibrium overshot a cubic penalty without bound (two tapered pads, k₃ 1e23)
            if kept.prepare(values, KRYLOV_RTOL, ahead) and kept.solve(R, du):
                u.axpy(1.0, du)
                step_eta = kept.rtol
                how = (f"factorisation {factorisations} (frictionless) and GMRES "
                       f"({kept.krylov_guess} iterations to {kept.rtol:.0e})")
                kernels.note("newton_step", f"symmetric factorisation ({ksp.getPC().getFactorSolverType()}), "
                             "GMRES")
                continue
            # GMRES did not converge on the fresh frictionless factorisation: LU of J from here on
            symmetric = False
            P, Kf = J.getPythonContext().terms
            explicit = _refilled(None, P, Kf)
            for obj in (kept, ksp, J):
                obj.destroy()
            kept = ksp = None
            J = explicit
        if progress is not None:           # the preload's longest silent phase (348k DOFs: 17-22 s)
            progress(f"preload: step {k} by factorisation {factorisations + 1} of the Jacobian "
                     f"({J.getSize()[0]} rows)")
        t0 = time.perf_counter()
        if ksp is None:
            ksp = direct_solver(J, options, prefix)
        else:                              # J's new values, factorised now so that the cost rule sees
            refactorise(ksp)               # their seconds (not at the next solve, as KSPSetUp would)
        factorisations += 1
        if jacobian != "refactorise":
            if kept is None:
                kept = KeptFactorisation(ksp, J, bc_rows, _families(ops, friction),
                                         max_factorisations=max_factorisations, options=options)
            kept.reset(values, comm.allreduce(time.perf_counter() - t0, op=MPI.MAX))
        t0 = time.perf_counter()
        ksp.solve(R, du)
        if kept is not None:         # the cost of a GMRES iteration, until one is measured
            kept.note_solve(comm.allreduce(time.perf_counter() - t0, op=MPI.MAX))
        how = f"factorisation {factorisations}"
        kernels.note("newton_step", "factorisation")
        if ksp.getConvergedReason() < 0:
            raise PreloadError(f"preload: linear solve failed (reason {ksp.getConvergedReason()}) "
                               f"at Newton iteration {k}")
        u.axpy(1.0, du)
    columns = kept.columns_computed - kept.columns_before if kept is not None else 0
    krylov = kept.krylov_iterations - kept.krylov_before if kept is not None else 0
    if factor is not None:
        factor.J, factor.ksp, factor.kept = J, ksp, kept
    for obj in ((R, du, t) if factor is not None else (kept, R, du, t, ksp, J)):
        if obj is not None:
            obj.destroy()
    if f is not ops.f:
        f.destroy()
    pressure, normal, fric, area = {}, {}, {}, {}
    for it, op in ops.contacts:
        pressure[it.name] = p = UnilateralLaw(k_l=it.kn, k_nl=k3).force(-gaps[it.name])
        normal[it.name] = comm.allreduce(float(op.weight @ p), op=MPI.SUM)
        if not (it.has_friction and friction):
            fric[it.name] = 0.0
        elif it.law is None:
            fric[it.name] = it.mu * normal[it.name]
        else:                              # ∫ μ(V) p dA
            fric[it.name] = comm.allreduce(float(op.weight @ (it.friction_coefficient(op.x) * p)), op=MPI.SUM)
        area[it.name] = comm.allreduce(float(op.weight @ (gaps[it.name] < 0)), op=MPI.SUM)
    active = {n: g < 0.0 for n, g in gaps.items()}
    return PreloadResult(u, active, gaps, pressure, normal, fric, area, len(history) - 1, history,
                         factorisations, columns, krylov, jacobian if symmetric or jacobian != "symmetric" else
                         "symmetric, then update")


class _FrictionAdded:
    """The "symmetric" preload's GMRES operator J = P + K_f as products (a PETSc ``python`` Mat context): P
    the factorised frictionless Jacobian, K_f = μ G_t₁ᵀ diag(w σ') G_n its friction term, nonzero on the
    contact rows only.  A third matrix of K's pattern is not held beside K and P (1.2 GiB at 1.32M DOFs,
    where the preload's peak decides whether the Cholesky fits: ``app.resources.preload_jacobian``)."""

    def __init__(self, P: PETSc.Mat, Kf: PETSc.Mat | None):
        self.terms: tuple[PETSc.Mat, PETSc.Mat | None] = (P, Kf)

    def replace(self, P: PETSc.Mat, Kf: PETSc.Mat | None) -> None:
        self.destroy(None)
        self.terms = (P, Kf)

    def mult(self, _mat, x: PETSc.Vec, y: PETSc.Vec) -> None:
        P, Kf = self.terms
        P.mult(x, y)
        if Kf is not None:
            Kf.multAdd(x, y, y)

    def destroy(self, _mat) -> None:
        for A in self.terms:
            if A is not None:
                A.destroy()
        self.terms = (None, None)


def _friction_added(J: PETSc.Mat | None, ksp: PETSc.KSP, Kf: PETSc.Mat | None) -> PETSc.Mat:
    """J = P + ``Kf`` as products (:class:`_FrictionAdded`), P the operator ``ksp`` factorised; ``J`` given
    the new terms where it is one already.  J holds a reference of its own to P and takes ``Kf`` (both
    released with J or its next terms)."""
    P = ksp.getOperators()[0]        # a new reference (petsc4py counts it)
    if J is None:
        J = PETSc.Mat().createPython(P.getSizes(), _FrictionAdded(P, Kf), comm=P.getComm())
        J.setUp()
    else:
        J.getPythonContext().replace(P, Kf)
    return J


def _refilled(A: PETSc.Mat | None, *terms: PETSc.Mat | None) -> PETSc.Mat:
    """Σ ``terms`` (None skipped) in ``A``, whose pattern holds theirs (kept from its first filling, so a
    factorisation of it reuses its analysis); a new matrix where ``A`` is None."""
    present = [T for T in terms if T is not None]
    if A is None:
        A = present[0].copy()
        present, pattern = present[1:], PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN
    else:
        A.zeroEntries()
        pattern = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN
    for T in present:
        A.axpy(1.0, T, structure=pattern)
    return A


def _families(ops: Operators, friction: bool) -> list[RankOneFamily]:
    """The Jacobian's per-point stiffness terms (module doc) as rank-one families for the low-rank
    updates (:mod:`fem_squeal.fe.kept_factorisation`): the normal penalty with its friction row
    (G_n + μ G_t₁)ᵀ diag(w σ') G_n, and the tangential penalty G_tᵀ diag(w k_t χ) G_t per tangent."""
    out = []
    for it, op in ops.contacts:
        left: list = [(op.Gn, 1.0)]
        if friction and it.has_friction:
            left.append((op.Gt1, it.mu if it.law is None else it.friction_coefficient(op.x)))
        out.append(RankOneFamily(f"{it.name}/normal", tuple(left), op.Gn))
        if it.kt > 0:
            for name, Gt in _penalty_tangents(it, op):
                out.append(RankOneFamily(f"{it.name}/{name}", ((Gt, 1.0),), Gt))
    return out


def _penalty_tangents(it, op) -> list[tuple[str, PETSc.Mat]]:
    """The tangents the penalty k_t acts along: t₂ (across the sliding direction) for a sliding
    contact, t₂ and t₁ for a sticking one (sliding = 0); the residual, the families and their values."""
    return [("t2", op.Gt2)] if it.sliding != 0 else [("t2", op.Gt2), ("t1", op.Gt1)]


def _family_values(ops: Operators, tangents: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The families' d per point at this step: w σ' (normal) and w k_t χ (tangential, χ = closed)."""
    out = {}
    for it, op in ops.contacts:
        dsig = tangents[it.name]
        out[f"{it.name}/normal"] = op.weight * dsig
        if it.kt > 0:
            for name, _ in _penalty_tangents(it, op):
                out[f"{it.name}/{name}"] = op.weight * it.kt * (dsig > 0)
    return out


def static_displacement(ops: Operators, options: dict | None = None, prefix: str = "preload_") -> PETSc.Vec:
    """The linear static displacement K u = f (rigid plates are bilateral springs in K): the preload of a
    model without contact interfaces, whose plates' pressure k_n (u·n) the friction damping needs
    (:func:`fem_squeal.fe.assembly.static_displacement`, its failure as a :class:`PreloadError`)."""
    if ops.f is None:
        raise ModelError("loads: the preload needs a load (e.g. loads.pressure on the piston)")
    try:
        return assembly_static_displacement(ops.K, ops.f, options, prefix)
    except ModelError:
        raise PreloadError("preload: linear static solve failed; a free body needs boundary conditions "
                           "that hold its rigid-body motions") from None


def friction_damping(ops: Operators, mesh_data, spec: ModelSpec, u: PETSc.Vec | None,
                     pressure: dict[str, np.ndarray] | None) -> PETSc.Mat | None:
    """The friction-damping matrix C_d of the sliding contacts and plates with ``friction_damping``
    (Abaqus ``FRICTION DAMPING=YES``), about the preload: displacement ``u`` (the plates' pressure
    p = k_n max(u·n, 0)) and the contacts' quadrature-point pressures ``pressure`` (PreloadResult).

    Derivation.  At a point with preload pressure p the counter-face (disc, plate) moves at V s
    relative to the body (V = Ω r, s the unit sliding direction, t₂ = n × s); the body's velocity
    relative to the counter-face is v_rel = −V s + a s + b t₂ (a, b: the tangential components of
    the vibration velocity, slave minus master for a contact).  The friction force on the body is

        F = −μ(|v_rel|) p v_rel/|v_rel|.

    To first order in (a, b): |v_rel| = V − a and v_rel/|v_rel| = −s + (b/V) t₂, so

        F = μ(V) p s − p μ'(V) a s − (μ(V) p/V) b t₂.

    The first term is the steady friction force (its pressure variation is K_f); the others are
    forces proportional to the relative velocity.  On the left-hand side of M ü + C u̇ + K u = 0 they
    give the damping per unit area

        C = p μ'(V) s sᵀ + (μ(V) p/V) t₂ t₂ᵀ,

    i.e. C_d = G_t₁ᵀ diag(w p μ') G_t₁ + G_t₂ᵀ diag(w p μ/V) G_t₂ for a contact (the rows G_t₁, G_t₂
    of the interface operator, w the area weights) and the facet form
    ∫ p [μ/V (u·t₂)(v·t₂) + μ' (u·s)(v·s)] ds for a plate.  A transverse velocity turns the friction
    force away from it (μ p/V > 0: positive damping); along s a rising μ(V) damps and a falling
    branch (μ' < 0, Stribeck between v_s and v_d) feeds energy in: negative damping.  μ, μ' come from
    the interface's law (:func:`fem_squeal.fe.model.speed_friction`).  Zero on the clamped DOFs;
    None if no interface asks for it.  The app adds C_d to the operators' C after the preload, so the
    CEA solves the damped PEP and the reduced model projects it into C₀; a μ sweep of the reduced
    model scales K_f, not C_d (frozen at the scene's μ and speed)."""
    bc_rows = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
    total: PETSc.Mat | None = None

    def add(A: PETSc.Mat) -> None:
        nonlocal total
        A.zeroRowsColumns(bc_rows, diag=0.0)
        if total is None:
            total = A
        else:
            total.axpy(1.0, A, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            A.destroy()

    for it, op in ops.contacts:
        if not it.friction_damping:
            continue
        if pressure is None or it.name not in pressure:
            raise ModelError(f"interfaces.{it.name}.friction_damping: needs the contact pressure of the "
                             "nonlinear preload (preload.mode = 'nonlinear')")
        V = sliding_speed(op.x, it.speed)
        mu, dmu = speed_friction(it.mu, it.law, V)
        add(itf.friction_damping_matrix(op, pressure[it.name], mu, dmu, V))
    plates = [pl for pl in spec.plates if pl.friction_damping and pl.kn > 0]
    if plates:
        if u is None:
            raise ModelError("friction_damping: a rigid plate's pressure comes from the static preload "
                             "displacement (loads.pressure)")
        Vh = ops.V
        mesh = Vh.mesh
        uh = fem.Function(Vh)
        uh.x.array[: u.getLocalSize()] = u.array_r
        uh.x.scatter_forward()
        tr, te = ufl.TrialFunction(Vh), ufl.TestFunction(Vh)
        n, x = ufl.FacetNormal(mesh), ufl.SpatialCoordinate(mesh)
        qdeg = spec.quadrature_degree or 4 * spec.degree    # u, v, p, μ: four P_k traces
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=mesh_data.facet_tags,
                         metadata={"quadrature_degree": qdeg})
        a = None
        for pl in plates:
            s = forms.circumferential_direction(x, float(pl.sliding))
            p = pl.kn * ufl.max_value(ufl.dot(uh, n), 0.0)
            speed_V = pl.speed * ufl.sqrt(x[0] ** 2 + x[1] ** 2)
            mu, dmu = (pl.mu, 0.0) if pl.law is None else plate_friction_fields(Vh, pl)
            term = forms.friction_damping_form(tr, te, p, mu, dmu, speed_V, n, s, ds(mesh_data.faces[pl.face]))
            a = term if a is None else a + term
        form = _compile(a, None)
        A = fem_petsc.assemble_matrix(form)
        A.assemble()
        add(A)
    return total
