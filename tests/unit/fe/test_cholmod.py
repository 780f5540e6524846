"""CHOLMOD called directly (fem_squeal.fe.cholmod) and the real-mode path built on it: the factor
solves what it should (CHOLMOD's solve and the compiled block solve alike), reads one triangle,
keeps a given order, refuses what is not positive definite; the modes it gives are those of PETSc's
CHOLMOD interface; the compiled CSR block product is SciPy's."""
from __future__ import annotations

from contextlib import nullcontext

import numpy as np
import pytest
import scipy.sparse as sp

from fem_squeal.fe import cholmod, eigen
from fem_squeal.fe.eigen import solve_real_modes
from fem_squeal.util import blas

pytestmark = pytest.mark.skipif(not cholmod.available(), reason="libcholmod (SuiteSparse 5) not found")


def _laplacian(m: int, shift: float = 0.0) -> sp.csr_matrix:
    """The 3D 7-point Laplacian on an m³ grid (Dirichlet), minus ``shift`` I: SPD for shift below
    its lowest eigenvalue 3·(2 − 2 cos(π/(m+1))); condition ~ (2(m+1)/π)² ≈ 120 for m = 16."""
    T = sp.diags([-np.ones(m - 1), 2 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])
    Id = sp.identity(m)
    A = sp.kron(sp.kron(T, Id), Id) + sp.kron(sp.kron(Id, T), Id) + sp.kron(sp.kron(Id, Id), T)
    return (A - shift * sp.identity(m ** 3)).tocsr()


def test_block_solve_to_round_off():
    """A X = B for 5 right-hand sides: the relative residual is round-off times the condition
    (~120 · 1e-16); 1e-12 leaves a margin of ~100 for the sums' order."""
    A = _laplacian(16)
    B = np.random.default_rng(0).standard_normal((A.shape[0], 5))
    with cholmod.Cholesky(A.indptr, A.indices, A.data) as F:
        X = F.solve(B)
        x = F.solve(B[:, 2])
        assert X.flags.f_contiguous and X.shape == B.shape and x.shape == (A.shape[0],)
        assert np.linalg.norm(A @ X - B) <= 1e-12 * np.linalg.norm(B)
        # one column takes other BLAS kernels than five: the same to round-off
        assert np.linalg.norm(x - X[:, 2]) <= 1e-13 * np.linalg.norm(X[:, 2])
        assert F.flops > 0 and F.factor_entries >= A.nnz / 2


def _levels() -> list[int]:
    """The builds of the compiled block solve this CPU runs (3: AVX2, 4: AVX-512 too)."""
    got = cholmod._solve_lib()
    return [] if got is None else list(range(3, got[1] + 1))


@pytest.mark.skipif(cholmod._solve_lib() is None, reason="no compiled block solve here (needs GCC, x86-64, AVX2)")
@pytest.mark.parametrize("k", [4, 5, 8, 12, 16])
def test_compiled_block_solve_equals_cholmods(k):
    """The supernodal block solve (compiled, 8 or 16 columns per pass; each build this CPU runs)
    against cholmod_solve2 on the same factor: the same solution to round-off.  Both apply the same
    L in another order of the sums; 1e-13 of max |x| is 100 ulp times the growth of the
    Laplacian's triangular solves (~10 here).  The builds make the same operations per right-hand
    side (8 in one AVX-512 register or two AVX2 ones): equal to the bit.  The factor has panels of
    every width mod 12 (the kernel's 12-column blocks and their tails)."""
    A = _laplacian(14)
    B = np.asfortranarray(np.random.default_rng(5).standard_normal((A.shape[0], k)))
    with cholmod.Cholesky(A.indptr, A.indices, A.data) as F:
        assert F._panels is not None
        widths = np.diff(F._panels[4])
        assert set(widths % 12) == set(range(12)) and np.any(widths >= 24)
        panels = F._panels
        Xs = []
        for level in _levels():
            F._panels = (panels[0], level, *panels[2:])
            Xs.append(F.solve(B))
        F._panels = None                              # CHOLMOD's own solve on the same factor
        Xc = F.solve(B)
        F._panels = panels
    X = Xs[0]
    assert all(np.array_equal(X, Y) for Y in Xs[1:])
    assert X.flags.f_contiguous and X.shape == B.shape
    assert np.max(np.abs(X - Xc)) <= 1e-13 * np.max(np.abs(Xc))
    # residual: round-off times the condition (~100 for m = 14), with a margin of ~100 as above
    assert np.linalg.norm(A @ X - B) <= 1e-12 * np.linalg.norm(B)


