"""The operating matrix on the reduced model (issue 39, first part): the friction table μ(T, Ω) and its
range checks, the conditions, the direction (friction and gyroscopic terms turned), the noise matrix,
and every condition computed alone (what makes the result independent of the rank count)."""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.reduced.eigensolve import quadratic_eigs
from fem_squeal.reduced.laws.friction import ConstantFriction, StribeckFriction, TableFriction, operating_mu
from fem_squeal.reduced.model import PlateProjection, ReducedModel
from fem_squeal.reduced.operating_matrix import (
    Conditions,
    InterfaceLaw,
    evaluate,
    factorial,
    from_table,
    matrices_at,
    noise_matrix,
    parameter_points,
)
from fem_squeal.util.errors import ModelError

W1, W2 = 2 * np.pi * 1000.0, 2 * np.pi * 1100.0


def spinning_model(m: int = 6, seed: int = 1) -> ReducedModel:
    """A random model with friction, a named plate (its own μ), gyroscopic, Ω² and friction-damping terms."""
    rng = np.random.default_rng(seed)
    w2 = (2 * np.pi * np.linspace(1000, 3000, m)) ** 2
    sym = lambda A: 0.5 * (A + A.T)  # noqa: E731
    G = rng.normal(size=(m, m)) * 50.0
    plate = PlateProjection(Kc=sym(rng.normal(size=(m, m))) * 1e5, Kt=np.zeros((m, m)),
                            Kf=rng.normal(size=(m, m)) * 1e6, kn=1e10, mu=0.4, sliding=1)
    return ReducedModel(K0=np.diag(w2), Kf1=rng.normal(size=(m, m)) * 3e6, C0=np.eye(m) * 20.0, mu0=0.4,
                        plates={"pad": plate}, speed0=60.0, G1=G - G.T, K2=sym(rng.normal(size=(m, m))) * 10.0,
                        Cd0=np.eye(m) * 5.0, speed_varies=True)


def flutter_model() -> ReducedModel:
    """Two modes coupled by friction (no damping): flutter above μ_c = (W2² − W1²)/(2√(AB)) = 0.5."""
    a = (W2 ** 2 - W1 ** 2) / (2 * 0.5)
    return ReducedModel(K0=np.diag([W1 ** 2, W2 ** 2]), Kf1=np.array([[0.0, a], [-a, 0.0]]), mu0=0.3)


def test_table_is_bilinear_and_refuses_conditions_outside():
    law = TableFriction([0.0, 100.0, 300.0], [0.0, 50.0], [[0.5, 0.4], [0.3, 0.2], [0.1, 0.3]])
    assert law.coefficient(100.0, 50.0) == pytest.approx(0.2)
    assert law.coefficient(50.0, 25.0) == pytest.approx(0.25 * (0.5 + 0.4 + 0.3 + 0.2))
    assert law.coefficient(200.0, -50.0) == pytest.approx(0.5 * (0.2 + 0.3))   # |Ω|: the direction is separate
    np.testing.assert_allclose(law.coefficient(np.array([0.0, 300.0]), 0.0), [0.5, 0.1])
    with pytest.raises(ModelError,
                       match=r"^friction table: temperature 301 is outside the table's range \[0, 300\]"):
        law.coefficient([20.0, 301.0], 10.0)
    with pytest.raises(ModelError, match=r"^friction table: speed 60 is outside the table's range \[0, 50\]"):
        law.coefficient(20.0, 60.0)
    one = TableFriction([20.0], [0.0, 100.0], [[0.4, 0.2]])     # one temperature: independent of T
    assert one.coefficient(900.0, 50.0) == pytest.approx(0.3)
    with pytest.raises(ModelError, match=r"^x\.mu: must have one row per temperature .* shape \(2, 2\)"):
        TableFriction([0.0, 1.0], [0.0, 1.0], [[0.4, 0.4, 0.4]], name="x")
    with pytest.raises(ModelError, match=r"^x\.temperature: must be strictly increasing"):
        TableFriction([1.0, 0.0], [0.0], [[0.4], [0.4]], name="x")


