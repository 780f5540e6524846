"""The kept factorisation with low-rank updates (fem_squeal.fe.kept_factorisation) against a direct
solve of the updated matrix J_k = J_f + Σ (G_n + μ G_t₁)ᵀ diag(d) G_n, assembled explicitly, by both
routes (Woodbury on the points' columns; GMRES preconditioned by the factor); serial and on 2 ranks.
The preload's use of it (the same Newton iterates as refactorising every step) is checked on the brake
corner in tests/integration/test_brake.py."""
from __future__ import annotations

import numpy as np
import pytest
from support.ranks import two_rank_signature

N, POINTS = 240, 60
BC = (0, 1, 2)


def _aij(comm, dense: np.ndarray):
    from petsc4py import PETSc

    rows, cols = dense.shape
    A = PETSc.Mat().createAIJ(((None, rows), (None, cols)), comm=comm)
    A.setPreallocationNNZ(cols)
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    lo, hi = A.getOwnershipRange()
    for i in range(lo, hi):
        nz = np.flatnonzero(dense[i])
        A.setValues([i], nz.astype(PETSc.IntType), dense[i, nz])
    A.assemble()
    return A


def problem():
    """J_f (SPD, clamped rows as identity), point matrices G_n, G_t₁ with a few entries per row,
    μ per point, reference stiffness per point and two later steps' (points opening and closing)."""
    rng = np.random.default_rng(7)
    B = rng.standard_normal((N, N)) * (rng.random((N, N)) < 0.03)
    J = B @ B.T + N * np.eye(N)
    Gn = np.zeros((POINTS, N))
    Gt = np.zeros((POINTS, N))
    for q in range(POINTS):
        cols = rng.choice(N, 6, replace=False)
        Gn[q, cols] = rng.standard_normal(6)
        Gt[q, cols] = rng.standard_normal(6)
    mu = 0.1 + 0.5 * rng.random(POINTS)
    w = 0.5 + rng.random(POINTS)
    kn = 30.0
    ref = np.where(rng.random(POINTS) < 0.6, kn, 0.0)
    steps = []
    for frac in (0.15, 0.3):
        v = ref.copy()
        flip = rng.random(POINTS) < frac
        v[flip] = kn - v[flip]
        steps.append(v)
    return J, Gn, Gt, mu, w, ref, steps


def _with_bc(A: np.ndarray) -> np.ndarray:
    A = A.copy()
    A[list(BC), :] = 0.0
    A[:, list(BC)] = 0.0
    return A


def signature() -> dict:
    """The updated solves of two steps (and the plain J_f solve) against direct solves of the
    assembled J_k, as rank-independent lists."""
    from mpi4py import MPI
    from petsc4py import PETSc

    from fem_squeal.fe.factorisation import CHOLESKY, LU, factor_solver
    from fem_squeal.fe.kept_factorisation import KeptFactorisation, RankOneFamily

    comm = MPI.COMM_WORLD
    J, Gn, Gt, mu, w, ref, steps = problem()
    Jf = _with_bc(J + (Gn + mu[:, None] * Gt).T @ np.diag(w * ref) @ Gn)
    Jf[list(BC), list(BC)] = 1.0
    Jp, Gnp, Gtp = _aij(comm, Jf), _aij(comm, Gn), _aij(comm, Gt)
    ksp = factor_solver(Jp, LU, "kept_test_")
    lo, hi = Gnp.getOwnershipRange()
    fam = RankOneFamily("c/normal", ((Gnp, 1.0), (Gtp, mu[lo:hi])), Gnp)
    kept = KeptFactorisation(ksp, Jp, np.array([i for i in BC if Jp.getOwnershipRange()[0] <= i <
                                                Jp.getOwnershipRange()[1]]), [fam], max_factorisations=1)
    kept.reset({"c/normal": (w * ref)[lo:hi]}, 1.0)
    rlo, rhi = Jp.getOwnershipRange()
    b = np.sin(np.arange(N) + 1.0)
    b[list(BC)] = 0.0
    out = {"errors": [], "columns": []}

    def solved(v, kept=kept) -> tuple[float, bool]:
        """The step with stiffness values ``v``: the updated solve's error against the direct solve of
        the assembled J_k, and whether its own check passed."""
        Jk = Jf + _with_bc((Gn + mu[:, None] * Gt).T @ np.diag(w * (v - ref)) @ Gn)
        x_ref = np.linalg.solve(Jk, b)
        assert kept.prepare({"c/normal": (w * v)[lo:hi]})
        bv, xv = Jp.createVecLeft(), Jp.createVecRight()
        bv.array[:] = b[rlo:rhi]
        ok = kept.solve(bv, xv)
        x = np.concatenate(comm.allgather(xv.array_r.copy()))
        return float(np.linalg.norm(x - x_ref) / np.linalg.norm(x_ref)), bool(ok)

    for v in steps:
        err, ok = solved(v)
        out["errors"].append(err)
        out["columns"].append(kept.columns_computed)
        out.setdefault("ok", []).append(ok)
        out.setdefault("changed", []).append(int(np.count_nonzero(v != ref)))
    # GMRES preconditioned by the factor, where it is the cheaper route (columns made dear): no column
    kept.reset({"c/normal": (w * ref)[lo:hi]}, 1.0)
    kept.note_solve(1e-6)
    kept.column_seconds = 1.0
    for v in steps:
        err, ok = solved(v)
        out.setdefault("krylov_errors", []).append(err)
        out.setdefault("krylov_ok", []).append(ok and kept.route == "krylov")
    out["krylov_columns"] = kept.columns_computed - out["columns"][-1]
    out["krylov_iterations"] = kept.krylov_iterations
    # the user's GMRES options (the scene's, under the factor's prefix) apply: one iteration does not
    # converge, and the step falls back to the columns, still exact; GMRES is not tried again
    kept.reset({"c/normal": (w * ref)[lo:hi]}, 1.0)
    kept.options = {"kept_test_krylov_ksp_max_it": 1}
    err, ok = solved(steps[0])
    out["fallback"] = [err, ok, kept.route, kept.krylov_failed, kept.krylov_iterations - out["krylov_iterations"]]
    # a budget that holds no column: GMRES where its cost is known, else refactorise (whatever
    # max_factorisations says)
    out["union"] = int(np.count_nonzero((steps[0] != ref) | (steps[1] != ref)))
    kept.memory_bytes = 0.0
    kept.reset({"c/normal": (w * ref)[lo:hi]}, 1.0)
    kept.column_seconds = None
    out["no_room_krylov"] = kept.prepare({"c/normal": (w * steps[0])[lo:hi]}) and kept._step[0] == "krylov"
    kept.solve_seconds = kept.iteration_seconds = None
    out["refused"] = not kept.prepare({"c/normal": (w * steps[0])[lo:hi]})
    out["preconditioner"] = preconditioner_only(comm, J, Gn, w, ref, steps, Jp, kept, solved, CHOLESKY,
                                                factor_solver, KeptFactorisation, fam)
    kept.destroy()
    ksp.destroy()
    for A in (Jp, Gnp, Gtp):
        A.destroy()
    del PETSc
    return out


