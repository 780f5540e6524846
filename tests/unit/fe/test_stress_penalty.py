"""Stress test of the contact penalty (short version of benchmarks/stress_penalty.py).

Ring (seed 003), P2 at 0.003 m (13k DOFs), k_n = 1e10 (the scene), 1e14 and 1e16 N/m³: penalty
ratios r = k_n h / C₁₁ of about 6e-3, 61 and 6e3 (fem_squeal.fe.penalty)."""
from __future__ import annotations

import sys
import warnings

import numpy as np
import pytest
from support.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))


@pytest.fixture(scope="module")
def rows():
    import stress_penalty

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {kn: stress_penalty.run_case(kn, 0.003) for kn in (1e10, 1e14, 1e16)}


def test_warning_only_above_the_ratio(rows):
    from fem_squeal.fe.penalty import WARN_RATIO

    for kn, r in rows.items():
        assert r["warned"] == (r["ratio"] > WARN_RATIO), (kn, r["ratio"])
    assert rows[1e16]["warned"] and not rows[1e14]["warned"]


def test_residuals_stay_small(rows):
    # the CEA's own acceptance bound (max_residual 1e-8): a stiff penalty must not degrade it here
    for kn, r in rows.items():
        assert r["max_residual"] < 1e-8, (kn, r["max_residual"])


def test_eigenvalues_saturate_while_conditioning_grows(rows):
    """Past r ≫ 1 the interface is rigid: the flutter eigenvalues change by O(1/r) from 1e14 to
    1e16 (bound 1/r(1e14) ≈ 1.6e-2), while κ₁(K − σM) grows ∝ k_n (bound: 10× for 100× k_n,
    allowing the estimator's factor-3 slack on each side)."""
    a, b = rows[1e14], rows[1e16]
    pa = {k: complex(*v) for k, v in a["unstable_pairs"].items()}
    pb = {k: complex(*v) for k, v in b["unstable_pairs"].items()}
    assert set(pa) == set(pb) == {2, 3, 4, 5, 6}
    change = max(abs(pb[k] - pa[k]) / abs(pa[k]) for k in pa)
    assert change < 1.0 / a["ratio"], change
    assert b["cond"] > 10 * a["cond"], (a["cond"], b["cond"])
    assert np.isfinite(b["cond"])


def test_condition_estimate_against_dense():
    """Hager's estimate is a lower bound of κ₁ within a factor 3 (checked against numpy on a small
    non-symmetric matrix with a known, large condition number)."""
    from petsc4py import PETSc

    from fem_squeal.fe.penalty import condition_number_1

    rng = np.random.default_rng(0)
    n = 60
    U, _ = np.linalg.qr(rng.standard_normal((n, n)))
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    A = U @ np.diag(np.logspace(0, 8, n)) @ V.T
    M = PETSc.Mat().createDense((n, n), array=A.copy(), comm=PETSc.COMM_SELF)
    M.assemble()
    M = M.convert("aij")
    est = condition_number_1(M, solver="petsc")
    exact = np.linalg.cond(A, 1)
    assert exact / 3 <= est <= exact * (1 + 1e-8), (est, exact)