def test_constant_and_stribeck_are_special_cases():
    T, W = np.array([20.0, 300.0]), np.array([10.0, 100.0])
    np.testing.assert_array_equal(operating_mu(ConstantFriction(0.37), T, W), [0.37, 0.37])
    s = StribeckFriction(0.5, 0.35, 0.05, 2.0)
    np.testing.assert_array_equal(operating_mu(s, T, W, radius=0.1), s.coefficient(W * 0.1)[0])
    with pytest.raises(ModelError, match="radius: must be > 0"):
        operating_mu(s, T, W)
    table = TableFriction([0.0, 400.0], [0.0, 200.0], np.full((2, 2), 0.37))
    np.testing.assert_array_equal(operating_mu(table, T, W), [0.37, 0.37])


def test_factorial_table_and_corners():
    c = factorial([1.0], [50.0, 150.0, 250.0], [10.0, 60.0], ["forward", "reverse"])
    assert c.size == 12
    assert c.row(1) == {"pressure": 1.0, "temperature": 50.0, "speed": 10.0, "direction": "reverse"}
    assert c.corners() == [0, 1, 2, 3, 8, 9, 10, 11]
    t = from_table([{"pressure": 1, "temperature": 20, "speed": 5, "direction": "reverse"}])
    assert t.direction.tolist() == [-1.0]
    with pytest.raises(ModelError, match=r"^direction: must be one of \['forward', 'reverse'\]"):
        factorial([1.0], [20.0], [1.0], ["backward"])
    with pytest.raises(ModelError, match=r"^conditions\.pressure: must be > 0"):
        factorial([0.0], [20.0], [1.0], ["forward"])
    with pytest.raises(ModelError, match=r"^conditions\[0\]: missing \['speed'\]"):
        from_table([{"pressure": 1, "temperature": 20, "direction": "forward"}])


def test_constant_table_reproduces_the_nominal_model_exactly():
    model = spinning_model()
    law = InterfaceLaw(TableFriction([0.0, 400.0], [0.0, 200.0], np.full((2, 2), 0.4)))
    cond = factorial([1.0], [20.0], [60.0], ["forward"])
    K, C = matrices_at(model, {k: v[0] for k, v in parameter_points(model, cond, {}, law).items()}, 1)
    K0, C0 = model.matrices()
    np.testing.assert_array_equal(K, K0[0])
    np.testing.assert_array_equal(C, C0[0])
    res = evaluate(model, cond, parameter_points(model, cond, {"pad": law}, law))
    np.testing.assert_allclose(res.eigenvalues[0], quadratic_eigs(K0, C0)[0], rtol=1e-12)


def test_reverse_turns_friction_and_gyroscopic_terms_only():
    model = spinning_model()
    law = InterfaceLaw(TableFriction([0.0, 400.0], [0.0, 200.0], [[0.5, 0.3], [0.4, 0.2]]))
    cond = factorial([1.0], [100.0], [80.0], ["forward", "reverse"])
    pts = parameter_points(model, cond, {"pad": InterfaceLaw(ConstantFriction(0.25))}, law)
    mu = float(law.mu(100.0, 80.0))
    assert mu == pytest.approx(0.75 * 0.6 * 0.5 + 0.25 * 0.6 * 0.4 + 0.75 * 0.4 * 0.3 + 0.25 * 0.4 * 0.2)  # 0.395
    assert pts["mu"].tolist() == pytest.approx([mu, -mu]) and pts["mu.pad"].tolist() == [0.25, -0.25]
    Kf, Cf = matrices_at(model, {k: v[0] for k, v in pts.items()}, 1)
    Kr, Cr = matrices_at(model, {k: v[1] for k, v in pts.items()}, -1)
    pl = model.plates["pad"]
    # K(μ, Ω) = K0 + μ Kf1 + (μ_pad − μ μ_pad⁰/μ⁰) Kf_pad + Ω² K2;  C = C0 + Ω G1 + (|μ|/|μ⁰|)(Ω₀/|Ω|) Cd0
    for d, K, C in ((1, Kf, Cf), (-1, Kr, Cr)):
        K_expected = model.K0 + d * mu * model.Kf1 + d * (0.25 - mu) * pl.Kf + 80.0 ** 2 * model.K2
        np.testing.assert_allclose(K, K_expected, rtol=1e-13, atol=1e-6)
        np.testing.assert_allclose(C, model.C0 + d * 80.0 * model.G1 + (mu / 0.4) * (60.0 / 80.0) * model.Cd0,
                                   rtol=1e-13, atol=1e-9)


