"""The instabilities of a stability map (fem_squeal.reduced.stability_map.instabilities): two friction
flutter pairs of a four-mode model over (E, sign(v)μ), where each pair flutters for |μ| above a threshold
that moves with E.  Each (pair, sign of μ) is one instability whose points are exactly those of the
closed form, whose fastest growth is the closed form's, and whose coupling is its two real modes at
50 % each (above flutter |y₁| = |y₂|: tests/unit/reduced/test_operating_matrix.py)."""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.reduced.eigensolve import unstable
from fem_squeal.reduced.model import MU, ReducedModel, e_param
from fem_squeal.reduced.stability_map import instabilities, instability_couplings
from fem_squeal.reduced.sweep import Grid, evaluate

W = 2 * np.pi * np.array([1000.0, 1100.0, 3000.0, 3200.0])   # rad/s: pairs (0, 1) and (2, 3)
MU_C = (0.5, 0.7)                                             # flutter thresholds at E = E0


def _model() -> ReducedModel:
    """K(E, μ) = diag(ω₁², s ω₂², ω₃², s ω₄²) + μ [[0, a], [−a, 0]] per pair, s = E/E0 (the 'disc' part
    holds the second mode of each pair), a = (ω₂² − ω₁²)/(2 μ_c)."""
    w2 = W ** 2
    a = [(w2[1] - w2[0]) / (2 * MU_C[0]), (w2[3] - w2[2]) / (2 * MU_C[1])]
    Kf = np.zeros((4, 4))
    Kf[0, 1], Kf[1, 0], Kf[2, 3], Kf[3, 2] = a[0], -a[0], a[1], -a[1]
    return ReducedModel(K0=np.diag(w2), Kf1=Kf, K_parts={"disc": np.diag([0.0, w2[1], 0.0, w2[3]])},
                        E0={"disc": 1.0}, mu0=0.3, info={"modes": 4})


def _closed_form(s: np.ndarray, mu: np.ndarray, pair: int) -> np.ndarray:
    """The growing eigenvalue λ (Re λ ≥ 0, Im λ > 0) of the pair: K y = κ y, λ² = −κ, the four λ are
    ±√−κ and their conjugates, κ = (ω₁² + s ω₂²)/2 ± i√(μ²a² − d²), d = (s ω₂² − ω₁²)/2."""
    w2 = W[2 * pair:2 * pair + 2] ** 2
    a = (w2[1] - w2[0]) / (2 * MU_C[pair])
    d = (s * w2[1] - w2[0]) / 2
    kappa = (w2[0] + s * w2[1]) / 2 + 1j * np.sqrt((mu * a) ** 2 - d ** 2 + 0j)
    lam = np.sqrt(-kappa)
    return np.abs(lam.real) + 1j * np.abs(lam.imag)


@pytest.fixture(scope="module")
def found():
    model = _model()
    s, mu = np.linspace(0.96, 1.04, 9), np.linspace(-1.0, 1.0, 41)
    grid = Grid({e_param("disc"): s, MU: mu})
    res = evaluate(model, grid)
    out = instabilities(res, (0.0, 5000.0))
    instability_couplings(model, out)
    return s, mu, out


def test_each_pair_and_sign_of_mu_is_one_instability_with_the_closed_form_points(found):
    s, mu, out = found
    S, MUg = np.meshgrid(s, mu, indexing="ij")
    assert len(out) == 4
    for pair, f_lo, f_hi in ((0, 1000.0, 1100.0), (1, 3000.0, 3200.0)):
        lam = _closed_form(S, MUg, pair)
        mine = [x for x in out if f_lo < x.freq_hz[0] and x.freq_hz[1] < f_hi]
        assert len(mine) == 2
        for x in mine:
            side = MUg > 0 if x.at[MU] > 0 else MUg < 0
            expected = unstable(lam, 1e-6) & side
            np.testing.assert_array_equal(x.mask, expected)
            np.testing.assert_allclose(x.growth[expected], lam[expected].real, rtol=1e-9)
            # the fastest growth: at |μ| = 1 and the smallest E (the pair's frequencies closest)
            assert x.max_growth_rate == pytest.approx(lam[expected].real.max(), rel=1e-9)
            assert abs(x.at[MU]) == 1.0 and x.at[e_param("disc")] == pytest.approx(0.96)
            assert x.ranges[MU][0 if x.at[MU] > 0 else 1] == pytest.approx(
                (1 if x.at[MU] > 0 else -1) * np.abs(MUg[expected]).min())
    # fastest first: the upper pair's growth rate is the larger at |μ| = 1
    assert out[0].freq_hz[0] > 3000.0 and out[0].max_growth_rate >= out[1].max_growth_rate


def test_coupling_of_each_instability_is_its_two_real_modes_at_50_percent(found):
    _, _, out = found
    for x in out:
        pair = [0, 1] if x.freq_hz[0] < 2000.0 else [2, 3]
        c = x.coupling
        assert sorted(c["pair"]) == pair and c["percent"][:2] == pytest.approx([50.0, 50.0], abs=1e-6)
        assert abs(c["outside"]) < 1e-12
        d = x.as_dict()
        assert d["points"] == x.mask.sum() and d["coupling"] is c and 0 < d["share"] < 0.5


def test_nothing_unstable_gives_no_instability():
    model = _model()
    res = evaluate(model, Grid({e_param("disc"): [1.0], MU: np.linspace(-0.3, 0.3, 5)}))
    assert instabilities(res, (0.0, 5000.0)) == []