def test_only_the_upper_triangle_is_read():
    """Entries below the diagonal are not read: garbage there changes nothing, bit for bit."""
    A = _laplacian(10)
    lower = sp.tril(A, -1).tocsr()
    garbage = (sp.triu(A).tocsr() + 7.5 * lower).tocsr()
    B = np.random.default_rng(1).standard_normal((A.shape[0], 3))
    with cholmod.Cholesky(A.indptr, A.indices, A.data) as F, \
            cholmod.Cholesky(garbage.indptr, garbage.indices, garbage.data) as G:
        assert np.array_equal(F.solve(B), G.solve(B))


def test_a_given_order_is_kept():
    """The natural order of a 3D grid fills far more than CHOLMOD's own (nested dissection or AMD):
    handed in, it is used as given (more factor entries); a random order too, and every order
    solves the same system to round-off."""
    A = _laplacian(12)
    n = A.shape[0]
    B = np.random.default_rng(2).standard_normal((n, 2))
    with cholmod.Cholesky(A.indptr, A.indices, A.data) as own, \
            cholmod.Cholesky(A.indptr, A.indices, A.data, np.arange(n)) as natural, \
            cholmod.Cholesky(A.indptr, A.indices, A.data, np.random.default_rng(3).permutation(n)) as rand:
        assert natural.factor_entries > 1.5 * own.factor_entries
        assert rand.factor_entries > 1.5 * own.factor_entries
        X = own.solve(B)
        for F in (natural, rand):
            assert np.linalg.norm(F.solve(B) - X) <= 1e-12 * np.linalg.norm(X)


def test_not_positive_definite_is_refused():
    A = _laplacian(6, shift=1.0)          # lowest eigenvalue 3(2 − 2cos(π/7)) = 0.65 < 1
    with pytest.raises(cholmod.NotPositiveDefinite, match="not positive definite"):
        cholmod.Cholesky(A.indptr, A.indices, A.data)


def test_close_is_idempotent():
    A = _laplacian(4)
    F = cholmod.Cholesky(A.indptr, A.indices, A.data)
    F.close()
    F.close()


def _factor_values(A: sp.csr_matrix) -> np.ndarray:
    with cholmod.Cholesky(A.indptr, A.indices, A.data) as F:
        return F.factor_values()


def test_the_factor_is_the_same_without_cholmods_openmp_threads(monkeypatch):
    """The factorisation runs with OpenMP's regions off (:func:`fem_squeal.util.blas.serial_openmp`).
    CHOLMOD's OpenMP loops only zero, copy and scatter-subtract (each entry once per update, in the
    same order), so the factor must be identical to the bit.  The 3D Laplacian on 16³ has
    supernodes far above the loops' thresholds (1024 entries, 64 rows)."""
    gomp = blas._gomp()
    if gomp is None or gomp.omp_get_max_active_levels() < 1:
        pytest.skip("no libgomp, or its regions are off in this process: nothing to compare")
    A = _laplacian(16)
    guarded = _factor_values(A)
    monkeypatch.setattr(cholmod, "serial_openmp", nullcontext)
    threaded = _factor_values(A)
    assert guarded.size == threaded.size and np.array_equal(guarded, threaded)


# ------------------------------------------------------------------ the real-mode path

