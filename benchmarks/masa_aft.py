"""MASA: AFT samples per period N against the error of the equivalent stiffness k (K₁, seed 000
eq. 18), and the cost of a MASA amplitude sweep against N, the contact elements and the basis.

    .venv/bin/python benchmarks/masa_aft.py [--quick] [--ranks N]

Serial NumPy/SciPy (the reduced layer); ``--ranks`` is only recorded in the output name (no MPI).
Set OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 for one-core timings.

1. AFT accuracy, one element, k of :func:`fem_squeal.reduced.aft.first_harmonic` against a
   reference, max relative error over a spread of amplitudes A, for N = 4 … 1024:
   (a) cubic law without contact loss (A < δ₀): reference ¾k_nl A² (exact; the remainder is a
       trigonometric polynomial of degree 3, so N ≥ 5 samples are exact: the only harmonic of r
       that can alias onto the first is the third, 3 ≡ −1 (mod 4) at N = 4 only);
   (b) cubic law k_l + k_nl δ³ (tune_cubic, 30 % cubic) with loss (A > δ₀): reference
       :func:`~fem_squeal.reduced.aft.cubic_remainder_stiffness`; the force has a slope jump k_l
       at contact loss, so the trapezoidal sum converges as N⁻² with the Euler–Maclaurin bound
       |Δk| ≤ (2π/3N²) k_l |sin θ* cos θ*|, θ* = arccos(−δ₀/A) (sharp: the worst amplitude
       reaches it);
   (c) pure cubic law (k_l = 0) with loss: F ∈ C² at contact loss (F''' jumps), N⁻⁴;
   (d) exponential law F = F_s e^{λΔ} (seed 002 eq. 2; ExponentialLaw has no ``remainder`` method
       — MASA takes UnilateralLaw only — so a 3-line adapter is used), reference the Bessel closed
       form k = F_s λ (2I₁(λA)/(λA) − 1); analytic integrand: the error is the aliased Bessel
       tail I_{N±1}(λA), super-geometric once N > λA.
   Time per element evaluation (vectorised over 4096 elements).
2. Cost of a MASA sweep (one instability × 50 amplitudes 0 … 5 p_loss, no sweep break, 10
   bisections of the stationary amplitude) on a synthetic reduced model (diagonal modal K of m
   modes in 0.8–12 kHz, n elements with random closure/slip rows, μ = 0.4, cubic law tuned to a
   3 kHz tangent at unit preload), split into AFT (first_harmonic), dense eigensolve
   (quadratic_eigs) and the rest (K₁ = BᵀkD, status), against N, n and m.
3. Effect of N on the MASA outcome on that model (m = 100, n = 200): stationary amplitudes p*
   (30 bisections) of every instability with exactly one p* in 0 … 4 p_loss, and Re λ of the
   tracked eigenvalue at p = 2 p_loss, against N = 8192 as reference.

Timings: min over repeats; the machine may be shared (noted in the output header).
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

from fem_squeal.reduced import masa as masa_mod  # noqa: E402
from fem_squeal.reduced.aft import cubic_remainder_stiffness, first_harmonic  # noqa: E402
from fem_squeal.reduced.laws.contact import ExponentialLaw, UnilateralLaw, exponential_like, tune_cubic  # noqa: E402

OMEGA = 2 * np.pi * 3000.0
DEFAULT_N = 64          # MasaProblem / first_harmonic / scene analyses.masa.n_samples default


# ------------------------------------------------------------------ 1. AFT accuracy
def cubic_law(k_l_on: bool = True):
    k_l, k_nl, d0 = tune_cubic(1e7, 100.0, 0.3)
    return UnilateralLaw(k_l=float(k_l) if k_l_on else 0.0, k_nl=float(k_nl)), float(d0)


@dataclass(frozen=True)
class ExponentialRemainder:
    """The AFT remainder F(δ_s + Δ) − F(δ_s) − F'(δ_s)Δ = F_s(e^{λΔ} − 1 − λΔ) of an ExponentialLaw."""

    law: ExponentialLaw

    def remainder(self, d_static, dd, v):
        x = np.asarray(self.law.lam) * dd
        return self.law.force(d_static) * (np.expm1(x) - x)