def test_speed_that_the_model_cannot_follow_is_named():
    model = spinning_model()
    model.speed_varies = False
    cond = factorial([1.0], [20.0], [30.0], ["forward"])
    with pytest.raises(ModelError, match=r"^speed: the disc speed is not a parameter of this reduced model"):
        parameter_points(model, cond, {})
    with pytest.raises(ModelError, match=r"^friction\.disc: not a sliding interface with its own μ"):
        parameter_points(spinning_model(), cond, {"disc": InterfaceLaw(ConstantFriction(0.3))})


def test_noise_matrix_counts_by_band_and_variable():
    """μ(T) crosses the flutter threshold 0.5 between 100 and 200 °C: the hot conditions are stable in both
    directions (friction coupling flutters for either sign of μ), and the unstable pair lies near 1.05 kHz."""
    model = flutter_model()
    law = InterfaceLaw(TableFriction([0.0, 300.0], [0.0], [[0.7], [0.3]]))
    cond = factorial([1.0], [0.0, 100.0, 200.0, 300.0], [0.0], ["forward", "reverse"])
    res = evaluate(model, cond, parameter_points(model, cond, {}, law))
    noise = noise_matrix(res, (0.0, 10000.0), 1e-6)
    assert noise["n_unstable"] == [1, 1, 1, 1, 0, 0, 0, 0]
    assert noise["unstable_conditions"] == 4 and noise["occurrence"] == 0.5
    band = {b["band_hz"]: b["conditions"] for b in noise["third_octave"]}
    assert band[1000] == 4 and sum(band.values()) == 4
    by_t = {r["value"]: r["occurrence"] for r in noise["by_variable"]["temperature"]}
    assert by_t == {0.0: 1.0, 100.0: 1.0, 200.0: 0.0, 300.0: 0.0}
    assert [r["occurrence"] for r in noise["by_variable"]["direction"]] == [0.5, 0.5]
    m = noise["modes"][0]
    mu = 0.7
    sigma = (W2 ** 2 - W1 ** 2) * np.sqrt(mu ** 2 - 0.25)     # eig K = (W1² + W2²)/2 ± i sigma
    lam2 = -(W1 ** 2 + W2 ** 2) / 2 + 1j * sigma              # λ² of the flutter pair
    assert m["growth_rate"] == pytest.approx(np.sqrt(lam2).real, rel=1e-9)
    assert m["frequency_hz"] == pytest.approx(np.sqrt(lam2).imag / (2 * np.pi), rel=1e-9)


def test_unstable_modes_carry_their_coupling_pair():
    """Above flutter, (λ² + W1²)y₁ + μa y₂ = 0 with |λ² + W1²| = μ(W2² − W1²) = μa: |y₁| = |y₂|, the two real
    modes at 50 % each, for every μ; nothing outside (the two modes span the model).  The inverse-iteration
    vector gives the participations of the full eigenvector matrix to 1e-10."""
    import dataclasses

    from fem_squeal.reduced.mode_coupling import basis_modes, modal_part, participation
    from fem_squeal.reduced.operating_matrix import mode_couplings

    model = dataclasses.replace(flutter_model(), info={"modes": 2})
    law = InterfaceLaw(TableFriction([0.0, 300.0], [0.0], [[0.9], [0.3]]))
    cond = factorial([1.0], [0.0, 100.0, 150.0], [0.0], ["forward", "reverse"])     # μ 0.9, 0.7, 0.6
    pts = parameter_points(model, cond, {}, law)
    res = evaluate(model, cond, pts)
    noise = noise_matrix(res, (0.0, 10000.0), 1e-6)
    mode_couplings(model, res, pts, noise["modes"])
    assert len(noise["modes"]) == 6
    freqs, V = basis_modes(model.K0, 2)
    for m in noise["modes"]:
        c = m["coupling"]
        assert sorted(c["real_modes"]) == [0, 1] and c["percent"] == pytest.approx([50.0, 50.0], abs=1e-8)
        assert abs(c["outside"]) < 1e-12 and c["label"] == "real modes 0 (50 %) and 1 (50 %)"
        K, C = matrices_at(model, {n: v[m["condition"]] for n, v in pts.items()}, res.conditions.direction[
            m["condition"]])
        lam, Y = quadratic_eigs(K[None], None, vectors=True)
        j = np.argmin(np.abs(lam[0] - complex(m["growth_rate"], 2 * np.pi * m["frequency_hz"])))
        p, _ = participation(V.T @ modal_part(Y[0][:, [j]], 2)[0], np.ones(1))
        assert np.sort(p[:, 0]) == pytest.approx(np.sort(c["percent"]), abs=1e-10)