def _same_modes(a, b, M) -> None:
    """The same frequencies to 1e-10 (both converge to residuals ~1e-14: tol 1e-7 on the
    shift-inverted operator, eigenvalue error ~ residual²) and each vector of ``a`` in the span of
    ``b``'s vectors of the same frequency (the ring's sin/cos pairs are double): M-projection
    norm 1 to 1e-8."""
    assert np.max(np.abs(a.freqs_hz / b.freqs_hz - 1)) < 1e-10
    Xa = np.column_stack([v.array_r for v in a.vectors])
    MXb = []
    for v in b.vectors:
        y = M.createVecLeft()
        M.mult(v, y)
        MXb.append(y.array_r.copy())
    MXb = np.column_stack(MXb)
    for j in range(len(a.freqs_hz)):
        twins = np.flatnonzero(np.abs(b.freqs_hz / a.freqs_hz[j] - 1) < 1e-6)
        assert abs(np.linalg.norm(MXb[:, twins].T @ Xa[:, j]) - 1) < 1e-8


def test_direct_path_gives_the_modes_of_petscs_cholmod(ring_operators):
    """The default on one rank (CHOLMOD called directly, METIS order handed in, block Lanczos)
    against PETSc's CHOLMOD interface (chosen by name: K, M permuted, MatMatSolve): the same modes."""
    ops = ring_operators(kn=0, clamped=("inner",))
    direct = solve_real_modes(ops.K, ops.M, 12, 0.0, prefix="d_")
    petsc = solve_real_modes(ops.K, ops.M, 12, 0.0, prefix="p_",
                             options={"p_st_pc_factor_mat_solver_type": "cholmod"})
    assert direct.solver == petsc.solver == "cholmod"
    assert direct.method == petsc.method == "block Lanczos, 8 columns"
    assert np.all(direct.residuals < 1e-8)
    _same_modes(direct, petsc, ops.M)


def test_shifted_factor_and_the_krylov_schur_fallback(monkeypatch, ring_operators):
    """σ > 0 below the lowest mode (K − σM factorised directly), and a block Lanczos that cannot
    run (no vector budget: Krylov–Schur on PETSc's factorisation takes over): the modes of the
    unshifted default."""
    ops = ring_operators(kn=0, clamped=("inner",))
    ref = solve_real_modes(ops.K, ops.M, 12, 0.0, prefix="r_")
    shifted = solve_real_modes(ops.K, ops.M, 12, 0.5 * ref.freqs_hz[0], prefix="s_")
    assert shifted.solver == "cholmod" and shifted.method.startswith("block Lanczos")
    _same_modes(shifted, ref, ops.M)
    monkeypatch.setattr(eigen.block_krylov, "BLOCK_MEMORY", 0.0)     # where block Lanczos reads it
    fallback = solve_real_modes(ops.K, ops.M, 12, 0.0, prefix="f_")
    assert fallback.solver == "cholmod" and fallback.method == "Krylov-Schur"
    _same_modes(fallback, ref, ops.M)


def test_csr_view_is_petscs_csr_without_a_copy():
    """csr_view lends PETSc's own arrays (read-only, no copy) equal to getValuesCSR's copies; the
    matrix is intact afterwards (restored: MatMult still works and gives the same product)."""
    from petsc4py import PETSc

    from fem_squeal.fe.csr import csr_view

    A = _laplacian(6)
    P = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                            A.data))
    want = P.getValuesCSR()
    with csr_view(P) as got:
        for g, w in zip(got, want):
            assert np.array_equal(g, w) and not g.flags.writeable and not g.flags.owndata
    x = P.createVecRight()
    x.array[:] = np.arange(A.shape[0], dtype=float)
    y = P.createVecLeft()
    P.mult(x, y)
    assert np.allclose(y.array_r, A @ x.array_r, rtol=1e-15, atol=0)


