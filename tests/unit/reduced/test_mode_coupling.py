"""Mode coupling on a reduced basis and the squeal index (plain NumPy: fem_squeal.reduced.mode_coupling,
fem_squeal.reduced.squeal_index)."""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.reduced import mode_coupling, squeal_index
from fem_squeal.reduced.eigensolve import quadratic_eigs


def _rotated_model(mu: float):
    """Four real modes (100, 200, 210, 400 Hz) in a basis rotated among themselves (as the basis'
    orthonormalisation leaves them) plus a fifth, static column; friction couples modes 1 and 2."""
    w = 2 * np.pi * np.array([100.0, 200.0, 210.0, 400.0])
    Q = np.linalg.qr(np.random.default_rng(3).standard_normal((4, 4)))[0]
    K = np.zeros((5, 5))
    K[:4, :4] = Q @ np.diag(w ** 2) @ Q.T
    K[4, 4] = (2 * np.pi * 5000.0) ** 2
    F = np.zeros((5, 5))
    F[1, 2], F[2, 1] = w[1] * w[2], -w[1] * w[2]
    T = np.eye(5)
    T[:4, :4] = Q
    return K, T @ F @ T.T, lambda m: quadratic_eigs(K + m * T @ F @ T.T, None, vectors=True)


def test_the_merged_pair_is_found_through_the_basis_rotation():
    """Past the coalescence of modes 1 and 2 the unstable eigenvector is half on each of them, nothing
    on the others and nothing outside the modal columns; the basis modes' frequencies are recovered."""
    K, _, solve = _rotated_model(0.2)
    modes = mode_coupling.basis_modes(K, 4)
    assert np.allclose(modes[0], [100.0, 200.0, 210.0, 400.0], rtol=1e-12)
    lam = solve(0.2)[0]
    c = mode_coupling.coupling_at(solve, 0.2, lam[np.argmax(lam.real)], modes)
    assert sorted(c["pair"]) == [1, 2] and len(c["real_modes"]) == 2
    assert c["percent"] == pytest.approx([50.0, 50.0], abs=1e-8)
    assert abs(c["outside"]) < 1e-12
    assert c["label"].startswith("real modes ") and "(50 %)" in c["label"]


def test_participation_and_outside_share():
    C = np.array([[0.6, 0.0], [0.0, 1.0], [0.8j, 0.0]])
    p, r = mode_coupling.participation(C, np.array([1.25, 1.0]))
    assert p[:, 0] == pytest.approx([36.0, 0.0, 64.0]) and p[:, 1] == pytest.approx([0.0, 100.0, 0.0])
    assert r == pytest.approx([0.2, 0.0])
    s = mode_coupling.summary(p[:, 1], r[1], np.array([1.0, 2.0, 3.0]))
    assert s["real_modes"] == [1] and s["label"] == "real mode 1 (100 %)"
    g = mode_coupling.degenerate_groups(np.array([10.0, 100.0, 100.001, 300.0]))
    assert g == [[0], [1, 2], [3]]
    # rigid-body modes: round-off frequencies around 0 (−2e-3, 1.4e-3, 1.8e-3 Hz on the free ring) are one group
    g = mode_coupling.degenerate_groups(np.array([-2.06e-3, 1.42e-3, 1.85e-3, 359.4396, 359.4396, 1008.5]))
    assert g == [[0, 1, 2], [3, 4], [5]]


def test_levels_squeal_index_and_bands():
    """L_W = 10 log10(P/1 pW); SI = L_W + 10 log10(Re λ) for unstable modes only, ranked; the 13 bands
    1-16 kHz touch each other and hold each mode once."""
    assert squeal_index.level_db([1e-12, 1e-2])[1] == pytest.approx(100.0)
    L = np.array([100.0, 90.0, 120.0])
    si = squeal_index.squeal_index([10.0, 100.0, -5.0], L)
    assert si[:2] == pytest.approx([110.0, 110.0 + 0.0]) and np.isnan(si[2])
    assert squeal_index.ranking(np.array([110.0, 111.0, np.nan]), [True, True, False]) == [1, 0]
    bands = squeal_index.third_octave_bands()
    assert len(bands) == 13 and bands[0][0] == 1000 and bands[-1][0] == 16000
    assert all(a[2] == pytest.approx(b[1]) for a, b in zip(bands, bands[1:]))
    rows = squeal_index.band_summary([1000.0, 1010.0, 5000.0, 20000.0], [1.0, 2.0, 3.0, 4.0],
                                     [False, True, False, True], [np.nan, 7.0, np.nan, 9.0])
    assert sum(b["n_modes"] for b in rows) == 3
    b1 = next(b for b in rows if b["band_hz"] == 1000)
    assert (b1["n_modes"], b1["n_unstable"], b1["max_level_db"], b1["max_squeal_index_db"]) == (2, 1, 2.0, 7.0)
