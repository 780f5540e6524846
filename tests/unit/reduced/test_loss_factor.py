"""Loss factors as tables η(f, T) (issue 39, shims and insulators): the table and its named errors, a
constant table reproducing the constant η exactly, and the fixed point in frequency per mode on the
reduced model (in the operating matrix's conditions too)."""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.fe.model import Material
from fem_squeal.reduced.eigensolve import TWO_PI, quadratic_eigs
from fem_squeal.reduced.laws.loss_factor import LossTable, loss_table
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.operating_matrix import (
    LossFactors,
    condition_fixed_point,
    evaluate,
    factorial,
    matrices_at,
)
from fem_squeal.util.errors import ModelError

BAND = (200.0, 1200.0)


def shim_model(m: int = 6, seed: int = 3) -> ReducedModel:
    """Modes 300..1500 Hz coupled by friction, a 'shim' part carrying part of the stiffness."""
    rng = np.random.default_rng(seed)
    w2 = (TWO_PI * np.array([300.0, 500.0, 520.0, 800.0, 1000.0, 1500.0][:m])) ** 2
    B = rng.normal(size=(m, m))
    Kp = 0.3 * np.diag(np.sqrt(w2)) @ (B @ B.T / m) @ np.diag(np.sqrt(w2))
    return ReducedModel(K0=np.diag(w2), Kf1=rng.normal(size=(m, m)) * 1e6, mu0=0.3, C0=np.eye(m) * 5.0,
                        K_parts={"shim": Kp}, E0={"shim": 1e9}, eta0={"shim": 0.0})


RISING = LossTable([100.0, 2000.0], [0.0, 100.0], [[0.02, 0.4], [0.01, 0.1]], reference_frequency=500.0,
                   reference_temperature=20.0, name="materials.shim.eta_table")


def test_table_interpolates_and_names_bad_input():
    assert RISING.value(100.0, 0.0) == 0.02 and RISING.value(2000.0, 100.0) == pytest.approx(0.1)
    assert RISING.value(1050.0, 50.0) == pytest.approx(0.25 * (0.02 + 0.4 + 0.01 + 0.1))
    assert RISING.nominal == pytest.approx(RISING.value(500.0, 20.0)) and RISING.constant is None
    flat = LossTable([100.0, 2000.0], [0.0, 50.0], [[0.07, 0.07], [0.07, 0.07]])
    assert flat.constant == 0.07 and flat.nominal == 0.07 and flat.value(1234.5, 33.0) == 0.07    # bit for bit
    assert not flat.varies_with_frequency and RISING.varies_with_frequency
    with pytest.raises(ModelError, match=r"^x\.frequency: must be strictly increasing \(got \[100\.0, 50\.0\]\)"):
        LossTable([100.0, 50.0], [20.0], [[0.1, 0.1]], name="x")
    with pytest.raises(ModelError, match=r"^x\.temperature: must be strictly increasing"):
        LossTable([100.0], [20.0, 20.0], [[0.1], [0.1]], name="x")
    with pytest.raises(ModelError, match=r"^x\.eta: must be finite and >= 0 \(got -0\.1\)"):
        LossTable([100.0, 200.0], [20.0], [[0.1, -0.1]], reference_frequency=150.0, name="x")
    with pytest.raises(ModelError, match=r"^x\.eta: must have one row per temperature .* shape \(2, 1\)"):
        LossTable([100.0], [0.0, 1.0], [[0.1, 0.1]], name="x")
    with pytest.raises(ModelError, match=r"^x\.reference_frequency: required, the table varies with the freq"):
        LossTable([100.0, 200.0], [20.0], [[0.1, 0.2]], name="x")
    with pytest.raises(ModelError, match=r"^x: reference_temperature 200 is outside the table's range \[0, 100\]"):
        LossTable([100.0], [0.0, 100.0], [[0.1], [0.2]], reference_temperature=200.0, name="x")
    with pytest.raises(ModelError, match=r"^materials\.shim\.eta_table: temperature 120 is outside the table's "
                                         r"range \[0, 100\]"):
        RISING.value(500.0, 120.0)
    with pytest.raises(ModelError, match=r"^materials\.shim\.eta_table: frequency 2500 is outside"):
        RISING.value(2500.0, 20.0)
    with pytest.raises(ModelError, match=r"^t\.speed: unknown key; allowed"):
        loss_table({"eta": [0.1], "speed": [1.0]}, "t")


