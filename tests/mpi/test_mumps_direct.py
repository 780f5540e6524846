"""MUMPS called directly (fem_squeal.fe.mumps): LDLᵀ with and without pivoting and block solves on each
rank's rows, on 1 rank and 2, and the real modes on 2 ranks through it against 1 rank's (CHOLMOD)."""
from __future__ import annotations

import numpy as np
import pytest
from support.ranks import two_rank_signature

pytest.importorskip("petsc4py")


def signature() -> dict:
    """On the ring clamped at its inner face (K positive definite): the relative residuals of block solves with
    K (SYM = 1) and with the indefinite K − σM (σ = 1.5 λ₁: SYM = 1 refuses it, SYM = 2 solves it),
    Bᵀ K⁻¹ B for the block B of the rigid translations' masses, and the real
    modes with the path that ran."""
    from mpi4py import MPI
    from support.ring import ring_operators

    from fem_squeal.fe import kernels, mumps
    from fem_squeal.fe.dense import apply
    from fem_squeal.fe.eigen import solve_real_modes
    from fem_squeal.fe.eigen.real_modes import _owned_rows

    comm = MPI.COMM_WORLD
    kernels.tally(reset=True)
    ops = ring_operators(kn=0, clamped=("inner",))
    rm = solve_real_modes(ops.K, ops.M, 6, 0.0)
    out = {"freqs": rm.freqs_hz.tolist(), "solver": rm.solver, "paths": kernels.tally()}
    if not mumps.available():
        return out
    n, rows = ops.K.getSize()[0], ops.K.getOwnershipRange()
    # B = M [e_x e_y e_z] (the rigid translations: independent of the rows' numbering, which differs
    # between 1 and 2 ranks), and Bᵀ K⁻¹ B, the same on any rank count
    X0 = apply(ops.M, np.asfortranarray(np.kron(np.ones(((rows[1] - rows[0]) // 3, 1)), np.eye(3))))
    sigma = 1.5 * (2 * np.pi * rm.freqs_hz[0]) ** 2

    def residual(A, triplets, definite):
        with mumps.LDLT(comm, n, rows, triplets, definite) as F:
            X = F.solve(X0)
        R = apply(A, X) - X0
        return np.sqrt(comm.allreduce(float(np.sum(R ** 2))) / comm.allreduce(float(np.sum(X0 ** 2)))), X

    K = _owned_rows(ops.K, n)
    out["spd_residual"], X = residual(ops.K, mumps.lower_triplets(rows, (K.indptr, K.indices, K.data)), True)
    out["compliance"] = comm.allreduce(X0.T @ X).tolist()
    A = (K - sigma * _owned_rows(ops.M, n)).tocsr()
    shifted = mumps.lower_triplets(rows, (A.indptr, A.indices, A.data))
    try:
        mumps.LDLT(comm, n, rows, shifted, True).close()
        out["refused"] = False
    except mumps.NotPositiveDefinite:
        out["refused"] = True
    Ap = ops.K.copy()
    Ap.axpy(-sigma, ops.M, structure=Ap.Structure.DIFFERENT_NONZERO_PATTERN)
    out["indefinite_residual"] = residual(Ap, shifted, False)[0]
    return out


@pytest.fixture(scope="module")
def signatures(mpirun, tmp_path_factory):
    from test_mumps_direct import signature as one_rank
    out = tmp_path_factory.mktemp("mumps") / "sig.json"
    return one_rank(), two_rank_signature(mpirun, "test_mumps_direct", out)


@pytest.mark.mpi
def test_direct_mumps_solves_on_one_and_two_ranks(signatures):
    """K X = B to round-off with SYM = 1 on 1 and 2 ranks (the same Bᵀ K⁻¹ B on both), K − σM (σ above
    the lowest mode) refused by SYM = 1 (a negative pivot) and solved by SYM = 2."""
    from fem_squeal.fe import mumps
    if not mumps.available():
        pytest.skip("the mumps_shim kernel is not built")
    for sig in signatures:
        assert sig["spd_residual"] < 1e-12 and sig["indefinite_residual"] < 1e-10
        assert sig["refused"]
    one, two = (np.array(s["compliance"]) for s in signatures)
    assert np.max(np.abs(one - two)) <= 1e-10 * np.max(np.abs(one))


@pytest.mark.mpi
def test_real_modes_on_two_ranks_through_direct_mumps(signatures):
    """The real modes on 2 ranks come from the direct MUMPS path (its block solves on each rank's
    rows) and agree with 1 rank's (CHOLMOD) to 1e-9."""
    from fem_squeal.fe import mumps
    if not mumps.available():
        pytest.skip("the mumps_shim kernel is not built")
    one, two = signatures
    assert two["solver"] == "mumps"
    assert "mumps, distributed right-hand sides" in two["paths"]["block_solve"]
    assert any(p.startswith("mumps-direct, SYM=1") for p in two["paths"]["factorisation"])
    assert np.max(np.abs(np.array(two["freqs"]) / np.array(one["freqs"]) - 1)) <= 1e-9