def preconditioner_only(comm, J, Gn, w, ref, steps, Jp, exact_kept, solved, CHOLESKY, factor_solver,
                        KeptFactorisation, fam) -> dict:
    """A kept factorisation that is not J_f's (``exact=False``: the preload's "symmetric" Jacobian): the
    Cholesky of the frictionless J_f, J_f's friction rows left out; every step by GMRES on J_k, never a
    column; GMRES that cannot converge refuses the step (refactorise) instead of taking columns; a
    refactorisation is chosen where it is cheaper, and never for a step without a changed point."""
    Jsym = _with_bc(J + Gn.T @ np.diag(w * ref) @ Gn)
    Jsym[list(BC), list(BC)] = 1.0
    Sp = _aij(comm, Jsym)
    ksp = factor_solver(Sp, CHOLESKY, "kept_sym_")
    kept = KeptFactorisation(ksp, Jp, exact_kept.bc_local + Jp.getOwnershipRange()[0], [fam],
                             max_factorisations=2, exact=False)
    lo, hi = fam.right.getOwnershipRange()
    kept.reset({"c/normal": (w * ref)[lo:hi]}, 1e3)
    out = {"errors": [], "routes": []}
    for v in [ref, *steps]:
        err, ok = solved(v, kept)
        out["errors"].append(err if ok else 1.0)
        out["routes"].append(kept.route)
    out["columns"] = kept.columns_computed
    kept.factor_seconds = 1e-9                       # a refactorisation cheaper than any GMRES step
    out["refactorise"] = [kept.prepare({"c/normal": (w * steps[0])[lo:hi]}),
                          kept.prepare({"c/normal": (w * ref)[lo:hi]})]
    kept.factor_seconds = 1e3
    kept.options = {"kept_sym_krylov_ksp_max_it": 1}
    assert kept.prepare({"c/normal": (w * steps[1])[lo:hi]})
    bv, xv = Jp.createVecLeft(), Jp.createVecRight()
    bv.set(1.0)
    out["failed"] = [kept.solve(bv, xv), kept.krylov_failed, kept.columns_computed]
    for obj in (bv, xv, kept, ksp, Sp):
        obj.destroy()
    return out


def check(sig: dict) -> None:
    """Woodbury is exact: the updated solve equals the direct solve of J_k to round-off (κ(J_k) is
    about 10³ here, so 1e-11 leaves two orders for the r×r dense solve); the residual check passed;
    each point's column is computed once (the second step reuses the first step's)."""
    assert max(sig["errors"]) <= 1e-11, sig["errors"]
    assert all(sig["ok"])
    assert sig["columns"][0] == sig["changed"][0]
    assert sig["columns"][1] == sig["union"] < sig["changed"][0] + sig["changed"][1]
    assert sig["refused"] and sig["no_room_krylov"]
    # GMRES to a relative residual of 1e-11: the error at most κ(J_k) ≈ 10³ times that; J_f⁻¹J_k − I has
    # the rank of the change (9 and 18 points here), so GMRES ends within that many iterations and more
    assert max(sig["krylov_errors"]) <= 1e-8, sig["krylov_errors"]
    assert all(sig["krylov_ok"]) and sig["krylov_columns"] == 0
    assert 0 < sig["krylov_iterations"] <= 2 * (sig["changed"][0] + sig["changed"][1] + 2)
    err, ok, route, failed, its = sig["fallback"]
    assert err <= 1e-11 and ok and route == "update" and failed and its == 1
    pre = sig["preconditioner"]
    # GMRES to 1e-11 on J_k, preconditioned by a factor that lacks the friction rows: the error is within
    # κ(J_k) ≈ 10³ of the residual, as for the exact factor's GMRES above
    assert max(pre["errors"]) <= 1e-8 and set(pre["routes"]) == {"krylov"} and pre["columns"] == 0, pre
    assert pre["refactorise"] == [False, True], pre
    assert pre["failed"] == [False, True, 0], pre


def test_updated_solves_equal_direct_solves():
    check(signature())


@pytest.mark.mpi
def test_updated_solves_on_two_ranks(mpirun, tmp_path):
    check(two_rank_signature(mpirun, "test_kept_factorisation", tmp_path / "sig.json"))
