"""Monte Carlo robustness on the reduced model (fem_squeal.reduced.robustness).

* A degenerate distribution (std = 0, lower = upper) gives the nominal reduced CEA's answer.
* Uniform μ on the two-DOF Hoffmann model: P(unstable) = P(μ > μ_c) in closed form, within the
  estimator's standard error; the standard error falls as N^(−1/2).
* Same seed, same samples and results, whatever the chunking and the rank count (mpirun -n 2).
* Spearman ρ and its Fisher-z interval against scipy; bad distributions raise named errors.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import spearmanr
from support.paths import ROOT
from support.processes import clean_env

from fem_squeal.reduced.eigensolve import TWO_PI, unstable
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.robustness import Distribution, Probability, draw, run_robustness, spearman
from fem_squeal.reduced.stability_map import equal_bands
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.errors import ModelError, UnknownNameError

MU_C = 0.25
BAND = (0.0, 3200.0)


def hoffmann(kt=1.0e7, beta=0.0) -> ReducedModel:
    """The two-DOF model of fem_squeal.reduced.two_dof (unit mass, defaults): flutter for μ > μ_c =
    (−(k11 − k22 − kt)²/(4k12) − k12)/kt = 0.25 (k11 = 4.2e7, k22 = 3e7, k12 = −2e6, kt = 1e7).
    A part "pad" (its stiffness ∝ the contact stiffness) makes a second parameter."""
    K0 = np.array([[4.2e7, -2.0e6], [-2.0e6, 3.0e7 + kt]])
    Kpad = np.array([[0.0, 0.0], [0.0, kt]])
    return ReducedModel(K0=K0, Kf1=np.array([[0.0, kt], [0.0, 0.0]]), K_parts={"pad": Kpad},
                        E0={"pad": 8e9}, beta={"pad": beta}, mu0=0.4)


def brake_like(m: int = 24, seed: int = 1) -> ReducedModel:
    """A small friction model with several coupled pairs (for rank and determinism checks)."""
    rng = np.random.default_rng(seed)
    w = TWO_PI * np.sort(rng.uniform(200.0, 3000.0, m))
    K0 = np.diag(w ** 2)
    S = rng.standard_normal((m, m))
    Kf = 2e-2 * w.max() ** 2 * (S - S.T) / np.sqrt(m)
    Kd = np.diag(0.6 * w ** 2)
    return ReducedModel(K0=K0, Kf1=Kf, K_parts={"disc": Kd}, E0={"disc": 1.25e11}, mu0=0.4)


def test_degenerate_distribution_is_the_nominal_cea():
    model = brake_like()
    bands = equal_bands(BAND, 4)
    dists = {"mu": Distribution("normal", 0.4, 0.0), "E.disc": Distribution("uniform", 1.25e11, 1.25e11)}
    res = run_robustness(model, dists, 50, seed=7, band_hz=BAND, bands_hz=bands)
    lam = solve_points(model, {})[0]
    f = lam.imag / TWO_PI
    bad = unstable(lam) & (f >= BAND[0]) & (f <= BAND[1])
    assert bad.any()
    assert res.probability().p == 1.0 and res.probability().stderr == 0.0
    for (lo, hi), pb in zip(bands, res.band_probabilities()):
        expect = bool(np.any(bad & (f >= lo) & (f <= hi)))
        assert pb.p == float(expect)
    assert np.array_equal(res.family_lambda, np.broadcast_to(res.nominal, res.family_lambda.shape))
    assert np.array_equal(res.family_hits[0], unstable(res.nominal))
    print(f"degenerate: {int(bad.sum())} unstable nominal modes, per band "
          f"{[p.p for p in res.band_probabilities()]}")


def test_uniform_mu_two_dof_closed_form():
    model = hoffmann()
    a, b = 0.1, 0.5
    exact = (b - MU_C) / (b - a)
    rows = []
    for seed in (1, 2, 3):
        res = run_robustness(model, {"mu": Distribution("uniform", a, b)}, 4000, seed, BAND, [BAND])
        p = res.probability()
        rows.append((p.p, p.stderr, (p.p - exact) / p.stderr))
        # the estimate is exactly the share of samples beyond μ_c: all its error is sampling error
        assert np.array_equal(res.any_hit, res.samples["mu"] > MU_C)
        assert abs(p.p - exact) < 4 * p.stderr
        assert p.lo95 < exact < p.hi95 or abs(p.p - exact) < 3 * p.stderr
        # the family of the nominal unstable pair carries the probability; growth = Re λ of the family
        fam = res.family_probabilities()
        assert max(f.p for f in fam) == p.p
        # μ drives it: ρ(μ, max growth) close to 1
        d = res.drivers()["mu"]
        assert d["rho"] > 0.9 and d["ci95"][0] > 0.9
    print(f"P(μ > μ_c) exact {exact:.4f}; (p̂, SE, z):", [tuple(round(x, 4) for x in r) for r in rows])


def test_standard_error_falls_as_inverse_sqrt_n():
    model = hoffmann()
    dist = {"mu": Distribution("uniform", 0.1, 0.5)}
    se = [run_robustness(model, dist, n, 11, BAND, [BAND]).probability().stderr for n in (250, 1000, 4000, 16000)]
    ratios = [se[i] / se[i + 1] for i in range(len(se) - 1)]
    print("SE:", [f"{s:.4f}" for s in se], "ratios (expect 2):", [f"{r:.3f}" for r in ratios])
    assert all(abs(r - 2) < 0.15 for r in ratios)


def test_reproducible_and_chunk_independent():
    model = brake_like()
    dists = {"mu": Distribution("uniform", 0.2, 0.6), "E.disc": Distribution("lognormal", 1.25e11, 0.05e11)}
    r1 = run_robustness(model, dists, 300, 5, BAND, equal_bands(BAND, 3))
    r2 = run_robustness(model, dists, 300, 5, BAND, equal_bands(BAND, 3), chunk=7)
    assert all(np.array_equal(r1.samples[k], r2.samples[k]) for k in dists)
    assert np.array_equal(r1.any_hit, r2.any_hit) and np.array_equal(r1.family_lambda, r2.family_lambda)
    r3 = run_robustness(model, dists, 300, 6, BAND, equal_bands(BAND, 3))
    assert not np.array_equal(r1.samples["mu"], r3.samples["mu"])
    x = draw(dists, 20000, 1)["E.disc"]
    assert abs(x.mean() / 1.25e11 - 1) < 2e-3 and abs(x.std() / 0.05e11 - 1) < 0.03


SCRIPT = """
import json, sys
import numpy as np
from mpi4py import MPI
sys.path[:0] = {paths!r}
from test_robustness import brake_like, BAND
from fem_squeal.reduced.robustness import Distribution, run_robustness
from fem_squeal.reduced.stability_map import equal_bands
comm = MPI.COMM_WORLD
dists = {{"mu": Distribution("uniform", 0.2, 0.6), "E.disc": Distribution("normal", 1.25e11, 0.06e11)}}
r = run_robustness(brake_like(), dists, 301, 5, BAND, equal_bands(BAND, 3), comm=comm if comm.size > 1 else None)
if comm.rank == 0:
    print(json.dumps({{"hits": r.band_hits.astype(int).tolist(), "growth": r.max_growth.tolist(),
                      "fam": [[z.real, z.imag] for z in r.family_lambda.ravel()]}}))