def signature() -> dict:
    """The couplings of the spinning model's unstable modes on the ranks of COMM_WORLD (an ``mpirun -n 2``
    child of :func:`test_couplings_do_not_depend_on_the_rank_count`, or this process)."""
    import dataclasses

    from mpi4py import MPI

    from fem_squeal.reduced.operating_matrix import mode_couplings

    model = dataclasses.replace(spinning_model(), info={"modes": 4})
    law = InterfaceLaw(TableFriction([0.0, 400.0], [0.0, 200.0], [[0.9, 0.7], [0.8, 0.6]]))
    cond = factorial([1.0], [20.0, 380.0], [10.0, 150.0], ["forward", "reverse"])
    pts = parameter_points(model, cond, {}, law)
    res = evaluate(model, cond, pts, MPI.COMM_WORLD)
    modes = noise_matrix(res, (0.0, 1e5), 1e-6)["modes"]
    mode_couplings(model, res, pts, modes, comm=MPI.COMM_WORLD)
    return {"percent": [m["coupling"]["percent"] for m in modes], "pairs": [m["coupling"]["pair"] for m in modes]}


@pytest.mark.mpi
def test_couplings_do_not_depend_on_the_rank_count(mpirun, tmp_path):
    from support.ranks import two_rank_signature

    one = signature()
    assert len(one["pairs"]) >= 2
    assert two_rank_signature(mpirun, "test_operating_matrix", tmp_path / "two.json") == one


def test_rigid_body_modes_are_not_counted_unstable():
    """A free part's rigid-body mode (λ ≈ 0 with a round-off growth rate, as the ring's between its plates)
    is no squeal: the noise matrix leaves out the band's modes below 1e-3 of its top (eigensolve.in_band)."""
    from fem_squeal.reduced.eigensolve import in_band
    from fem_squeal.reduced.operating_matrix import MatrixResult

    lam = np.array([[0.007 + 0.002j, 1e-3 + 0.011j, 2.0 + 2 * np.pi * 9413.0j, -1.0 + 2 * np.pi * 500.0j]])
    res = MatrixResult(factorial([1.0], [20.0], [0.0], ["forward"]), lam, 0.0, 1)
    modes = noise_matrix(res, (0.0, 10000.0), 1e-6)["modes"]
    assert [round(m["frequency_hz"]) for m in modes] == [9413]
    assert in_band(lam[0], (0.0, 10000.0)).tolist() == [False, False, True, True]


def test_a_condition_does_not_depend_on_the_others():
    """Each condition is solved alone: any subset (a rank's share) gives the same bits."""
    model = spinning_model()
    law = InterfaceLaw(TableFriction([0.0, 400.0], [0.0, 200.0], [[0.5, 0.3], [0.4, 0.2]]))
    cond = factorial([1.0], [20.0, 200.0, 380.0], [10.0, 150.0], ["forward", "reverse"])
    pts = parameter_points(model, cond, {}, law)
    full = evaluate(model, cond, pts).eigenvalues
    odd = np.arange(1, cond.size, 2)
    sub = Conditions(*(getattr(cond, v)[odd] for v in ("pressure", "temperature", "speed", "direction")))
    part = evaluate(model, sub, {k: v[odd] for k, v in pts.items()}).eigenvalues
    np.testing.assert_array_equal(part, full[odd])