@pytest.mark.parametrize("k", [8, 3, 13, 16, 29])
@pytest.mark.parametrize("blocks", [False, True])
def test_block_product_equals_scipys(k, blocks):
    """The compiled CSR × column-major block product against SciPy's: up to 8 columns in place
    (a tail of k mod 8), more in row-major panels of 16 (a tail of k mod 16), with the three rows
    of a node that share a pattern taken together (``blocks``: a 3 × 3-block matrix, one row of
    which gets an extra entry, so that its node falls back to single rows).  Each entry is the same
    sum in the same order, contracted into FMAs or not: they agree to round-off of the sum (1e-15
    of the largest |y|: at most 28 terms of O(1) per row).  Also a rectangular matrix."""
    from fem_squeal.fe.csr import block_product

    A = _laplacian(9)
    if blocks:
        A = sp.kron(A, np.ones((3, 3))).tocsr()
        A = (A + sp.csr_matrix(([1.0], ([7], [40])), shape=A.shape)).tocsr()   # node (6, 7, 8): not uniform
    A.data += np.random.default_rng(6).random(A.nnz)         # unsymmetric values, the same pattern
    for R in (A, A[: A.shape[0] // 2 + 1]):                   # square, and fewer rows than columns
        csr = (R.indptr.astype(np.int32), R.indices.astype(np.int32), R.data)
        product = block_product(csr, R.shape[1])
        if product is None:
            pytest.skip("no compiled kernel here (needs a C compiler)")
        X = np.asfortranarray(np.random.default_rng(7).standard_normal((R.shape[1], k)))
        Y = product(X)
        assert Y.flags.f_contiguous and Y.shape == (R.shape[0], k)
        assert np.max(np.abs(Y - R @ X)) <= 1e-15 * np.max(np.abs(Y))
        assert np.allclose(product(X[:, 0]), R @ X[:, 0], rtol=0, atol=1e-15 * np.max(np.abs(Y)))
        with pytest.raises(ValueError, match="rows"):
            product(X[1:])


def test_sum_norms_inf_equal_petscs_norms_of_the_sums():
    """‖Σ_i c_iq A_i‖∞ merged row by row without forming the sums against PETSc's MatNorm of each
    formed sum: terms of different patterns, a negative coefficient, a zero one, and two terms that
    cancel on one row (its absolute sum must use the summed entries, not the terms'); the three
    coefficient sets in one pass and each alone.  The same additions in another order: equal to
    1e-15 relative."""
    from petsc4py import PETSc

    from fem_squeal.fe.assembly import combination
    from fem_squeal.fe.csr import sum_norms_inf

    A = _laplacian(7)
    B = sp.random(A.shape[0], A.shape[1], density=0.05, random_state=3, format="csr") + sp.eye(A.shape[0])
    C = A.copy()
    C.data[:] = 0.0
    C = (C + sp.csr_matrix(([5.0], ([3], [3])), shape=A.shape)).tocsr()

    def petsc(S):
        S = S.tocsr()
        return PETSc.Mat().createAIJ(S.shape, csr=(S.indptr.astype(PETSc.IntType), S.indices.astype(PETSc.IntType),
                                                   S.data), comm=PETSc.COMM_SELF)
    mats = [petsc(A), petsc(B), petsc(C), petsc(A)]
    coefs = np.array([[1.0, -0.3, 2.0, 0.0], [1.0, 0.0, 0.0, -1.0], [2.5, 1.0, -0.2, 0.7]]).T
    together = sum_norms_inf(mats, coefs)
    for q in range(coefs.shape[1]):
        S = combination(list(zip(mats, coefs[:, q])))
        want = S.norm(PETSc.NormType.INFINITY)
        S.destroy()
        assert abs(together[q] - want) <= 1e-15 * max(want, 1.0)
        assert abs(sum_norms_inf(mats, coefs[:, q:q + 1])[0] - want) <= 1e-15 * max(want, 1.0)
    assert sum_norms_inf([mats[0], mats[3]], np.array([[1.0], [-1.0]]))[0] == 0.0  # A − A: every row cancels
