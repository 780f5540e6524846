"""Reduced layer (pure NumPy): quadratic eigen-solves, tracking, coalescence, stability maps.

The two-degree-of-freedom mode-coupling model M = I, K(μ) = diag(ω₁², ω₂²) + μ[[0, a], [−b, 0]],
C = diag(c₁, c₂) has the characteristic polynomial
    det(s²I + sC + K) = s⁴ + a₃s³ + a₂s² + a₁s + a₀,
    a₃ = c₁ + c₂,  a₂ = ω₁² + ω₂² + c₁c₂,  a₁ = c₁ω₂² + c₂ω₁²,  a₀ = ω₁²ω₂² + μ²ab.
Only a₀ depends on μ, so by Routh–Hurwitz (a₃ > 0, a₃a₂ > a₁ and H₃ = a₃a₂a₁ − a₁² − a₃²a₀ > 0)
the flutter boundary is H₃ = 0:
    μc² ab = (a₃a₂a₁ − a₁²)/a₃² − ω₁²ω₂².
Undamped (c → 0 with c₁ = c₂) this is μc = (ω₂² − ω₁²)/(2√(ab)), the coalescence of the two
frequencies.  With c₁ = c, c₂ = ρc, c → 0, the limit is not the undamped value unless ρ = 1
(destabilisation paradox): unequal damping lowers μc.
"""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.reduced.eigensolve import quadratic_eigs, unstable
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.stability_map import equal_bands, stability_map
from fem_squeal.reduced.sweep import Grid, evaluate, path_solver, signed_mu_axis, solve_points
from fem_squeal.reduced.tracking import mac_matrix, track

W1, W2, A, B = 1.0, 1.2, 1.0, 1.0


def two_dof(c1: float = 0.0, c2: float = 0.0) -> ReducedModel:
    C = np.diag([c1, c2]) if c1 or c2 else None
    return ReducedModel(K0=np.diag([W1 ** 2, W2 ** 2]), Kf1=np.array([[0.0, A], [-B, 0.0]]), C0=C)


def mu_routh_hurwitz(c1: float, c2: float) -> float:
    a3, a2, a1 = c1 + c2, W1 ** 2 + W2 ** 2 + c1 * c2, c1 * W2 ** 2 + c2 * W1 ** 2
    return float(np.sqrt(((a3 * a2 * a1 - a1 ** 2) / a3 ** 2 - W1 ** 2 * W2 ** 2) / (A * B)))


MU_C0 = (W2 ** 2 - W1 ** 2) / (2 * np.sqrt(A * B))


def test_quadratic_eigs_match_polynomial_roots():
    """Reduced eigenvalues = the roots (Im ≥ 0) of the characteristic quartic, damped and not."""
    for c1, c2, mu in [(0, 0, 0.1), (0, 0, 0.3), (0.02, 0.07, 0.25)]:
        m = two_dof(c1, c2)
        K, C = m.matrices({"mu": np.array([mu])})
        lam = quadratic_eigs(K[0], None if C is None else C[0])
        a3, a2, a1 = c1 + c2, W1 ** 2 + W2 ** 2 + c1 * c2, c1 * W2 ** 2 + c2 * W1 ** 2
        roots = np.roots([1, a3, a2, a1, W1 ** 2 * W2 ** 2 + mu ** 2 * A * B])
        roots = roots[roots.imag > 0]
        assert np.allclose(np.sort_complex(lam), np.sort_complex(roots), rtol=1e-12, atol=1e-12)


def test_routh_hurwitz_limits_and_paradox():
    """The closed form reduces to the coalescence value undamped, rises with equal damping, and
    drops below it for unequal damping however small (the destabilisation paradox)."""
    assert mu_routh_hurwitz(1e-7, 1e-7) == pytest.approx(MU_C0, rel=1e-6)
    assert mu_routh_hurwitz(0.05, 0.05) > MU_C0
    for c in (1e-2, 1e-4, 1e-6):
        assert mu_routh_hurwitz(c, 5 * c) < 0.9 * MU_C0


