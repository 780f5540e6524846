"""A kept factorisation updated by low-rank terms (the Sherman–Morrison–Woodbury identity).

The preload's Newton steps (:mod:`fem_squeal.fe.preload`) solve J_k δ = −R with a Jacobian that
differs from the one last factorised, J_f, only at the contact points whose stiffness changed since
(a point that closed or opened, seed 000 eq. 4): one rank-one term per point and stiffness family,

    J_k = J_f + Σ_i a_i d_i b_iᵀ = J_f + A D Bᵀ,

with, for the normal penalty of point q, a = (G_n + μ_q G_t₁)ᵀ e_q, b = G_nᵀ e_q and
d = w_q (σ'_k − σ'_f) (±w_q k_n for the linear penalty), and for a tangential penalty a = b = G_tᵀ e_q.
Then (Woodbury)

    J_k⁻¹ r = y − Z (D⁻¹ + Bᵀ Z)⁻¹ Bᵀ y,   y = J_f⁻¹ r,   Z = J_f⁻¹ A,

which is exact: the Newton iterates are those of a fresh factorisation, to round-off.  Z's columns
depend only on J_f and the point, so they are kept across steps and only new points cost a solve;
they are computed in blocks (one multiple right-hand-side solve of the factor each).  Every solve is
checked by its residual ‖J_k x − r‖ (J_f x by a product with the kept matrix, A D Bᵀ x by products
with the point matrices), so a poorly conditioned update is caught and refactorised instead.

A step whose new points would cost many columns is solved instead by GMRES on J_k (J_f x + A D Bᵀ x,
the same products as the residual check) preconditioned by the kept factorisation alone: J_f⁻¹J_k − I
has the rank of the change, and its spectrum clusters where the penalty of a point dominates its
surroundings, so few iterations reach round-off.  Measured on the brake corner (163,506 DOFs, 2 ranks,
the Jacobians of the exact Newton path, GMRES to 1e-11): 21–25 iterations from the factorisation of the
first step (922 points changed by the last), 15–17 from the second's (268–377 changed).

GMRES goes to ``rtol`` (:data:`KRYLOV_RTOL` unless the caller's inexact Newton step asks less:
:func:`fem_squeal.fe.preload.forcing`).  Which route a step takes is decided by measured cost: the new
columns times the measured seconds per column, GMRES's iterations per decade of residual last measured
(:data:`KRYLOV_GUESS` over 11 decades before any) times the decades the step asks and the seconds per
iteration (a solve with the factor, measured), and the seconds of the last factorisation (while
``max_factorisations``, the first included, allows one); the columns must also fit the memory budget.
Columns and factorisations serve the later steps too, a GMRES step only itself: GMRES counts
:data:`KRYLOV_STEPS_AHEAD` times (:data:`KRYLOV_STEPS_AHEAD_KEPT` where the factorisation serves the next
pressures of a continuation).  Where GMRES does not converge (a cubic penalty, far from the
state), the step takes the columns and GMRES is not tried again on that factorisation.

A factor of another matrix than J_f (``exact=False``: the preload's "symmetric" Jacobian, the Cholesky
of its frictionless part P_f, :func:`fem_squeal.fe.preload.solve_preload`) serves as GMRES's
preconditioner only: J_k = J_f + A D Bᵀ is applied as above, P_f⁻¹ J_k − I has the rank of the friction
term and the change, no Woodbury column is exact, and a GMRES that does not converge refuses the step
(refactorise) instead of taking columns.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.factorisation import scoped_options

#: Columns of the first block of a factor (their time is the first measurement of a column's cost).
PROBE_COLUMNS = 16
#: Columns per multiple right-hand-side solve afterwards (MUMPS's BLAS-3 solve; 16-256 measured on
#: the brake corner at 163k DOFs: 0.033, 0.028, 0.038 s per column for blocks of 16, 64, 256).
BLOCK_COLUMNS = 64
#: Relative residual ‖J_k x − r‖/‖r‖ above which an updated solve is refused (and refactorised).
UPDATE_RESIDUAL = 1e-8
#: GMRES iterations of a step preconditioned by the kept factorisation, until one is measured (the brake
#: corner's 21–25 from its first factorisation; module docstring).
KRYLOV_GUESS = 25
#: GMRES of a step: relative residual ‖J_k x − r‖/‖r‖ reached (the exact routes' round-off is ~1e-12 on the
#: brake; the converged state is then the same to the preload's tolerance) within this many iterations,
#: without restart (the vectors cost n_local·8 bytes each); else the step takes the columns, or
#: refactorises, and GMRES is not tried again on this factorisation.  The linear penalty converged in
#: 15–25; a cubic penalty, whose stiffness changes at every closed point, climbed past 100 (brake, 163k)
KRYLOV_RTOL = 1e-11
KRYLOV_MAX_IT = KRYLOV_RESTART = 60
#: A GMRES step serves only itself; a column or a refactorisation serves this step and the ones after it
#: (the Newton path converging, the next pressures of a continuation): GMRES is compared at this many steps.
#: Brake corner, 2 ranks: 348k DOFs, a cold preload, GMRES after the first factorisation (7.5 s a step
#: against 67 s of columns or a 23 s refactorisation); 163k, the second factorisation and the columns
#: (2.3 s a step against 5.2 s; the continuation's 173 new points 3.3 s): measured cheapest either way.
KRYLOV_STEPS_AHEAD = 3
#: ... and where the factorisation is kept for the next pressures of a continuation (fe.preload_continuation:
#: 10 pressures took 25 Newton steps on the tapered brake, 163k DOFs; at 3 the continuation took 44 s
#: against 30 s with the columns, GMRES leaving nothing for the next pressures to reuse)
KRYLOV_STEPS_AHEAD_KEPT = 10
#: A column of a block solve against one solve with the factor, before the columns' cost is measured
#: (brake corner, 163k DOFs, 2 ranks: 19 ms per column in blocks of 64 against 92 ms per solve)
COLUMN_SHARE = 0.2


@dataclass(frozen=True)
class RankOneFamily:
    """Terms a_q d_q b_qᵀ, one per row q of the point matrices (rank-local rows):
    a_q = Σ_m c_m[q] L_mᵀ e_q (``left`` = ((L_m, c_m), ...), c_m per row or one number) and
    b_q = Rᵀ e_q (``right`` = R).  ``key`` names the family (interface and stiffness)."""

    key: str
    left: tuple[tuple[PETSc.Mat, np.ndarray | float], ...]
    right: PETSc.Mat


def default_memory_budget(comm: MPI.Comm) -> float:
    """Bytes per rank the kept columns may take: a quarter of the machine's memory shared by the ranks
    (every rank counted as on this machine, which errs on the safe side)."""
    try:
        phys = float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        phys = 8e9
    return 0.25 * phys / comm.size


def _decades(rtol: float) -> float:
    """The decades of residual a Krylov solve to ``rtol`` gains (at least 1)."""
    return max(1.0, -math.log10(rtol))


class KeptFactorisation:
    """The factorisation of J_f (``ksp``, ``J`` holding J_f's values) and the low-rank updates of it.

    Lifecycle: :meth:`reset` after each (re)factorisation with the families' stiffness values of J_f;
    :meth:`prepare` with a step's values computes the update (or returns False: refactorise);
    :meth:`solve` applies it (or returns False when its residual check fails)."""

    def __init__(self, ksp: PETSc.KSP, J: PETSc.Mat, bc_rows: np.ndarray, families: list[RankOneFamily], *,
                 max_factorisations: int = 2, memory_bytes: float | None = None,
                 steps_ahead: int = KRYLOV_STEPS_AHEAD, options=None, exact: bool = True):
        self.ksp, self.J = ksp, J
        self.exact = exact          # ksp factorises J_f itself (else a preconditioner of it: GMRES only)
        self.comm = J.getComm().tompi4py()
        self.families = {f.key: f for f in families}
        lo, hi = J.getOwnershipRange()
        self.n_local = hi - lo
        self.bc_local = np.asarray(bc_rows, dtype=np.int64) - lo
        self.max_factorisations = max_factorisations
        self.steps_ahead = steps_ahead                # GMRES's cost counted this many times (a column's once)
        self.options = options                        # the scene's PETSc options (GMRES's, under <prefix>krylov_)
        self.memory_bytes = default_memory_budget(self.comm) if memory_bytes is None else memory_bytes
        self.factorisations = 0
        self.factor_seconds = 0.0
        self.column_seconds: float | None = None
        self.columns_computed = 0
        self.columns_before = 0        # columns_computed when the current solve began (new_solve)
        self.solve_seconds: float | None = None    # one solve with the factor (note_solve)
        self.iteration_seconds: float | None = None  # one GMRES iteration of a Krylov step, measured
        self.krylov_guess = KRYLOV_GUESS            # the iterations of the last Krylov step
        self.krylov_rate = KRYLOV_GUESS / _decades(KRYLOV_RTOL)   # its iterations per decade of residual
        self.rtol = KRYLOV_RTOL                     # the relative residual of the step prepared (forcing)
        self._ahead = steps_ahead                   # ... and the steps its GMRES cost counts for
        self.krylov_iterations = 0                  # GMRES iterations of the Krylov steps, all solves
        self.krylov_before = 0                      # krylov_iterations when the current solve began
        self.route = ""                             # how the last step was solved: "update" or "krylov"
        self.krylov_failed = False                  # GMRES did not converge on this factorisation
        self._reference: dict[str, np.ndarray] = {}
        self._clear()

    # ------------------------------------------------------------------ state
    def _clear(self) -> None:
        self._index: dict[tuple[str, int], int] = {}    # (family, global point row) -> column
        self._n = 0                                       # columns computed (Z[:, :n], Y[k][:, :n])
        self._Z = np.zeros((self.n_local, 0), order="F")
        self._Y = {k: np.zeros((f.right.getLocalSize()[0], 0)) for k, f in self.families.items()}
        self._step: tuple | None = None

    def reset(self, values: dict[str, np.ndarray], seconds: float) -> None:
        """J_f was (re)factorised in ``seconds`` with the families' values ``values``: forget the columns."""
        self.factorisations += 1
        self.factor_seconds = seconds
        self._reference = {k: np.array(v, dtype=float) for k, v in values.items()}
        self.krylov_failed = False
        self._clear()

    def new_solve(self) -> None:
        """A new nonlinear solve (the next pressure of a continuation) starts from this factorisation: it
        counts as the solve's first for ``max_factorisations``; the kept columns stay valid (same J_f)."""
        self.factorisations = 1
        self.columns_before = self.columns_computed
        self.krylov_before = self.krylov_iterations

    def note_solve(self, seconds: float) -> None:
        """A solve with the factor took ``seconds`` (the cost of a GMRES iteration, before one is measured)."""
        self.solve_seconds = seconds

    @property
    def has_update(self) -> bool:
        """Whether the last step was solved by an update (:meth:`solve` then applies that step's J_k)."""
        return self._step is not None

    def may_refactorise(self) -> bool:
        return self.factorisations < self.max_factorisations

    # ------------------------------------------------------------------ the update of a step
    def _changes(self, values: dict[str, np.ndarray]) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """(family, global point rows, d) of the changed points, in the same order on every rank."""
        out = []
        for key, f in self.families.items():
            lo = f.right.getOwnershipRange()[0]
            d = np.asarray(values[key], float) - self._reference[key]
            q = np.flatnonzero(d != 0.0)
            rows = self.comm.allgather(q + lo)
            ds = self.comm.allgather(d[q])
            out.append((key, np.concatenate(rows).astype(np.int64), np.concatenate(ds)))
        return out

    def _krylov_seconds(self) -> float | None:
        """The expected seconds of a Krylov step (None before any solve with the factor was measured)."""
        per = self.iteration_seconds or self.solve_seconds
        return None if per is None or self.krylov_failed else self.krylov_rate * _decades(self.rtol) * per

    def prepare(self, values: dict[str, np.ndarray], rtol: float = KRYLOV_RTOL, steps_ahead: int | None = None
                ) -> bool:
        """Set up the step J_k − J_f for the families' ``values``: True when the step can be solved
        without a refactorisation (by Woodbury on the points' columns, or by GMRES preconditioned by
        the factor, whichever the measured costs say is cheaper), False when a refactorisation is
        cheaper than both (as long as ``max_factorisations`` allows one).  ``rtol``: GMRES's relative
        residual for this step (an inexact Newton step's forcing); ``steps_ahead``: how many steps
        GMRES's cost counts for this one (None: the constructor's)."""
        self.rtol = rtol
        self._ahead = self.steps_ahead if steps_ahead is None else steps_ahead
        changes = self._changes(values)
        new = [(key, int(r)) for key, rows, _ in changes for r in rows if (key, int(r)) not in self._index]
        d = np.concatenate([ds for _, _, ds in changes]) if changes else np.zeros(0)
        total = len(self._index) + len(new)
        fits = not new or self.comm.allreduce(8.0 * self.n_local * (total + 2 * BLOCK_COLUMNS), op=MPI.MAX) <= \
            self.memory_bytes
        krylov = self._krylov_seconds()
        if not self.exact:          # the factor is not J_f's: no Woodbury columns, GMRES unless refactorising
            if len(d) and krylov is not None and self.may_refactorise() and \
                    self.factor_seconds < self._ahead * krylov:
                return False
            self._step = ("krylov", changes, d, values)
            return True
        while new:
            per_column = self.column_seconds if self.column_seconds is not None else \
                (None if self.solve_seconds is None else COLUMN_SHARE * self.solve_seconds)
            costs = {"krylov": None if krylov is None else self._ahead * krylov,
                     "refactorise": self.factor_seconds if self.may_refactorise() else None,
                     "columns": (None if per_column is None else len(new) * per_column) if fits else math.inf}
            known = {k: c for k, c in costs.items() if c is not None}
            # the columns' cost unknown (nothing measured yet): a probe block measures it
            best = min(known, key=known.get) if costs["columns"] is not None else "columns"
            if best == "krylov":
                self._step = ("krylov", changes, d, values)
                return True
            if best == "refactorise" or not fits:
                return False        # refactorise (cheaper; or the columns do not fit, whatever the limit)
            m = PROBE_COLUMNS if self.column_seconds is None else BLOCK_COLUMNS
            block, new = new[:m], new[m:]
            t = time.perf_counter()
            self._compute_columns(block)
            self.column_seconds = self.comm.allreduce(time.perf_counter() - t, op=MPI.MAX) / len(block)
        order = np.array([self._index[(key, int(r))] for key, rows, _ in changes for r in rows], dtype=np.int64)
        r = len(order)
        S = np.zeros((r, r))
        i0 = 0
        for key, rows, _ in changes:
            lo, hi = self.families[key].right.getOwnershipRange()
            mine = np.flatnonzero((rows >= lo) & (rows < hi))
            S[i0 + mine] = self._Y[key][rows[mine] - lo][:, order]
            i0 += len(rows)
        S = self.comm.allreduce(S, op=MPI.SUM)
        S[np.diag_indices(r)] += 1.0 / d
        self._step = ("update", changes, d, order, S)
        return True

    def _compute_columns(self, block: list[tuple[str, int]]) -> None:
        """Z = J_f⁻¹ A for the points of ``block`` (one multiple right-hand-side solve), and the rows
        R_f Z of every family (for Bᵀ Z)."""
        m = len(block)
        A = None
        for key, f in self.families.items():
            lo, hi = f.right.getOwnershipRange()
            cols = [(j, r - lo) for j, (k, r) in enumerate(block) if k == key and lo <= r < hi]
            if self.comm.allreduce(len(cols), op=MPI.SUM) == 0:
                continue
            for L, c in f.left:
                E = PETSc.Mat().createAIJ(((hi - lo, None), (None, m)), nnz=(1, 1), comm=self.comm)
                E.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
                for j, q in cols:
                    E.setValue(q + lo, j, float(c if np.isscalar(c) else c[q]))
                E.assemble()
                P = L.transposeMatMult(E)
                E.destroy()
                if A is None:
                    A = P
                else:
                    A.axpy(1.0, P, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                    P.destroy()
        Ad = PETSc.Mat().createDense(((self.n_local, None), (None, m)), comm=self.comm)
        Ad.setUp()
        a = Ad.getDenseArray()
        a[:] = 0.0
        ai, aj, av = A.getValuesCSR()                 # local rows, global (= block) columns
        a[np.repeat(np.arange(self.n_local), np.diff(ai)), aj] = av
        a[self.bc_local, :] = 0.0                      # J_f's clamped rows are identity rows
        Ad.assemble()
        A.destroy()
        X = Ad.duplicate()
        self.ksp.getPC().getFactorMatrix().matSolve(Ad, X)
        n0 = self._n
        if n0 + m > self._Z.shape[1]:                 # grow the stores by doubling (amortised copies)
            cap = max(2 * self._Z.shape[1], n0 + m)
            self._Z = _grown(self._Z, cap)
            self._Y = {k: _grown(Y, cap) for k, Y in self._Y.items()}
        self._Z[:, n0:n0 + m] = X.getDenseArray()
        for key, f in self.families.items():
            Yb = f.right.matMult(X)
            self._Y[key][:, n0:n0 + m] = Yb.getDenseArray()
            Yb.destroy()
        for j, k in enumerate(block):
            self._index[k] = n0 + j
        self._n = n0 + m
        self.columns_computed += m
        Ad.destroy()
        X.destroy()

    # ------------------------------------------------------------------ the solve
    def solve(self, b: PETSc.Vec, x: PETSc.Vec) -> bool:
        """x = J_k⁻¹ b for the prepared step (Woodbury, or GMRES preconditioned by the factor); False when
        its residual exceeds UPDATE_RESIDUAL ‖b‖ or GMRES does not converge (x is then not to be used)."""
        self.route = self._step[0]
        if self.route == "krylov":
            if self._krylov_solve(b, x):
                return True
            self.krylov_failed = True          # the columns then, unless a refactorisation is cheaper
            if not self.exact:
                return False                   # no columns of a preconditioner: refactorise
            return self.prepare(self._step[3], self.rtol, self._ahead) and self.solve(b, x)
        _, changes, d, order, S = self._step
        self.ksp.solve(b, x)
        if len(order):
            t = np.zeros(len(order))
            i0 = 0
            for key, rows, _ in changes:
                R = self.families[key].right
                lo, hi = R.getOwnershipRange()
                v = R.createVecLeft()
                R.mult(x, v)
                mine = np.flatnonzero((rows >= lo) & (rows < hi))
                t[i0 + mine] = v.array_r[rows[mine] - lo]
                v.destroy()
                i0 += len(rows)
            t = self.comm.allreduce(t, op=MPI.SUM)
            try:
                s = np.linalg.solve(S, t)
            except np.linalg.LinAlgError:
                return False
            x.array[:] -= self._Z[:, order] @ s
        return self._residual(changes, d, x, b) <= UPDATE_RESIDUAL

    def _krylov_solve(self, b: PETSc.Vec, x: PETSc.Vec) -> bool:
        """GMRES on J_k (:meth:`apply`) right-preconditioned by the kept factor, to KRYLOV_RTOL in the
        true residual; the user's options under ``<factor prefix>krylov_`` win (the scene's
        ``solver.petsc_options`` or the command line, e.g. ``preload_krylov_ksp_max_it``)."""
        _, changes, d, _ = self._step
        op = PETSc.Mat().createPython(self.J.getSizes(), _UpdatedJacobian(self, changes, d), comm=self.comm)
        op.setUp()
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOptionsPrefix((self.ksp.getOptionsPrefix() or "") + "krylov_")
        ksp.setOperators(op)
        ksp.setType(PETSc.KSP.Type.GMRES)
        ksp.setGMRESRestart(KRYLOV_RESTART)
        ksp.setPCSide(PETSc.PC.Side.RIGHT)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.setTolerances(rtol=self.rtol, atol=0.0, max_it=KRYLOV_MAX_IT)
        pc = ksp.getPC()
        pc.setType(PETSc.PC.Type.PYTHON)
        pc.setPythonContext(_KeptPreconditioner(self.ksp))
        with scoped_options({}, self.options):
            ksp.setFromOptions()
        try:
            t = time.perf_counter()
            ksp.solve(b, x)
            its = ksp.getIterationNumber()
            self.krylov_iterations += its
            if its:
                self.iteration_seconds = self.comm.allreduce(time.perf_counter() - t, op=MPI.MAX) / its
                self.krylov_guess = its
                self.krylov_rate = its / _decades(self.rtol)
            ok = ksp.getConvergedReason() > 0
        finally:
            ksp.destroy()
            op.destroy()
        return ok and self._residual(changes, d, x, b) <= max(UPDATE_RESIDUAL, 2.0 * self.rtol)

    def apply(self, changes, d: np.ndarray, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """y = J_k x = J_f x + A D Bᵀ x, A D Bᵀ x by products with the point matrices (J_f's clamped
        rows are identity rows: the update has none)."""
        self.J.mult(x, y)
        acc = y.duplicate()
        acc.set(0.0)
        i0 = 0
        for key, rows, _ in changes:
            f = self.families[key]
            lo, hi = f.right.getOwnershipRange()
            v = f.right.createVecLeft()
            f.right.mult(x, v)
            w = np.zeros(hi - lo)
            mine = np.flatnonzero((rows >= lo) & (rows < hi))
            w[rows[mine] - lo] = d[i0 + mine] * v.array_r[rows[mine] - lo]
            for L, c in f.left:
                v.array[:] = w * c
                L.multTransposeAdd(v, acc, acc)
            v.destroy()
            i0 += len(rows)
        acc.array[self.bc_local] = 0.0
        y.axpy(1.0, acc)
        acc.destroy()

    def _residual(self, changes, d: np.ndarray, x: PETSc.Vec, b: PETSc.Vec) -> float:
        """‖J_k x − b‖ / ‖b‖ (:meth:`apply`)."""
        r = b.duplicate()
        self.apply(changes, d, x, r)
        r.axpy(-1.0, b)
        bn = b.norm()
        rel = r.norm() / bn if bn > 0 else r.norm()
        r.destroy()
        return rel

    def destroy(self) -> None:
        self._clear()


class _UpdatedJacobian:
    """The PETSc python-matrix context of J_k (:meth:`KeptFactorisation.apply`)."""

    def __init__(self, kept: KeptFactorisation, changes, d: np.ndarray):
        self.kept, self.changes, self.d = kept, changes, d

    def mult(self, _mat, x: PETSc.Vec, y: PETSc.Vec) -> None:
        self.kept.apply(self.changes, self.d, x, y)


class _KeptPreconditioner:
    """The PETSc python-preconditioner context applying the kept factor J_f⁻¹."""

    def __init__(self, ksp: PETSc.KSP):
        self.ksp = ksp

    def apply(self, _pc, x: PETSc.Vec, y: PETSc.Vec) -> None:
        self.ksp.solve(x, y)


def _grown(a: np.ndarray, columns: int) -> np.ndarray:
    out = np.zeros((a.shape[0], columns), order="F")
    out[:, :a.shape[1]] = a
    return out
