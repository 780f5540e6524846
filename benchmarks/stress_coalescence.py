"""Stress test: eigenvalues near an exceptional point (mode-coupling onset), where flutter starts.

The Hoffmann two-DOF model of :mod:`fem_squeal.reduced.two_dof` has the linearised stiffness

    K(μ) = [[k₁₁, k₁₂ + μk_t], [k₁₂, k₂₂ + k_t]],   θ = −λ² its eigenvalues,

whose discriminant is linear in μ: (k₁₁ − k₂₂ − k_t)² + 4k₁₂(k₁₂ + μk_t) = 4k₁₂k_t(μ − μ_c).  So
past μ_c, with δ = μ − μ_c given exactly, θ = tr/2 ± √(k₁₂k_t δ) (k₁₂ < 0: complex for δ > 0)
and Re λ = ∓Im√θ are known to round-off for any δ: an independent reference however close to
the exceptional point.  The pair is embedded in an m = 200 reduced model (an orthogonal
similarity with 198 well-separated modes), the size of a brake basis, and solved as the sweeps
solve it (:func:`quadratic_eigs`).

Tables: (1) for δ/μ_c = 1e-1 … 1e-14 on both sides of μ_c: the computed Re λ against the exact
one, the eigenvalue condition number κ(λ) from the left and right eigenvectors
(:func:`condition_numbers`), and whether the stability flag (:func:`unstable`, growth_tol 1e-6) is
right; (2) the tracker (:func:`track`) over μ ∈ [0, 0.6] on a coarse grid: the refined μ_c
against the exact one, its kind (coalescence), solves and ambiguous steps.

    .venv/bin/python benchmarks/stress_coalescence.py [--quick]

Reading: κ grows as δ^(−1/2) (the signature of a defective double eigenvalue) and the error of λ
stays below κ·ε·|λ| (backward stability), so Re λ ∝ √δ loses relative accuracy as 1/δ.  On this
model Re λ is right to 2e-5 down to δ = 1e-8 μ_c; below δ ≈ 1e-9 μ_c the growth rate is under
growth_tol·|λ| (ζ < 1e-6), and the flag says stable, as it does for the exact eigenvalues.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

K11, K22, K12, KT = 4.2e7, 3.0e7, -2.0e6, 1.0e7
MU_C = -((K11 - K22 - KT) ** 2 / (4 * K12) + K12) / KT      # 0.25


def embedded(m: int = 200, seed: int = 0):
    """μ -> K(μ) of size m: the two-DOF pair and m − 2 modes at 2–20 kHz, rotated by a random
    orthogonal Q (the spectrum and the exceptional point are those of the blocks)."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    others = (2 * np.pi * np.linspace(2000.0, 20000.0, m - 2)) ** 2

    def K(mu: float) -> np.ndarray:
        B = np.zeros((m, m))
        B[:2, :2] = [[K11, K12 + mu * KT], [K12, K22 + KT]]
        B[2:, 2:] = np.diag(others)
        return Q @ B @ Q.T

    return K


def exact_pair(delta: float) -> np.ndarray:
    """The two λ (Im λ > 0) of the pair at μ = μ_c + δ, computed without cancellation."""
    tr = K11 + K22 + KT
    s = np.sqrt(complex(K12 * KT * delta))         # √disc/2 = √(k₁₂k_t δ), δ given exactly (k₁₂ < 0)
    theta = np.array([tr / 2 + s, tr / 2 - s])
    lam = 1j * np.sqrt(theta)
    return np.where(lam.imag < 0, -lam, lam)


def coalescence_table(m: int, exps: list[int]) -> list[dict]:
    from fem_squeal.reduced.eigensolve import condition_numbers, quadratic_eigs, unstable

    K = embedded(m)
    rows = []
    for side in (+1, -1):
        for e in exps:
            delta = side * MU_C * 10.0 ** (-e)
            Km = K(MU_C + delta)
            lam = quadratic_eigs(Km)
            ex = exact_pair(delta)
            j = np.argsort(np.abs(lam.imag - ex[0].imag))[:2]          # the pair: nearest in frequency
            pair = lam[j]
            re_num, re_ex = float(np.max(pair.real)), float(np.max(ex.real))
            lam_k, kap = condition_numbers(Km)
            jk = np.argsort(np.abs(lam_k.imag - ex[0].imag))[:2]
            flag = bool(unstable(pair).any())
            expected = bool(unstable(ex).any())     # the flag the exact eigenvalues get (growth_tol 1e-6)
            rows.append({"side": side, "rel_delta": side * 10.0 ** (-e), "re_exact": re_ex, "re_computed": re_num,
                         "abs_error": abs(re_num - re_ex),
                         "rel_error": abs(re_num - re_ex) / abs(re_ex) if re_ex else None,
                         "freq_error": float(np.max(np.abs(np.sort(pair.imag) - np.sort(ex.imag))) / ex[0].imag),
                         "kappa": float(np.max(kap[jk])), "flag_unstable": flag, "flag_expected": expected,
                         "flag_right": flag == expected, "abs_lambda": float(abs(ex[0]))})
    return rows