def exp_reference(Fs: float, lam: float, x: np.ndarray) -> np.ndarray:
    """k = F_s λ (2I₁(x)/x − 1), x = λA, as the positive series Σ_{k≥1} (x/2)^{2k}/(k!(k+1)!)."""
    from scipy.special import gammaln

    k = np.arange(1, 200)[:, None]
    terms = np.exp(2 * k * np.log(x / 2) - gammaln(k + 1) - gammaln(k + 2))
    return Fs * lam * terms.sum(axis=0)


def k_aft(law, d0: float, A: np.ndarray, N: int, phase: float = 0.7) -> np.ndarray:
    n = len(A)
    return first_harmonic(law, np.full(n, d0), A * np.cos(phase), A * np.sin(phase), OMEGA, N).k


def aft_cases():
    law, d0 = cubic_law()
    law3, _ = cubic_law(False)
    exp = exponential_like(1e7, 100.0)
    a_noloss = np.linspace(0.02, 0.99, 60) * d0
    a_loss = np.geomspace(1.001, 10.0, 400) * d0
    x_exp = np.geomspace(0.1, 10.0, 100)
    th = np.arccos(-d0 / a_loss)
    return {
        "a": (law, d0, a_noloss, 0.75 * float(law.k_nl) * a_noloss ** 2),
        "b": (law, d0, a_loss, cubic_remainder_stiffness(law.k_l, law.k_nl, d0, a_loss)),
        "c": (law3, d0, a_loss, cubic_remainder_stiffness(0.0, law3.k_nl, d0, a_loss)),
        "d": (ExponentialRemainder(exp), 0.0, x_exp / float(exp.lam),
              exp_reference(float(exp.p0 * exp.weight), float(exp.lam), x_exp)),
        "bound_b": lambda N: 2 * np.pi / (3 * N ** 2) * float(law.k_l) * np.abs(np.sin(th) * np.cos(th)),
        "law": law, "d0": d0, "exp": exp,
    }


def time_per_element(law, d0: float, N: int, n_el: int = 4096, reps: int = 5) -> float:
    rng = np.random.default_rng(0)
    A = rng.uniform(0.1, 5.0, n_el) * d0
    ph = rng.uniform(0, 2 * np.pi, n_el)
    d = np.full(n_el, d0)
    best = np.inf
    for _ in range(reps):
        t = time.perf_counter()
        first_harmonic(law, d, A * np.cos(ph), A * np.sin(ph), OMEGA, N)
        best = min(best, time.perf_counter() - t)
    return best / n_el


def slope(N, e) -> float:
    return float(np.polyfit(np.log(N), np.log(e), 1)[0])


def aft_accuracy(quick: bool):
    Ns = [4, 5, 8, 16, 64, 256] if quick else [4, 5, 6, 8, 16, 32, 64, 128, 256, 512, 1024]
    cs = aft_cases()
    rows = []
    for N in Ns:
        row = {"N": N}
        for key in "abcd":
            law, d0, A, ref = cs[key]
            err = np.abs(k_aft(law, d0, A, N) - ref) / np.abs(ref)
            row[f"err_{key}"] = float(err.max())
            if key == "b":
                row["worst_A_over_d0_b"] = float(A[np.argmax(err)] / d0)
                e_abs = np.abs(k_aft(law, d0, A, N) - ref)
                row["err_over_bound_b"] = float(np.max(e_abs / cs["bound_b"](N)))
        row["us_per_element_cubic"] = 1e6 * time_per_element(cs["law"], cs["d0"], N, reps=2 if quick else 5)
        row["us_per_element_exp"] = 1e6 * time_per_element(ExponentialRemainder(cs["exp"]), 0.0, N,
                                                          reps=2 if quick else 5)
        rows.append(row)
    # smallest N reaching 1e-8 on the exponential law, per λA
    law_e = ExponentialRemainder(cs["exp"])
    lam = float(cs["exp"].lam)
    need = {}
    for x in (1.0, 2.0, 5.0, 10.0, 20.0):
        ref = exp_reference(float(cs["exp"].p0 * cs["exp"].weight), lam, np.array([x]))
        need[x] = next((N for N in range(5, 200)
                        if abs(k_aft(law_e, 0.0, np.array([x / lam]), N)[0] / ref[0] - 1) < 1e-8), None)
    # the closed form's own round-off without loss (difference of O(k_t) terms for ¾k_nl A²)
    law, d0, A, ref = cs["a"]
    cf_err = float(np.max(np.abs(cubic_remainder_stiffness(law.k_l, law.k_nl, d0, A) / ref - 1)))
    return rows, need, cf_err