def test_material_with_a_constant_table_is_the_constant_eta():
    a = Material(2e10, 0.3, 7000.0, eta=0.05)
    b = Material(2e10, 0.3, 7000.0, eta_table={"frequency": [10.0, 5000.0], "eta": [0.05, 0.05]})
    assert b.eta == a.eta and isinstance(b.eta_table, LossTable)
    assert Material(2e10, 0.3, 7000.0, eta_table={"frequency": [10.0, 5000.0], "eta": [0.05, 0.05]}) == b
    c = Material(2e10, 0.3, 7000.0, eta_table={"frequency": [10.0, 5000.0], "eta": [0.0, 0.5],
                                               "reference_frequency": 2505.0})
    assert c.eta == pytest.approx(0.25)
    with pytest.raises(ModelError, match=r"^eta_table: give eta or eta_table, not both"):
        Material(2e10, 0.3, 7000.0, eta=0.1, eta_table={"eta": [0.1]})
    with pytest.raises(ModelError, match=r"^eta_table\.eta: must be finite and >= 0"):
        Material(2e10, 0.3, 7000.0, eta_table={"eta": [-0.1]})


def test_fixed_point_with_a_frequency_independent_table_is_the_constant_eta_solve():
    """η independent of f: one QEP for every mode, converged at the first iteration, the eigenvalues of
    the constant-η model to round-off (eig with vectors against eigvals); in the operating matrix such a
    table is a plain parameter: bit-identical to giving eta.<part> by hand."""
    model = shim_model()
    flat = LossTable([100.0, 2000.0], [0.0, 100.0], [[0.08, 0.08], [0.08, 0.08]])
    lam, res = condition_fixed_point(model, {}, 1.0, LossFactors({"shim": flat}, BAND), 20.0)
    K, C = matrices_at(model, {"eta.shim": 0.08}, 1.0)
    ref = quadratic_eigs(K[None], C[None])[0]
    assert res.solves == 1 and res.converged.all() and np.all(res.iterations == 1)
    assert np.max(np.abs(lam - ref) / np.abs(ref)) < 1e-13
    cond = factorial([1.0], [0.0, 40.0, 100.0], [0.0], ["forward", "reverse"])
    a = evaluate(model, cond, {"mu": 0.3 * cond.direction}, loss=LossFactors({"shim": flat}, BAND))
    b = evaluate(model, cond, {"mu": 0.3 * cond.direction, "eta.shim": np.full(cond.size, 0.08)})
    assert np.array_equal(a.eigenvalues, b.eigenvalues) and a.fixed_point is None
    # η(T) only: a parameter per condition, still no fixed point
    warm = LossTable([100.0], [0.0, 100.0], [[0.02], [0.2]], reference_temperature=20.0)
    c = evaluate(model, cond, {"mu": 0.3 * cond.direction}, loss=LossFactors({"shim": warm}, BAND))
    d = evaluate(model, cond, {"mu": 0.3 * cond.direction, "eta.shim": warm.value(100.0, cond.temperature)})
    assert np.array_equal(c.eigenvalues, d.eigenvalues)


def test_fixed_point_in_frequency_solves_each_mode_at_its_own_frequency():
    """η(f): every band mode converges to λ with λ an eigenvalue of the QEP at η(|Im λ|/2π) (the
    nonlinear eigenproblem), different from the start; too few iterations are reported, not hidden;
    a temperature outside the table is a named error before any computation."""
    model = shim_model()
    loss = LossFactors({"shim": RISING}, BAND, tol=1e-12)
    lam, res = condition_fixed_point(model, {}, 1.0, loss, 20.0)
    assert res.eigenvalues.size == 5 and res.converged.all() and res.iterations.max() > 2
    for x, eta in zip(res.eigenvalues, res.eta["shim"]):
        assert eta == pytest.approx(float(RISING.value(abs(x.imag) / TWO_PI, 20.0)), rel=1e-9)
        K, C = matrices_at(model, {"eta.shim": eta}, 1.0)
        assert np.min(np.abs(quadratic_eigs(K[None], C[None])[0] - x)) <= 1e-10 * abs(x)
    assert np.max(np.abs(res.eigenvalues - res.start) / np.abs(res.start)) > 1e-3
    short = condition_fixed_point(model, {}, 1.0, LossFactors({"shim": RISING}, BAND, max_iterations=2), 20.0)[1]
    assert not short.converged.all() and short.summary()["not_converged"][0]["iterations"] == 2
    cond = factorial([1.0], [20.0, 120.0], [0.0], ["forward"])
    with pytest.raises(ModelError, match=r"temperature 120 is outside the table's range \[0, 100\]"):
        evaluate(model, cond, {"mu": 0.3 * cond.direction}, loss=loss)
    cond = factorial([1.0], [20.0, 80.0], [0.0], ["forward", "reverse"])
    res2 = evaluate(model, cond, {"mu": 0.3 * cond.direction}, loss=loss)
    assert len(res2.fixed_point) == 4 and all(r["converged"] == r["modes"] for r in res2.fixed_point)
    np.testing.assert_array_equal(res2.eigenvalues[0], lam)
    with pytest.raises(ModelError, match=r"frequency 3000 is outside"):
        evaluate(model, cond, {"mu": 0.3 * cond.direction}, loss=LossFactors({"shim": RISING}, (200.0, 3000.0)))