"""


def test_same_results_on_one_and_two_ranks(tmp_path, mpirun):
    script = tmp_path / "rob.py"
    script.write_text(SCRIPT.format(paths=[str(Path(__file__).parent), str(ROOT / "tests")]))
    env = {**clean_env(), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    outs = []
    for cmd in ([sys.executable, str(script)], [*mpirun, sys.executable, str(script)]):
        p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120, cwd=ROOT)
        assert p.returncode == 0, p.stderr[-2000:]
        outs.append(json.loads(p.stdout.strip().splitlines()[-1]))
    assert outs[0] == outs[1]


def test_spearman_matches_scipy():
    rng = np.random.default_rng(0)
    x = rng.standard_normal(500)
    y = x + rng.standard_normal(500)
    s = spearman(x, y)
    assert abs(s["rho"] - spearmanr(x, y)[0]) < 1e-12
    assert s["ci95"][0] < s["rho"] < s["ci95"][1]
    assert spearman(np.ones(10), y[:10])["constant"]
    p = Probability.of(np.zeros(100, bool))
    assert p.p == 0 and p.stderr == 0 and 0.03 < p.hi95 < 0.04     # Wilson: ≈ 3.7 % (rule of three: 3 %)


def test_bad_distributions_named():
    with pytest.raises(ModelError, match="std: must be >= 0"):
        Distribution("normal", 0.4, -0.1)
    with pytest.raises(ModelError, match="lower: must be <= upper"):
        Distribution("uniform", 0.5, 0.3)
    with pytest.raises(ModelError, match="distribution: must be one of"):
        Distribution("weibull", 1.0, 2.0)
    with pytest.raises(ModelError, match="mean: must be > 0"):
        Distribution("lognormal", -1.0, 0.1)
    with pytest.raises(UnknownNameError, match="E.rotor"):
        run_robustness(hoffmann(), {"E.rotor": Distribution("uniform", 1.0, 2.0)}, 10, 1, BAND, [BAND])
    with pytest.raises(ModelError, match="E.pad: a Young's modulus must stay > 0"):
        run_robustness(hoffmann(), {"E.pad": Distribution("normal", 8e9, 2e9)}, 10, 1, BAND, [BAND])


# ---------------------------------------------------------------- the analyses (scene, run, report)

@pytest.mark.parametrize("override, message", [
    ("analyses.robustness.parameters.mu.std=-0.1", r"^analyses\.robustness\.parameters\.mu\.std: must be >= 0"),
    ("analyses.robustness.parameters.E.disc.lower=2e11",
     r"^analyses\.robustness\.parameters\.E\.disc\.lower: must be <= upper"),
    ("analyses.robustness.parameters.mu.distribution=weibull",
     r"^analyses\.robustness\.parameters\.mu\.distribution: must be one of"),
    ('analyses.robustness.parameters.kn.distribution="uniform"',
     r"^analyses\.robustness\.parameters\.kn: unknown parameter 'kn'"),
    ('analyses.robustness.parameters.E.rotor.distribution="uniform"',
     r"^analyses\.robustness\.parameters\.E\.rotor: unknown parameter 'E\.rotor'"),
    ('analyses.robustness.parameters.E.caliper.distribution="uniform"',
     r"^analyses\.robustness\.parameters\.E\.caliper: the reduced basis does not carry 'E\.caliper'"),
    ("analyses.robustness.parameters.mu.sigma=1", r"^analyses\.robustness\.parameters\.mu\.sigma: unknown key"),
    ("analyses.robustness.parameters.E.disc.distribution=normal",
     r"^analyses\.robustness\.parameters\.E\.disc\.lower: unknown key for a normal distribution"),
    ('analyses.sensitivity.parameters=["E.caliper"]',
     r"^analyses\.sensitivity\.parameters\[0\]: the reduced basis does not carry 'E\.caliper'"),
    ("analyses.sensitivity.kappa_max=0.5", r"^analyses\.sensitivity\.kappa_max: must be > 1"),
    ("analyses.sensitivity.modes=all", r"^analyses\.sensitivity\.modes: must be one of"),
])
def test_scene_errors_name_the_key(override, message):
    from fem_squeal.app.scene import load_scene
    from fem_squeal.util.errors import SceneError

    with pytest.raises(SceneError, match=message):
        load_scene(ROOT / "scenes" / "brake_robustness.toml", [override])


@pytest.mark.parametrize("override, message", [
    ('analyses.robustness.parameters.kn.piston_seal.distribution="uniform"',
     r"^analyses\.robustness\.parameters\.kn\.piston_seal: 'kn\.piston_seal': interface 'piston_seal' is a "
     r"spring; per-interface parameters exist for contact and rigid_plate interfaces with kn > 0 "
     r"\(\['pad_inner', 'pad_outer'\]\)"),
    ('analyses.robustness.parameters.kt.pad_rear.distribution="uniform"',
     r"^analyses\.robustness\.parameters\.kt\.pad_rear: unknown parameter 'kt\.pad_rear'; parameters are 'mu', "
     r"'E\.<part>' and 'eta\.<part>' with a part of \[.*\], 'mu\.<interface>', 'kn\.<interface>' and "
     r"'kt\.<interface>' with a contact or rigid_plate interface of \['pad_inner', 'pad_outer'\]"),
    ('analyses.sensitivity.parameters=["eta.caliper"]',
     r"^analyses\.sensitivity\.parameters\[0\]: the reduced basis does not carry 'eta\.caliper'.*"
     r"materials\.caliper\.eta > 0"),
    ("analyses.robustness.parameters.kn.pad_inner={distribution='normal', mean=5e11, std=1e11}",
     r"^analyses\.robustness\.parameters\.kn\.pad_inner: a contact stiffness must stay > 0"),
    ("analyses.robustness.parameters.kt.pad_inner={distribution='uniform', lower=-1e9, upper=1e9}",
     r"^analyses\.robustness\.parameters\.kt\.pad_inner: a tangential stiffness must stay >= 0"),
    ("materials.disc.eta=-0.01", r"^materials\.disc\.eta: must be >= 0"),
])
def test_scene_errors_for_the_interface_and_loss_parameters(override, message):
    from fem_squeal.app.scene import load_scene
    from fem_squeal.util.errors import SceneError

    with pytest.raises(SceneError, match=message):
        load_scene(ROOT / "scenes" / "brake_robustness.toml", [override])


def test_scene_accepts_the_interface_and_loss_parameters():
    """kn.<contact>, kt.<contact> (0 allowed), mu.<contact>, and eta.<part> of a part with a loss factor
    (the basis carries its stiffness: analyses.reduced.basis_design)."""
    from fem_squeal.app.analyses.reduced import basis_design
    from fem_squeal.app.analyses.robustness import distributions
    from fem_squeal.app.scene import load_scene, model_spec

    s = load_scene(ROOT / "scenes" / "brake_robustness.toml", [
        "analyses.robustness.parameters.kn.pad_inner={distribution='lognormal', mean=5e11, std=1e11}",
        "analyses.robustness.parameters.kt.pad_outer={distribution='uniform', lower=0.0, upper=1e11}",
        "analyses.robustness.parameters.mu.pad_outer={distribution='uniform', lower=0.3, upper=0.5}",
        "materials.lining_inner.eta=0.1",
        "analyses.robustness.parameters.eta.lining_inner={distribution='uniform', lower=0.05, upper=0.15}",
        'analyses.sensitivity.parameters=["mu", "kn.pad_inner", "kt.pad_outer", "mu.pad_outer", '
        '"eta.lining_inner"]'])
    d = distributions(s["analyses"]["robustness"])
    assert {"kn.pad_inner", "kt.pad_outer", "mu.pad_outer", "eta.lining_inner"} <= set(d)
    assert "lining_inner" in basis_design(s, model_spec(s))[3]


def test_robustness_E_distributions_go_into_the_basis_design():
    """A robustness distribution of E.<part> samples the part's modes at its range (uniform bounds,
    mean ± 3 std) and checks the reduced model there; the bundled scene's E sweep covers the same range,
    so its design is unchanged."""
    from fem_squeal.app.analyses.reduced import basis_design
    from fem_squeal.app.scene import load_scene, model_spec

    s = load_scene(ROOT / "scenes" / "brake_robustness.toml")
    base = load_scene(ROOT / "scenes" / "brake_robustness.toml",
                      ["analyses.robustness.parameters.E.disc.lower=1.2e11"])
    mu0, checks, samples, parts = basis_design(s, model_spec(s))
    assert samples == [{"E.disc": 112.5e9}, {"E.disc": 137.5e9}] and parts == ["disc"]
    _, _, samples_b, _ = basis_design(base, model_spec(base))
    assert {"E.disc": 1.2e11} in samples_b                   # the robustness range, beside the sweep's
    s = load_scene(ROOT / "scenes" / "brake_robustness.toml", [
        "analyses.robustness.parameters.E.caliper={distribution='normal', mean=1.7e11, std=1e10}",
        'analyses.sensitivity.parameters=["E.caliper"]'])
    _, checks, samples, parts = basis_design(s, model_spec(s))
    assert "caliper" in parts and {"E.caliper": 1.4e11} in samples and {"E.caliper": 2.0e11} in samples
    assert {"mu": mu0, "E.caliper": 1.4e11} in checks


def test_bundled_scene_loads():
    from fem_squeal.app.analyses.robustness import distributions
    from fem_squeal.app.pipeline import required
    from fem_squeal.app.scene import load_scene

    s = load_scene(ROOT / "scenes" / "brake_robustness.toml")
    d = distributions(s["analyses"]["robustness"])
    assert set(d) == {"mu", "E.disc"} and d["E.disc"].kind == "uniform"
    assert s["analyses"]["robustness"]["n_samples"] == 10000
    assert required(s)[-2:] == ["sensitivity", "robustness"]


class _Comm:
    rank, size = 0, 1


def _ctx(model, analyses: dict):
    from fem_squeal.app.fields import freeze
    from fem_squeal.app.stage import Context

    sections = {"reduced": {"band_hz": list(BAND), "growth_tol": 1e-6}, **analyses}
    analyses = {n: freeze(t, None, n) for n, t in sections.items()}
    scene = freeze({"title": "test", "analyses": analyses}, None, "scene")
    ctx = Context(scene, None, _Comm(), lambda *a: None, False, None, {})
    ctx.products["reduced"] = model
    return ctx


def test_analyses_run_and_report(tmp_path):
    """Both stages on a small model through their run/report functions (no FE model: no spot check)."""
    from fem_squeal.app.analyses import robustness as rob_stage
    from fem_squeal.app.analyses import sensitivity as sens_stage
    from fem_squeal.app.fields import check_fields

    model = brake_like()
    sec_s = check_fields({}, sens_stage.SECTION, "analyses.sensitivity")
    sec_r = check_fields({"n_samples": 400, "seed": 3, "n_bands": 4, "spot_checks": 0,
                          "parameters": {"mu": {"distribution": "uniform", "lower": 0.2, "upper": 0.6},
                                         "E": {"disc": {"distribution": "lognormal", "mean": 1.25e11,
                                                        "std": 0.1e11}}}},
                         rob_stage.SECTION, "analyses.robustness")
    ctx = _ctx(model, {"sensitivity": sec_s, "robustness": sec_r})
    out = sens_stage.run(ctx, tmp_path, {})["sensitivity"]
    lam = solve_points(model, {})[0]
    f = lam.imag / TWO_PI
    assert len(out) == int(np.sum(unstable(lam) & (f <= BAND[1])))
    for r in out:
        assert set(r["d_real_part"]) == {"mu", "E.disc"}
        assert r["unstable"] and (tmp_path / f"tornado_mode{r['index']}.png").is_file()
        if not r["near_coalescence"]:
            assert r["rel_d_real_part"]["mu"] == pytest.approx(0.4 * r["d_real_part"]["mu"])
    band = check_fields({"modes": "band", "parameters": ["mu"]}, sens_stage.SECTION, "analyses.sensitivity")
    every = sens_stage.run(_ctx(model, {"sensitivity": band}), tmp_path / "band", {})["sensitivity"]
    assert len(every) == int(np.sum(f <= BAND[1])) and all(set(r["d_freq_hz"]) == {"mu"} for r in every)
    html = sens_stage.report({"sensitivity": out})
    assert "<table>" in html and "Sensitivities" in html
    res = rob_stage.run(ctx, tmp_path, {})["robustness"]
    assert res["n_samples"] == 400 and len(res["bands"]) == 4 and set(res["drivers"]) == {"mu", "E.disc"}
    assert 0 < res["probability"]["p"] < 1
    assert all((tmp_path / n).is_file() for n in ("robustness.png", "robustness.npz", "robustness.json"))
    json.dumps(res)                                   # results.json-ready (plain types)
    html = rob_stage.report({"robustness": res})
    assert "P(at least one unstable mode)" in html and "Drivers" in html
    assert sens_stage.report({}) == "" and rob_stage.report({}) == ""


def test_monotone_driver_interval_contains_rho():
    """A perfectly monotone driver (ρ = 1, e.g. the growth of a ring's flutter pairs in μ) has an
    interval that contains ρ (the plot draws ρ minus/plus the interval: never negative)."""
    from fem_squeal.reduced.robustness import spearman

    x = np.linspace(0.2, 0.4, 200)
    for y, sign in ((x ** 3, 1.0), (-np.exp(x), -1.0)):
        d = spearman(x, y)
        assert d["rho"] == pytest.approx(sign, abs=1e-12)
        assert d["ci95"][0] <= d["rho"] <= d["ci95"][1]



def test_sobol_first_order_of_an_additive_model():
    """Y = 3X₁ + X₂ + 0·X₃ with independent X: S₁ = 9/10, S₂ = 1/10, S₃ = 0 (Var Xᵢ = 1); a non-monotone
    driver (Y = X₁², ρ ≈ 0) has S₁ = 1."""
    from fem_squeal.reduced.robustness import sobol_first_order

    rng = np.random.default_rng(7)
    n = 8000
    X = rng.standard_normal((3, n))
    y = 3 * X[0] + X[1]
    s = [sobol_first_order(x, y) for x in X]
    for si, ref in zip(s, (0.9, 0.1, 0.0)):
        assert si["ci95"][0] - 0.01 <= ref <= si["ci95"][1] + 0.01   # bootstrap interval (+ binning bias ~1e-2)
        assert abs(si["S1"] - ref) < 0.03                          # sampling + binning error at N = 8000
    u = rng.uniform(-1, 1, n)
    assert sobol_first_order(u, u ** 2)["S1"] > 0.95 and abs(spearman(u, u ** 2)["rho"]) < 0.05
    assert sobol_first_order(np.ones(n), y)["constant"]
    with pytest.raises(ModelError, match=r"^bins: must be in 2\.\.4000"):
        sobol_first_order(X[0], y, bins=1)
