"""The factorisation factory (fem_squeal.fe.factorisation): typed defaults, the user's options over
them, and nothing left in PETSc's options database after a solve."""
from __future__ import annotations

import numpy as np
import pytest
from petsc4py import PETSc

from fem_squeal.fe.factorisation import CHOLESKY, LU, factor_solver, refactorise, scoped_options, user_option


def _database() -> dict[str, str]:
    return dict(PETSc.Options().getAll())


def _laplacian(n: int) -> PETSc.Mat:
    A = PETSc.Mat().createAIJ([n, n], nnz=3, comm=PETSc.COMM_SELF)
    for i in range(n):
        A.setValue(i, i, 2.0)
        if i:
            A.setValue(i, i - 1, -1.0)
            A.setValue(i - 1, i, -1.0)
    A.assemble()
    return A


def test_options_of_a_factorisation():
    f = CHOLESKY.with_(icntl={13: 1, 24: 1}).with_(icntl={27: 64}, extra={"mat_cholmod_print": "0"})
    assert f.options("x_") == {"x_ksp_type": "preonly", "x_pc_type": "cholesky",
                               "x_pc_factor_mat_solver_type": "mumps", "x_mat_mumps_icntl_13": "1",
                               "x_mat_mumps_icntl_24": "1", "x_mat_mumps_icntl_27": "64",
                               "x_mat_cholmod_print": "0"}
    assert "x_pc_factor_mat_solver_type" not in f.with_(package="").options("x_")


def test_scoped_options_restore_the_database():
    """Defaults fill only what the user did not give; the scene's options win over the command
    line's; afterwards the database is exactly as before (a command-line value restored)."""
    db = PETSc.Options()
    db["fs_test_pc_type"] = "lu"            # as if given on the command line
    before = _database()
    try:
        with scoped_options({"fs_test_pc_type": "cholesky", "fs_test_ksp_type": "preonly"},
                            {"-fs_test_pc_factor_mat_solver_type": "superlu_dist", "fs_test_pc_type": "qr"}):
            assert db.getString("fs_test_pc_type") == "qr"               # scene over command line
            assert db.getString("fs_test_ksp_type") == "preonly"         # a default
            assert user_option("fs_test_pc_factor_mat_solver_type") == "superlu_dist"
        assert _database() == before
        with pytest.raises(RuntimeError), scoped_options({"fs_test_ksp_type": "cg"}):
            raise RuntimeError("a failed set-up")
        assert _database() == before
    finally:
        db.delValue("fs_test_pc_type")


def test_factor_solver_solves_and_leaves_nothing_behind():
    """A MUMPS LU and a user's choice (PETSc's own LU by the scene's options) solve the same
    tridiagonal system; no option stays in the database."""
    before = _database()
    A = _laplacian(20)
    b, x = A.createVecs()
    b.set(1.0)
    exact = np.array([0.5 * (i + 1) * (20 - i) for i in range(20)])     # -u'' = 1, u(0) = u(21) = 0
    for factorisation, options, package in ((LU, None, "mumps"),
                                            (LU, {"fs_user_pc_factor_mat_solver_type": "petsc"}, "petsc")):
        ksp = factor_solver(A, factorisation, "fs_user_", options)
        assert ksp.getPC().getFactorSolverType() == package
        ksp.solve(b, x)
        # a direct solve of the 20×20 Laplacian (condition ~ 180): error ~ κ ε ≈ 4e-14, bound 25× that
        assert np.allclose(x.array_r, exact, rtol=1e-12)
        ksp.destroy()
    assert _database() == before


@pytest.mark.parametrize("factorisation", [LU, CHOLESKY], ids=["lu", "cholesky"])
def test_refactorise_factorises_the_new_values_at_once(factorisation):
    """After the operator's values change, refactorise() leaves the factor of the new values in the PC
    (read through the factor matrix, which a solve does not set up again): the kept factorisation's cost
    rule times it (fem_squeal.fe.preload), and KSPSetUp, which defers it to the next solve, did not."""
    n = 40
    A = _laplacian(n)
    ksp = factor_solver(A, factorisation, "rf_test_")
    b, x = A.createVecs()
    b.setArray(np.linspace(1.0, 2.0, n))
    A.shift(0.7)                            # new values, same pattern
    refactorise(ksp)
    ksp.getPC().getFactorMatrix().solve(b, x)
    r = A.createVecLeft()
    A.mult(x, r)
    r.axpy(-1.0, b)
    assert r.norm() <= 1e-12 * b.norm()     # the old factor would leave ‖0.7 x‖ ≈ 0.3‖b‖
    for obj in (ksp, A, b, x, r):
        obj.destroy()


def test_eigensolvers_apply_the_scenes_options_for_their_solve_only(ring_operators):
    """The scene's options reach the solver (``x_block_size = 0``: SLEPc's Krylov–Schur; MUMPS
    named for its factorisation) and the complex-mode solve's defaults reach its EPS; PETSc's
    options database is the same before and after (defaults and scene options alike: nothing
    keyed to a prefix stays to change a later solve)."""
    from fem_squeal.fe.eigen import solve_complex_modes, solve_real_modes

    ops = ring_operators(kn=0, clamped=("inner",))
    before = _database()
    rm = solve_real_modes(ops.K, ops.M, 6, 0.0, prefix="x_",
                          options={"x_block_size": 0, "x_st_pc_factor_mat_solver_type": "mumps"})
    assert rm.method == "Krylov-Schur" and rm.solver == "mumps"
    assert _database() == before
    default = solve_real_modes(ops.K, ops.M, 6, 0.0, prefix="x_")      # the scene's options are gone
    assert default.method.startswith("block Lanczos") and default.solver != "mumps" or \
        ops.K.getComm().getSize() > 1
    assert _database() == before
    cm = solve_complex_modes(ops.K, ops.M, None, 4, 0.5 * float(rm.freqs_hz[2]), prefix="y_")
    assert cm.method == "linear" and len(cm.eigenvalues) >= 4
    assert _database() == before
    for v in (*rm.vectors, *default.vectors, *cm.vectors_re, *cm.vectors_im):
        v.destroy()