def test_table_over_pressure_is_trilinear_and_a_constant_layer_reproduces_mu():
    layers = [[[0.5, 0.4], [0.3, 0.2]], [[0.6, 0.5], [0.4, 0.1]]]
    law = TableFriction([0.0, 100.0], [0.0, 50.0], layers, pressure=[0.5, 1.5])
    flat = [TableFriction([0.0, 100.0], [0.0, 50.0], m) for m in layers]
    T, W, p = np.array([30.0, 70.0, 100.0]), np.array([10.0, 40.0, 50.0]), np.array([0.5, 0.8, 1.5])
    r = (p - 0.5) / 1.0
    np.testing.assert_allclose(law.coefficient(T, W, p),
                               (1 - r) * flat[0].coefficient(T, W) + r * flat[1].coefficient(T, W), rtol=1e-14)
    const = TableFriction([0.0, 400.0], [0.0, 200.0], np.full((3, 2, 2), 0.37), pressure=[0.5, 1.0, 2.0])
    np.testing.assert_array_equal(operating_mu(const, T, W, pressure=[0.5, 1.3, 2.0]), [0.37] * 3)
    same = TableFriction([0.0, 100.0], [0.0, 50.0], [layers[0]], pressure=[1.0])   # one pressure: independent of p
    twice = TableFriction([0.0, 100.0], [0.0, 50.0], [layers[0]] * 2, pressure=[0.5, 1.5])  # constant in p
    np.testing.assert_array_equal(twice.coefficient(T, W, p), flat[0].coefficient(T, W))
    np.testing.assert_array_equal(same.coefficient(T, W, [7.0, 0.1, 3.0]), flat[0].coefficient(T, W))
    with pytest.raises(ModelError, match=r"^friction table: pressure 2 is outside the table's range \[0\.5, 1\.5"):
        law.coefficient(T, W, [1.0, 2.0, 1.0])
    with pytest.raises(ModelError, match=r"^friction table: the table depends on the pressure"):
        law.coefficient(T, W)
    with pytest.raises(ModelError, match=r"^x\.mu: with a pressure axis, .* shape \(2, 2, 2\)"):
        TableFriction([0.0, 100.0], [0.0, 50.0], layers[0], pressure=[0.5, 1.5], name="x")
    with pytest.raises(ModelError, match=r"^x\.pressure: must be > 0"):
        TableFriction([0.0, 100.0], [0.0, 50.0], layers, pressure=[0.0, 1.5], name="x")
    cond = factorial([0.5, 1.5], [30.0], [10.0], ["forward", "reverse"])
    pts = parameter_points(flutter_model(), cond, {}, InterfaceLaw(law))
    np.testing.assert_allclose(pts["mu"], [1, -1, 1, -1] * law.coefficient(30.0, 10.0, cond.pressure))


def test_pressure_acts_through_the_stress_stiffening_term():
    """A model with the pressure parameter (K_σ,s): a condition at pressure p solves K(μ, Ω) + (p − 1) K_σ,s;
    at p = 1 exactly the model without it; a model without it does not see the pressure (μ(p) aside)."""
    base, model = spinning_model(), spinning_model()
    S = np.random.default_rng(3).normal(size=(base.size, base.size))
    model.Ksp = 1e5 * (S + S.T)
    assert "pressure" in model.parameters and "pressure" not in base.parameters
    cond = factorial([0.5, 1.0, 2.0], [20.0], [60.0, 90.0], ["forward", "reverse"])
    pts, pts0 = parameter_points(model, cond, {}), parameter_points(base, cond, {})
    assert np.array_equal(pts["pressure"], cond.pressure) and "pressure" not in pts0
    res, same = evaluate(model, cond, pts), evaluate(base, cond, pts0)
    for k in range(cond.size):
        K, C = matrices_at(base, {n: v[k] for n, v in pts0.items()}, cond.direction[k])
        K = K + (cond.pressure[k] - 1.0) * model.Ksp
        np.testing.assert_allclose(res.eigenvalues[k], quadratic_eigs(K[None], C[None])[0], rtol=1e-12)
    assert np.array_equal(res.eigenvalues[4:8], same.eigenvalues[4:8])          # p = 1
    assert np.array_equal(same.eigenvalues[0:4], same.eigenvalues[4:8])         # base: p not seen
    assert not np.allclose(res.eigenvalues[0:4], same.eigenvalues[0:4], rtol=1e-6)
