"""Near an exceptional point (short version of benchmarks/stress_coalescence.py, m = 40)."""
from __future__ import annotations

import sys

import numpy as np
import pytest
from support.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
import stress_coalescence as sc  # noqa: E402

EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def rows():
    return sc.coalescence_table(40, list(range(1, 13)))


def test_condition_number_of_a_normal_problem():
    """Symmetric K, C = 0: x = y, so κ(λ) = (|λ|² + ‖K‖)/(2|λ|²) exactly."""
    from fem_squeal.reduced.eigensolve import condition_numbers

    rng = np.random.default_rng(0)
    B = rng.standard_normal((8, 8))
    K = B @ B.T + 8 * np.eye(8)
    lam, kap = condition_numbers(K)
    np.testing.assert_allclose(kap, (np.abs(lam) ** 2 + np.linalg.norm(K, 2)) / (2 * np.abs(lam) ** 2), rtol=1e-10)


def test_kappa_grows_as_inverse_square_root(rows):
    """A defective double eigenvalue: κ ∝ δ^(−1/2); fitted slope over δ = 1e-2 … 1e-7 within 0.05."""
    up = [r for r in rows if r["side"] > 0 and 1e-7 <= r["rel_delta"] <= 1e-2]
    slope = np.polyfit(np.log10([r["rel_delta"] for r in up]), np.log10([r["kappa"] for r in up]), 1)[0]
    assert abs(slope + 0.5) < 0.05, slope


def test_real_parts_within_the_backward_error_bound(rows):
    """|Re λ − Re λ_exact| ≤ 100 κ ε |λ| (a backward-stable solve gives ~κε|λ|; 100 covers the
    norm constants), and the stability flag is the one the exact eigenvalues get, on both sides."""
    for r in rows:
        assert r["abs_error"] <= 100 * r["kappa"] * EPS * r["abs_lambda"], r
        assert r["flag_right"], r
    # resolved well into the approach: 1e-5 relative at δ = 1e-6 μ_c
    r6 = next(r for r in rows if r["rel_delta"] == 1e-6)
    assert r6["rel_error"] < 1e-5


def test_tracker_finds_the_exceptional_point():
    t = sc.tracker_row(40, 7)
    assert t["events"] == 1 and t["coalescences"] == 1
    assert t["mu_c_error"] < 1e-8