# ------------------------------------------------------------------ 2./3. MASA sweeps
def synthetic(m: int, n: int, mu: float = 0.4, seed: int = 0) -> masa_mod.MasaModel:
    """Modal K (m modes, 0.8–12 kHz ± 2 %), n elements with random rows, equilibrium at q = 0."""
    rng = np.random.default_rng(seed)
    w = 2 * np.pi * np.sort(np.linspace(800.0, 12000.0, m) * (1 + 0.02 * rng.normal(size=m)))
    D = rng.normal(size=(n, m)) / np.sqrt(n)
    T = rng.normal(size=(n, m)) / np.sqrt(n)
    F0 = np.ones(n)
    k_l, k_nl, ds = tune_cubic(np.full(n, OMEGA ** 2), F0, 0.3)
    cs = masa_mod.ContactSet(D=D, T=T, d0=ds, law=UnilateralLaw(k_l=k_l, k_nl=k_nl), mu=mu, name="pad")
    return masa_mod.MasaModel(K=np.diag(w ** 2), contacts=[cs], f=cs.B.T @ F0)


class Timers:
    """Wraps masa.first_harmonic and masa.quadratic_eigs (as MASA calls them) with wall clocks."""

    def __init__(self):
        self.t = {"aft": 0.0, "eig": 0.0}
        self._orig = (masa_mod.first_harmonic, masa_mod.quadratic_eigs)

    def _wrap(self, key, fn):
        def inner(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.t[key] += time.perf_counter() - t
        return inner

    def __enter__(self):
        masa_mod.first_harmonic = self._wrap("aft", self._orig[0])
        masa_mod.quadratic_eigs = self._wrap("eig", self._orig[1])
        return self

    def __exit__(self, *exc):
        masa_mod.first_harmonic, masa_mod.quadratic_eigs = self._orig


def sweep_cost(m: int, n: int, N: int, reps: int) -> dict:
    mm = synthetic(m, n)
    eq = masa_mod.static_equilibrium(mm)
    prob = masa_mod.MasaProblem(mm, eq, (0.0, 20000.0), n_samples=N)
    inst = prob.instabilities()
    t = max(inst, key=lambda i: i.lam.real)
    amps = np.linspace(0.0, 5.0 * prob.loss_amplitude(t), 50)
    best = None
    for _ in range(reps):
        with Timers() as tm:
            t0 = time.perf_counter()
            r = masa_mod.run_masa(prob, [t], amps, sweep_break=False, refine=10)[0]
            total = time.perf_counter() - t0
        if best is None or total < best["seconds"]:
            best = {"m": m, "n": n, "N": N, "states": r.steps, "seconds": total, "aft_s": tm.t["aft"],
                    "eig_s": tm.t["eig"], "instabilities": len(inst)}
    return best


def outcome(Ns, N_ref: int = 8192, m: int = 100, n: int = 200) -> tuple[list[dict], dict]:
    """Stationary amplitudes and tracked eigenvalues over 0 … 4 p_loss (41 steps) against N."""
    mm = synthetic(m, n)
    eq = masa_mod.static_equilibrium(mm)

    def run(N, targets=None):
        prob = masa_mod.MasaProblem(mm, eq, (0.0, 20000.0), n_samples=N)
        inst = prob.instabilities() if targets is None else targets
        out = []
        for t in inst:
            pl = prob.loss_amplitude(t)
            r = masa_mod.run_masa(prob, [t], np.linspace(0.0, 4.0 * pl, 41), sweep_break=False, refine=30)[0]
            out.append((t, pl, r.stationary, r.tracked))
        return out

    ref = [o for o in run(N_ref) if len(o[2]) == 1]
    targets = [o[0] for o in ref]
    rows = []
    for N in Ns:
        res = run(N, targets)
        e_st, e_re, e_lam = [], [], []
        for (t, _, st, tr), (_, _, st_ref, tr_ref) in zip(res, ref):
            e_st.append(abs(st[0] / st_ref[0] - 1) if len(st) == 1 else np.inf)
            e_re.append(np.max(np.abs(tr.real - tr_ref.real)) / t.lam.real)
            e_lam.append(np.max(np.abs(tr - tr_ref)) / t.lam.real)
        rows.append({"N": N, "max_rel_err_stationary": float(max(e_st)),
                     "max_err_re_over_re0": float(max(e_re)), "max_err_lambda_over_re0": float(max(e_lam))})
    info = {"N_ref": N_ref, "with_one_stationary": len(ref), "freq_hz": [t.freq_hz for t in targets],
            "stationary_over_ploss": [float(st[0] / pl) for _, pl, st, _ in ref]}
    return rows, info


# ------------------------------------------------------------------ main
def plot(acc, cost_N, ranks, quick):
    from fem_squeal.app.plots import pyplot

    plt = pyplot()

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    N = np.array([r["N"] for r in acc], float)
    labels = {"a": "(a) cubic, no loss (vs ¾k_nl A²)", "b": "(b) k_l + cubic, contact loss",
              "c": "(c) pure cubic, contact loss", "d": "(d) exponential, λA ≤ 10"}
    for key, lab in labels.items():
        e = np.maximum([r[f"err_{key}"] for r in acc], 1e-17)
        ax.loglog(N, e, "o-", label=lab)
    ax.loglog(N[N >= 8], 9.0 * N[N >= 8] ** -2.0, "k--", lw=0.8, label="9 N⁻²")
    ax.loglog(N[N >= 8], 4.0 * N[N >= 8] ** -4.0, "k:", lw=0.8, label="4 N⁻⁴")
    ax.axvline(DEFAULT_N, color="grey", lw=0.6)
    ax.set_xlabel("AFT samples per period N")
    ax.set_ylabel("max relative error of k (eq. 18)")
    ax.set_ylim(1e-17, 3)
    ax.legend(fontsize=7)
    Nc = np.array([r["N"] for r in cost_N], float)
    ms = lambda key: np.array([1e3 * r[key] / r["states"] for r in cost_N])  # noqa: E731
    bx.loglog(Nc, ms("seconds"), "o-", label="total per state")
    bx.loglog(Nc, ms("aft_s"), "s-", label="AFT")
    bx.loglog(Nc, ms("eig_s"), "^-", label="dense eigensolve")
    r0 = cost_N[0]
    bx.set_title(f"MASA sweep, m = {r0['m']}, {r0['n']} elements", fontsize=9)
    bx.set_xlabel("AFT samples per period N")
    bx.set_ylabel("ms per state matrix")
    bx.axvline(DEFAULT_N, color="grey", lw=0.6)
    bx.legend(fontsize=7)
    fig.tight_layout()
    casework.save_plot(fig, "masa_aft", ranks, quick)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ranks", type=int, default=1, help="recorded only (serial computation)")
    ap.add_argument("--quick", action="store_true", help="few N, small sweeps (smoke, a few seconds)")
    a = ap.parse_args()
    q = a.quick
    import os
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    lines = [f"MASA AFT benchmark{' (quick)' if q else ''}: serial (--ranks {a.ranks} recorded only), "
             f"OPENBLAS_NUM_THREADS={threads}; times are the min over repeats on a possibly shared machine.", ""]

    acc, need, cf_err = aft_accuracy(q)
    big = [r for r in acc if r["N"] >= 16]
    rate_b = slope([r["N"] for r in big], [r["err_b"] for r in big])
    rate_c = slope([r["N"] for r in big], [r["err_c"] for r in big])
    lines += ["## 1. AFT error of k (eq. 18) against N, max relative error over the amplitudes", "",
              "(a) cubic law, A/δ₀ ∈ [0.02, 0.99] (60), ref ¾k_nl A²; (b) k_l + k_nl δ³ (30 % cubic), "
              "A/δ₀ ∈ [1.001, 10] (400), ref closed form; (c) pure cubic, same A; (d) exponential law, "
              "λA ∈ [0.1, 10] (100), ref Bessel closed form.  Phase 0.7 rad.", "",
              "| N | (a) no loss | (b) loss, k_l > 0 | (b) err / E–M bound | (c) loss, pure cubic | "
              "(d) exponential | µs/element (cubic) | µs/element (exp.) |",
              "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in acc:
        lines.append(f"| {r['N']} | {r['err_a']:.1e} | {r['err_b']:.1e} | {r['err_over_bound_b']:.3f} | "
                     f"{r['err_c']:.1e} | {r['err_d']:.1e} | {r['us_per_element_cubic']:.3f} | "
                     f"{r['us_per_element_exp']:.3f} |")
    lines += ["", f"Fitted rates over N ≥ 16: (b) N^{rate_b:.2f}, (c) N^{rate_c:.2f}.  "
              f"Smallest N with (d) error < 1e-8: " + ", ".join(f"λA = {x:g}: {v}" for x, v in need.items())
              + f".  Closed form's own round-off without loss (vs ¾k_nl A²): {cf_err:.1e}.", ""]

    Ns_cost = [8, 16, 32, 64, 128, 256] if q else [8, 16, 32, 64, 128, 256, 512, 1024, 4096]
    reps = 1 if q else 3
    m0, n0 = (50, 100) if q else (100, 200)
    cost_N = [sweep_cost(m0, n0, N, reps) for N in Ns_cost]
    cost_n = [sweep_cost(m0, n, DEFAULT_N, reps) for n in ((50, 200) if q else (50, 100, 200, 400, 800))]
    cost_m = [sweep_cost(m, n0, DEFAULT_N, reps) for m in ((50, 100) if q else (50, 100, 200, 300))]
    lines += ["## 2. Cost of one MASA sweep (1 instability × 50 amplitudes + 10 bisections, undamped, "
              "no break) on the synthetic model", "",
              "| varied | basis m | elements n | N | state matrices | sweep [s] | ms/state | AFT [%] | "
              "eigensolve [%] | rest (K₁ = BᵀkD, status) [%] |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for what, group in (("N", cost_N), ("n", cost_n), ("m", cost_m)):
        for r in group:
            s = r["seconds"]
            lines.append(f"| {what} | {r['m']} | {r['n']} | {r['N']} | {r['states']} | {s:.3f} | "
                         f"{1e3 * s / r['states']:.2f} | {100 * r['aft_s'] / s:.0f} | "
                         f"{100 * r['eig_s'] / s:.0f} | "
                         f"{100 * (s - r['aft_s'] - r['eig_s']) / s:.0f} |")

    Ns_out = [8, 16, 64, 256] if q else [8, 16, 32, 64, 128, 256, 512, 1024]
    out_rows, info = outcome(Ns_out, N_ref=1024 if q else 8192)
    lines += ["", f"## 3. Effect of N on the MASA outcome (m = 100, n = 200; reference N = {info['N_ref']})", "",
              f"Instabilities with one stationary amplitude p* in 0 … 4 p_loss: {info['with_one_stationary']} "
              f"(at {', '.join(f'{f:.0f}' for f in info['freq_hz'])} Hz; p*/p_loss = "
              f"{', '.join(f'{v:.3f}' for v in info['stationary_over_ploss'])}).  Errors: max over them, "
              "and over the 41 sweep amplitudes for the tracked eigenvalue λ(p), relative to its Re λ at p = 0.",
              "", "| N | rel. error of p* | error of Re λ(p) / Re λ₀ | error of λ(p) / Re λ₀ |",
              "|---:|---:|---:|---:|"]
    for r in out_rows:
        lines.append(f"| {r['N']} | {r['max_rel_err_stationary']:.1e} | {r['max_err_re_over_re0']:.1e} | "
                     f"{r['max_err_lambda_over_re0']:.1e} |")
    rows = {"aft": acc, "exp_N_for_1e-8": {str(k): v for k, v in need.items()}, "closed_form_roundoff": cf_err,
            "rate_b": rate_b, "rate_c": rate_c, "cost_N": cost_N, "cost_n": cost_n, "cost_m": cost_m,
            "outcome": out_rows, "outcome_info": info, "default_N": DEFAULT_N, "quick": q}
    casework.save("masa_aft", lines, [rows], a.ranks, q)
    plot(acc, cost_N, a.ranks, q)


if __name__ == "__main__":
    main()
