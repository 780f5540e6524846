"""AFT accuracy against closed forms at the code's default samples per period (issue: MASA AFT
samples against the error in K₁; benchmark: benchmarks/masa_aft.py)."""
from __future__ import annotations

import inspect

import numpy as np
import pytest

from fem_squeal.reduced.aft import cubic_remainder_stiffness, first_harmonic
from fem_squeal.reduced.laws.contact import UnilateralLaw, exponential_like, tune_cubic
from fem_squeal.reduced.masa import MasaProblem

DEFAULT_N = inspect.signature(MasaProblem).parameters["n_samples"].default
K_L, K_NL, D0 = (float(v) for v in tune_cubic(1e7, 100.0, 0.3))   # 30 % cubic, as two_dof_model
LAW = UnilateralLaw(k_l=K_L, k_nl=K_NL)


def _k(law, d0, A, N, phase=0.7):
    A = np.asarray(A, float)
    return first_harmonic(law, np.full(A.shape, d0), A * np.cos(phase), A * np.sin(phase), 2e4, N).k


def test_default_n_is_64():
    # the benchmark's tolerances below are derived for the default; a change must be deliberate
    assert DEFAULT_N == 64
    assert inspect.signature(first_harmonic).parameters["n_samples"].default == DEFAULT_N


def test_no_contact_loss_is_exact_from_five_samples():
    """Without loss r(θ) = k_nl A²cos²θ (3δ₀ + A cos θ) has harmonics 0…3.  The N-point sum of
    r cos θ picks up harmonic j of r where j ≡ ±1 (mod N): only j = 3 at N = 4 (3 ≡ −1).  So
    N = 4 gives k = (¾ + ¼)k_nl A² exactly and every N ≥ 5 gives ¾k_nl A² to round-off."""
    A = np.linspace(0.02, 0.99, 40) * D0
    exact = 0.75 * K_NL * A ** 2
    for N in (5, 6, 7, 8, 16, DEFAULT_N, 1000):
        for phase in (0.0, 0.7, 2.5):
            assert np.max(np.abs(_k(LAW, D0, A, N, phase) / exact - 1)) < 1e-12, (N, phase)
    assert _k(LAW, D0, A, 4) == pytest.approx(K_NL * A ** 2, rel=1e-12)


def test_contact_loss_error_at_default_n_within_the_kink_bound():
    """With loss the force has a slope jump k_l where contact opens (θ = ±θ*, cos θ* = −δ₀/A).
    The trapezoidal sum of a periodic function with derivative jumps [g'] errs by
    h²/2·B̄₂(s)·Σ[g'] (Euler–Maclaurin, |B̄₂| ≤ 1/6), which for g = r cos θ gives
    |Δk| ≤ (2π/3N²) k_l |sin θ* cos θ*|.  benchmarks/masa_aft.py measures max error/bound
    = 0.98–1.01 for N ≥ 16 (the bound is reached: the sample offset s sweeps all values over the
    amplitudes), so 1.05 leaves room for the O(N⁻³) term only.  Relative: 2.0e-3 at N = 64."""
    A = np.geomspace(1.001, 10.0, 400) * D0
    exact = cubic_remainder_stiffness(K_L, K_NL, D0, A)
    th = np.arccos(-D0 / A)
    for N in (16, DEFAULT_N, 256):
        err = np.abs(_k(LAW, D0, A, N) - exact)
        bound = 2 * np.pi / (3 * N ** 2) * K_L * np.abs(np.sin(th) * np.cos(th))
        assert np.all(err <= 1.05 * bound + 1e-12 * np.abs(exact)), N
        assert np.max(err / bound) > 0.9                  # and the bound is sharp (N⁻², not faster)
    rel = np.abs(_k(LAW, D0, A, DEFAULT_N) / exact - 1)
    assert rel.max() < 2.5e-3
    # N⁻²: the envelope over the amplitudes drops by 16 per factor 4 in N (measured 16.1)
    e64, e256 = (np.max(np.abs(_k(LAW, D0, A, N) / exact - 1)) for N in (64, 256))
    assert 13 < e64 / e256 < 20


def test_pure_cubic_and_exponential_converge_faster():
    """Pure cubic (k_l = 0): F is C² where contact opens (F''' jumps), error N⁻⁴ (×16 per
    doubling; 2.3e-7 at N = 64).  Exponential law F_s e^{λΔ}: analytic, k = F_s λ(2I₁(λA)/(λA) − 1)
    (Bessel); the aliased tail I_{N±1}(λA) is below round-off at N = 64 for λA ≤ 10."""
    A = np.geomspace(1.001, 10.0, 200) * D0
    cubic = UnilateralLaw(k_l=0.0, k_nl=K_NL)
    ex = cubic_remainder_stiffness(0.0, K_NL, D0, A)
    e = [np.max(np.abs(_k(cubic, D0, A, N) / ex - 1)) for N in (DEFAULT_N, 2 * DEFAULT_N)]
    assert e[0] < 5e-7 and 12 < e[0] / e[1] < 20

    law = exponential_like(1e7, 100.0)

    class Remainder:       # ExponentialLaw has no remainder(): MASA takes UnilateralLaw only
        def remainder(self, d_static, dd, v):
            x = law.lam * dd
            return law.force(d_static) * (np.expm1(x) - x)

    from scipy.special import ive
    x = np.array([0.1, 1.0, 3.0, 10.0])
    ref = 100.0 * law.lam * (2 * ive(1, x) * np.exp(x) / x - 1)
    k = _k(Remainder(), 0.0, x / law.lam, DEFAULT_N)
    assert k == pytest.approx(ref, rel=1e-10)
    assert abs(_k(Remainder(), 0.0, x[-1:] / law.lam, 16)[0] / ref[-1] - 1) > 1e-6   # too few samples