@pytest.mark.parametrize("c1,c2", [(0.0, 0.0), (0.01, 0.05), (0.03, 0.03), (1e-4, 1e-3)])
def test_tracker_finds_routh_hurwitz_critical_mu(c1, c2):
    """Sweep sign(v)μ over [−0.5, 0.5] in steps of 0.01: the onset is bracketed by the grid step
    around the exact μc (both sliding directions: μ enters through μ²) and refined to 1e-8."""
    mu_c = MU_C0 if c1 == c2 == 0 else mu_routh_hurwitz(c1, c2)
    model = two_dof(c1, c2)
    tr = track(path_solver(model, "mu"), signed_mu_axis(0.5, 101))
    onsets = [e for e in tr.events if e.onset]
    assert len(onsets) == 2, tr.events
    for e in onsets:
        lo, hi = sorted(e.bracket)
        assert lo <= np.sign(e.value) * mu_c <= hi
        assert abs(abs(e.value) - mu_c) < 1e-8
        assert set(e.labels) == {"M1", "M2"}
        assert e.kind == ("coalescence" if c1 == c2 == 0 else e.kind)
    # the unstable side is the one with the larger real part, never both
    k = np.searchsorted(tr.values, 0.45)
    assert np.sum(unstable(tr.eigenvalues[k])) == 1


def test_crossing_followed_by_shape():
    """No coupling: K = diag(1 + μ, 2 − μ, 5) crosses at μ = 0.5 (a grid point); each branch keeps
    its own shape and eigenvalue line."""
    model = ReducedModel(K0=np.diag([1.0, 2.0, 5.0]), Kf1=np.diag([1.0, -1.0, 0.0]))
    mu = np.linspace(0.0, 1.0, 21)
    tr = track(path_solver(model, "mu"), mu)
    w2 = -(tr.eigenvalues ** 2).real
    assert np.allclose(w2[:, 0], 1 + mu) and np.allclose(w2[:, 1], 2 - mu) and np.allclose(w2[:, 2], 5)
    assert not tr.events


def test_veering_followed_without_swap():
    """Weak coupling ε = 1e-3: the curves repel over a width ~2ε, 25× finer than the grid step;
    the tracker must keep the lower branch lower (no swap to the other shape)."""
    eps = 1e-3
    model = ReducedModel(K0=np.array([[1.0, eps], [eps, 2.0]]), Kf1=np.diag([1.0, -1.0]))
    mu = np.linspace(0.0, 1.0, 21)
    tr = track(path_solver(model, "mu"), mu)
    exact = np.array([np.linalg.eigvalsh(np.array([[1 + p, eps], [eps, 2 - p]])) for p in mu])
    assert np.allclose(-(tr.eigenvalues ** 2).real, exact, rtol=1e-12)
    assert tr.solves > mu.size  # the veering step was bisected


def test_mac_matrix():
    Y = np.linalg.qr(np.random.default_rng(0).normal(size=(5, 5)))[0]
    assert np.allclose(mac_matrix(Y, Y), np.eye(5))
    assert np.allclose(mac_matrix(Y, 2j * Y), np.eye(5))


def test_grid_evaluate_and_map():
    """A (μ, c) grid on the 2-DOF model: the map counts 1 unstable mode exactly where μ > μc and
    all points are computed identically in chunks."""
    model = two_dof()
    model.K_parts = {"x": np.diag([1.0, 0.0])}
    model.E0 = {"x": 1.0}
    grid = Grid({"E.x": np.linspace(0.8, 1.2, 5), "mu": signed_mu_axis(0.5, 41)})
    res = evaluate(model, grid, chunk=7)
    assert res.eigenvalues.shape == (5, 41, 2)
    smap = stability_map(res, equal_bands((0.0, 1.0), 2))
    theta = grid.axes["E.x"]
    for i, t in enumerate(theta):
        mu_c = (W2 ** 2 - W1 ** 2 * t) / 2
        expect = (np.abs(grid.axes["mu"]) > mu_c + 1e-9).astype(int)
        near = np.abs(np.abs(grid.axes["mu"]) - mu_c) < 1e-9
        assert np.array_equal(smap.total[i][~near], expect[~near])
    assert np.array_equal(smap.counts.sum(axis=0), smap.total)
    one = solve_points(model, {"E.x": np.array([1.0]), "mu": np.array([0.3])})
    assert np.allclose(one[0], res.eigenvalues[2, np.argmin(np.abs(grid.axes["mu"] - 0.3))])