def tracker_row(m: int, n_grid: int) -> dict:
    from fem_squeal.reduced.eigensolve import quadratic_eigs
    from fem_squeal.reduced.tracking import track

    K = embedded(m)
    t = time.perf_counter()
    tr = track(lambda mu: quadratic_eigs(K(mu), vectors=True), np.linspace(0.0, 0.6, n_grid))
    dt = time.perf_counter() - t
    ev = [e for e in tr.events if e.kind == "coalescence"]
    return {"grid": n_grid, "m": m, "events": len(tr.events), "coalescences": len(ev),
            "mu_c": ev[0].value if ev else None, "mu_c_error": abs(ev[0].value - MU_C) / MU_C if ev else None,
            "solves": tr.solves, "ambiguous_steps": tr.ambiguous_steps, "seconds": dt,
            "freq_hz": ev[0].freq_hz if ev else None}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="m = 40, fewer distances")
    ap.add_argument("--ranks", type=int, default=1, help="recorded only: the reduced solves are serial")
    a = ap.parse_args()
    m = 40 if a.quick else 200
    exps = [1, 4, 8, 12] if a.quick else list(range(1, 15))
    rows = coalescence_table(m, exps)
    trk = [tracker_row(m, n) for n in ((7,) if a.quick else (7, 13, 61))]
    lines = [f"Two-DOF mode coupling (seed 000 model) embedded in m = {m}; μ_c = {MU_C:g} exactly; "
             "δ = μ − μ_c. Re λ exact from the discriminant 4k₁₂k_t δ (no cancellation).", "",
             "| δ/μ_c | exact Re λ [1/s] | computed Re λ | rel. error | freq. error | κ(λ) | flagged unstable | "
             "exact flag (growth_tol 1e-6) |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        rel = f"{r['rel_error']:.1e}" if r["rel_error"] is not None else "–"
        lines.append(f"| {r['rel_delta']:+.0e} | {r['re_exact']:.4g} | {r['re_computed']:.4g} | {rel} | "
                     f"{r['freq_error']:.1e} | {r['kappa']:.2e} | {r['flag_unstable']} | {r['flag_expected']} |")
    lines += ["", "Tracker over μ ∈ [0, 0.6] (MAC continuation with bisection; critical point refined to 1e-10 "
              "of the range):", "", "| grid points | events | coalescences | μ_c found | rel. error | f [Hz] | "
              "solves | ambiguous steps | time [s] |", "|---|---|---|---|---|---|---|---|---|"]
    for t in trk:
        mu = f"{t['mu_c']:.10f}" if t["mu_c"] is not None else "–"
        err = f"{t['mu_c_error']:.1e}" if t["mu_c_error"] is not None else "–"
        f = f"{t['freq_hz']:.1f}" if t["freq_hz"] is not None else "–"
        lines.append(f"| {t['grid']} | {t['events']} | {t['coalescences']} | {mu} | {err} | {f} | {t['solves']} | "
                     f"{t['ambiguous_steps']} | {t['seconds']:.2f} |")
    casework.save("stress_coalescence", lines, {"points": rows, "tracker": trk}, a.ranks, a.quick)
    from fem_squeal.app.plots import pyplot

    plt = pyplot()

    up = [r for r in rows if r["side"] > 0]
    d = [r["rel_delta"] for r in up]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].loglog(d, [r["kappa"] for r in up], "o-", label="κ(λ)")
    ax[0].loglog(d, up[0]["kappa"] * (np.array(d) / d[0]) ** -0.5, "k--", label="∝ δ^-1/2")
    ax[0].set_xlabel("(μ − μ_c)/μ_c")
    ax[0].legend()
    ax[1].loglog(d, [max(r["rel_error"] or 0.0, 1e-17) for r in up], "o-", label="rel. error of Re λ")
    ax[1].set_xlabel("(μ − μ_c)/μ_c")
    ax[1].legend()
    fig.tight_layout()
    casework.save_plot(fig, "stress_coalescence", a.ranks, a.quick)


if __name__ == "__main__":
    main()
