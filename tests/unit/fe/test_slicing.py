"""Spectrum slicing of the real modes to a cut (issue 36): every slice's count proved by the inertia of
its LDLᵀ factorisation, the modes those of a single-shift solve; the Krylov–Schur progress estimate."""
from __future__ import annotations

import io

import numpy as np
import pytest


@pytest.fixture(scope="module")
def ring(ring_operators):
    """The ring between two spring plates (the session's operators: three rigid-body modes at λ ≈ 0)
    and its 24 lowest modes by one shift-invert solve."""
    from fem_squeal.fe.eigen import solve_real_modes

    ops = ring_operators()
    ref = solve_real_modes(ops.K, ops.M, 24, 1.0)
    lam = ref.omega2.copy()
    for v in ref.vectors:
        v.destroy()
    return ops, lam


def test_slices_prove_their_counts_and_match_one_shift(ring):
    """Three slices to a cut between the 20th and 21st modes: exactly the 20 modes below it (the
    rigid-body ones included), each slice's inertia equal to the modes kept below its shift, the
    eigenvalues those of one shift-invert solve (within 1e-7 λ_cut, as test_modes_to_a_cut_without_a_count)."""
    from fem_squeal.fe.eigen import TWO_PI
    from fem_squeal.fe.eigen.slicing import sliced_modes
    from fem_squeal.fe.projection import modes_below

    ops, lam = ring
    f = np.sqrt(np.abs(lam)) / TWO_PI
    cut = 0.5 * (f[19] + f[20])
    lam_cut = (TWO_PI * cut) ** 2
    rm, slices = sliced_modes(ops.K, ops.M, cut, 3, tol=1e-7, max_residual=1e-8)
    assert rm is not None and len(rm.vectors) == 20 and len(slices) == 3
    assert np.max(np.abs(rm.omega2 - lam[:20])) < 1e-7 * lam_cut
    assert np.all(rm.residuals <= 1e-8) and "slicing" in rm.method
    kept = np.cumsum([s.modes for s in slices])
    assert kept[-1] == 20 and slices[-1].inertia == 20 and slices[-1].shift_hz == pytest.approx(cut)
    for s in slices:      # ν(c) = the modes below the shift, counted over all slices
        assert s.inertia == int(np.sum(rm.freqs_hz < s.shift_hz))
        assert s.lo_hz < s.hi_hz
    for v in rm.vectors:
        v.destroy()
    # modes_below selects it by its option (<prefix>slices)
    w2, Phi = modes_below(ops.K, ops.M, cut, options={"basis_slices": 2})
    assert Phi.shape[1] == 20 and np.max(np.abs(w2 - lam[:20])) < 1e-7 * lam_cut


def test_slices_refused_option():
    from fem_squeal.fe.projection.shifted import _slices
    from fem_squeal.util.errors import ModelError

    assert _slices("basis_", {"basis_slices": 3}) == 3
    with pytest.raises(ModelError, match="basis_slices: must be an integer"):
        _slices("basis_", {"basis_slices": "many"})


def test_restarts_left_follows_the_convergence_rate():
    """Error estimates falling ×10 per restart, at 1e-3 and 1e-2, tol 1e-7: five restarts left; none known
    before a rate is seen or while nothing falls; 0 once every estimate is below tol."""
    from fem_squeal.fe.eigen.options import restarts_left

    assert restarts_left(np.array([1e-2, 1e-1]), np.array([1e-3, 1e-2]), 1e-7) == pytest.approx(5.0)
    assert np.isnan(restarts_left(None, np.array([1e-3]), 1e-7))
    assert np.isnan(restarts_left(np.array([1e-3]), np.array([2e-3]), 1e-7))
    assert restarts_left(np.array([1e-3]), np.array([1e-8]), 1e-7) == 0.0


def test_progress_heartbeat_and_caller_eta():
    """In a log: a line per decile, and one more whenever ``heartbeat`` seconds passed; the caller's ETA shown."""
    from fem_squeal.util.progress import ProgressBar

    out = io.StringIO()
    bar = ProgressBar(100, "x", stream=out, heartbeat=0.0)
    bar.update(1, eta=12.0)
    bar.update(2, eta=float("nan"))
    bar.abandon()
    lines = out.getvalue().splitlines()
    assert len(lines) == 2 and "eta 12.0 s" in lines[0] and "eta ?" in lines[1]
    quiet = io.StringIO()
    bar = ProgressBar(100, "x", stream=quiet)
    bar.update(1)
    bar.update(2)
    assert len(quiet.getvalue().splitlines()) == 1