def test_bad_parameters_named():
    model = two_dof()
    with pytest.raises(KeyError, match="E.disc: not a parameter"):
        model.matrices({"E.disc": np.array([1.0])})
    with pytest.raises(ValueError, match="mu_max"):
        signed_mu_axis(-1, 10)
    with pytest.raises(ValueError, match="grid.mu"):
        Grid({"mu": []})
    with pytest.raises(ValueError, match="values"):
        track(path_solver(model, "mu"), [0.0, 0.0])


def test_save_load_roundtrip(tmp_path):
    model = two_dof(0.01, 0.02)
    model.K_parts, model.E0, model.beta = {"x": np.eye(2)}, {"x": 2e11}, {"x": 1e-5}
    model.info = {"modes": 2, "static": 0, "built_on": "two ranks"}
    model.save(tmp_path / "r.npz")
    back = ReducedModel.load(tmp_path / "r.npz")
    pts = {"mu": np.array([0.3]), "E.x": np.array([2.2e11])}
    assert np.allclose(solve_points(back, pts), solve_points(model, pts))
    # the basis counts survive (a map or sweep on a cached model names its couplings by info['modes']);
    # what is not a count is not kept
    assert back.info == {"modes": 2, "static": 0}


def _random_coupled(m: int = 30, seed: int = 3) -> ReducedModel:
    """m modes 1..10 rad/s, weakly coupled, a non-symmetric friction-like coupling of neighbours
    and light damping: coalescences, veerings and crossings along μ ∈ [−0.5, 0.5]."""
    rng = np.random.default_rng(seed)
    w2 = np.sort(rng.uniform(1.0, 100.0, m))
    S = 0.05 * rng.normal(size=(m, m))
    F = np.diag(rng.normal(size=m - 1), 1) * 4.0 - np.diag(rng.normal(size=m - 1), -1) * 4.0
    return ReducedModel(K0=np.diag(w2) + 0.5 * (S + S.T), Kf1=F + np.diag(rng.normal(size=m)),
                        C0=np.diag(rng.uniform(1e-3, 2e-2, m)))


@pytest.mark.parametrize("case", ["undamped", "damped", "crossing", "veering", "random"])
def test_values_first_tracking_follows_the_same_branches(case):
    """Steps accepted on eigenvalues alone (``values_solve``: no eigenvectors where every watched
    branch's new eigenvalue is unambiguously the one nearest its linear prediction; issue 23) give
    the branches of MAC continuation with eigenvectors at every step: the tracked eigenvalues equal to
    the round-off of the two LAPACK paths (eigvals vs eig, ~1e-13 relative here; a wrong assignment
    would be an O(1) difference) and the same events, located to the refinement tolerance (1e-10 of
    the range); with fewer eigenvector solves."""
    model = {"undamped": two_dof(), "damped": two_dof(0.01, 0.05),
             "crossing": ReducedModel(K0=np.diag([1.0, 2.0, 5.0]), Kf1=np.diag([1.0, -1.0, 0.0])),
             "veering": ReducedModel(K0=np.array([[1.0, 1e-3], [1e-3, 2.0]]), Kf1=np.diag([1.0, -1.0])),
             "random": _random_coupled()}[case]
    grid = signed_mu_axis(0.5, 201)
    vec = track(path_solver(model, "mu"), grid)
    fast = track(path_solver(model, "mu"), grid, values_solve=path_solver(model, "mu", vectors=False))
    assert np.max(np.abs(fast.eigenvalues - vec.eigenvalues) / np.abs(vec.eigenvalues)) < 1e-9
    assert [(e.branch, e.onset, e.kind) for e in fast.events] == [(e.branch, e.onset, e.kind) for e in vec.events]
    assert np.allclose([e.value for e in fast.events], [e.value for e in vec.events], rtol=0, atol=1e-9)
    assert fast.vector_solves < vec.vector_solves == vec.solves
    if case == "random":
        assert len(vec.events) >= 4 and fast.vector_solves < 0.6 * vec.vector_solves
