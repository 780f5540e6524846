"""The contact state at each brake pressure in the reduced model (issue 39): a pressure whose preload opens
or closes contact points evaluates the model with that pressure's closed rows.

Checked against a second model built directly at the other contact state (its K₀, K_f¹ formed from the
rows with that state's closed points): K(p), C(p) and ∂K/∂p at every parameter must agree to round-off
(1e-12 relative: the same sums in another order)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fem_squeal.reduced.contact_rows import ContactRows
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.util.errors import ModelError

M, N, MU0, KN, KT = 6, 9, 0.4, 5e3, 7e2


def _rows(active: np.ndarray) -> ContactRows:
    rng = np.random.default_rng(7)
    return ContactRows(D=rng.normal(size=(N, M)), T=rng.normal(size=(2, N, M)), weight=rng.uniform(0.5, 1.5, N),
                       kn=KN, kt=KT, mu=MU0, sliding=1.0, active=active, name="pad")


def _model(active: np.ndarray, states: dict | None = None) -> ReducedModel:
    """The model with the preload's closed rows ``active``: K₀ = K_el + K_c + k_t K_t¹, K_f¹ of those rows."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(M, M))
    rows = _rows(active)
    K0 = A @ A.T + M * np.eye(M) + rows.normal_stiffness() + KT * rows.tangential_stiffness()
    return ReducedModel(K0=K0, Kf1=rows.friction_stiffness(), C0=0.01 * np.eye(M), mu0=MU0,
                        contacts={"pad": rows}, contact_states=states or {})


A1 = np.array([1, 1, 1, 0, 1, 0, 1, 1, 0], bool)     # closed at the scene's pressure
A2 = np.array([1, 1, 1, 1, 1, 1, 1, 1, 0], bool)     # two more closed at twice the pressure
A05 = np.array([1, 0, 1, 0, 1, 0, 0, 1, 0], bool)    # two opened at half


@pytest.fixture
def model():
    return _model(A1, {2.0: {"pad": A2}, 0.5: {"pad": A05}})


@pytest.mark.parametrize("scale,active", [(2.0, A2), (0.5, A05)])
@pytest.mark.parametrize("point", [{"mu": 0.3}, {"mu": -0.5, "kn.pad": 2 * KN},
                                   {"mu": 0.4, "mu.pad": 0.25, "kt.pad": 0.0}])
def test_pressure_gives_the_model_of_its_contact_state(model, scale, active, point):
    direct = _model(active)
    K, C = model.matrices({**{k: np.array([v]) for k, v in point.items()}, "pressure": np.array([scale])})
    Kd, Cd = direct.matrices({k: np.array([v]) for k, v in point.items()})
    assert np.abs(K - Kd).max() <= 1e-12 * np.abs(Kd).max()
    assert np.array_equal(C, Cd)
    for name in point:
        dK, _ = model.derivative(name, {**point, "pressure": scale})
        dKd, _ = direct.derivative(name, point)
        assert np.abs(dK - dKd).max() <= 1e-12 * max(np.abs(dKd).max(), 1.0), name


def test_points_at_several_pressures_at_once(model):
    ps = np.array([0.5, 1.0, 2.0, 1.0])
    K, _ = model.matrices({"mu": np.full(4, 0.3), "pressure": ps}, 4)
    # a batch and a single point are the same sums, but BLAS may take them in another order (a batched
    # matmul blocks differently): agreement to round-off, 1e-13 of the largest entry (eps times ~N terms)
    tol = 1e-13 * np.abs(K).max()
    for k, p in enumerate(ps):
        one = model.matrices({"mu": np.array([0.3]), "pressure": np.array([p])})[0][0]
        assert np.abs(K[k] - one).max() <= tol, p
    assert np.abs(K[1] - model.matrices({"mu": np.array([0.3])})[0][0]).max() <= tol   # s = 1: preload's state


def test_a_pressure_between_the_continued_ones_is_refused(model):
    assert "pressure" in model.parameters
    with pytest.raises(ModelError, match=r"pressure: .* at \[0.5, 1.0, 2.0\] .*got 1.5"):
        model.matrices({"pressure": np.array([1.5])})


def test_contact_states_are_saved(model, tmp_path):
    model.save(tmp_path / "m.npz")
    back = ReducedModel.load(tmp_path / "m.npz")
    assert sorted(back.contact_states) == [0.5, 2.0]
    assert np.array_equal(back.contact_states[2.0]["pad"], A2)
    pt = {"mu": np.array([0.3]), "pressure": np.array([2.0])}
    assert np.array_equal(back.matrices(pt)[0], model.matrices(pt)[0])


def test_bad_contact_states_are_named():
    with pytest.raises(ModelError, match=r"contact_states\[2\]\.pad: needs the closed flags of its 9 rows"):
        _model(A1, {2.0: {"pad": A2[:4]}})
    with pytest.raises(ModelError, match="contact_states: a pressure scale must be a number > 0"):
        _model(A1, {-1.0: {"pad": A2}})


def test_pressure_terms_at_a_changed_contact_state_are_the_pressures_own(tmp_path):
    """With a stress stiffening and a friction damping per pressure (pressure_tables: each state's own
    projections, the affine slopes not holding across contact sets), K(s) and C(s) are those of a model
    built at that state with its terms in K₀ and C_d (the friction damping still scaled by |μ|/|μ⁰|)."""
    rng = np.random.default_rng(11)
    sym = lambda: (lambda A: 1e-2 * (A + A.T))(rng.normal(size=(M, M)))   # noqa: E731
    Ks, Cd, dKs, dCd = sym(), sym(), sym(), sym()
    base = _model(A1, {2.0: {"pad": A2}, 0.5: {"pad": A05}})
    model = replace(base, Ksp=Ks, Cd0=Cd, Cdp=0.5 * Cd, speed0=10.0,
                    pressure_tables={2.0: {"Ks": dKs, "Cd": dCd}, 0.5: {"Ks": -dKs, "Cd": -dCd}})
    direct = _model(A2)
    direct = replace(direct, K0=direct.K0 + dKs, Cd0=Cd + dCd, speed0=10.0)
    K, C = model.matrices({"mu": np.array([0.2]), "pressure": np.array([2.0])})
    Kd, Cdd = direct.matrices({"mu": np.array([0.2])})
    assert np.abs(K - Kd).max() <= 1e-12 * np.abs(Kd).max() and np.abs(C - Cdd).max() <= 1e-12 * np.abs(Cdd).max()
    K1, C1 = model.matrices({"mu": np.array([0.2]), "pressure": np.array([1.0])})   # s = 1: the scene's
    assert np.array_equal(K1, model.matrices({"mu": np.array([0.2])})[0])
    assert np.array_equal(C1, model.matrices({"mu": np.array([0.2])})[1])
    model.save(tmp_path / "m.npz")
    back = ReducedModel.load(tmp_path / "m.npz")
    assert np.array_equal(back.pressure_tables[0.5]["Cd"], -dCd)
    at = {"pressure": np.array([0.5])}
    assert np.array_equal(back.matrices(at)[1], model.matrices(at)[1])
