"""The factorisation factory (fem_squeal.fe.factorisation): typed defaults, the user's options over
them, and nothing left in PETSc's options database after a solve."""
from __future__ import annotations

import os

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


def _factor_files(folder) -> dict[str, int]:
    return {p.name: p.stat().st_size for p in folder.iterdir()}


def test_factors_out_of_core_go_to_files_and_solve_as_in_core(tmp_path, monkeypatch):
    """Inside ``factors_out_of_core`` a MUMPS factorisation writes its factors to files in the folder
    given (MUMPS reads $MUMPS_OOC_TMPDIR when it factorises), as many bytes as its INFOG(9) entries
    (8 each: the whole factor), and solves to what the in-core factor gives (the same factor, stored
    elsewhere: 1e-13 relative, rounding of a 3D Laplacian's solve); destroying the factor removes the
    files; afterwards the environment and the options database are as before.  A MUMPS ICNTL(22) the
    user gives wins (0: in core), and an eigensolver's spectral transformation gets the default too."""
    from fem_squeal.fe.eigen.options import eps_defaults
    from fem_squeal.fe.factorisation import factors_out_of_core, out_of_core_folder

    monkeypatch.delenv("MUMPS_OOC_TMPDIR", raising=False)
    A, before = _laplacian(4000), _database()
    b = A.createVecLeft()
    b.setArray(np.sin(np.arange(4000.0)))
    x_in, x_out = b.duplicate(), b.duplicate()
    ksp = factor_solver(A, LU, "ooc_test_")
    ksp.solve(b, x_in)
    ksp.destroy()
    folder = tmp_path / "factors"
    folder.mkdir()
    with factors_out_of_core(str(folder)):
        assert out_of_core_folder() == str(folder)
        assert eps_defaults("e_", LU)["e_st_mat_mumps_icntl_22"] == "1"
        assert "e_st_mat_mumps_icntl_22" not in eps_defaults("e_", LU.with_(package="cholmod"))
        ksp = factor_solver(A, LU, "ooc_test_")
        F = ksp.getPC().getFactorMatrix()
        files = _factor_files(folder)
        assert F.getMumpsIcntl(22) == 1 and files and sum(files.values()) == 8 * F.getMumpsInfog(9)
        ksp.solve(b, x_out)
        F = None                                               # the factor's last handle with the KSP's
        ksp.destroy()
        assert not _factor_files(folder)                       # MUMPS removed its files
        kept = factor_solver(A, LU, "ooc_test_", {"ooc_test_mat_mumps_icntl_22": 0})
        assert kept.getPC().getFactorMatrix().getMumpsIcntl(22) == 0 and not _factor_files(folder)
        kept.destroy()
    assert out_of_core_folder() is None and "MUMPS_OOC_TMPDIR" not in os.environ
    assert _database() == before
    x_out.axpy(-1.0, x_in)
    assert x_out.norm() <= 1e-13 * x_in.norm()
    assert "ooc_test_mat_mumps_icntl_22" not in LU.options("ooc_test_")
