"""Robustness of the stability to scattered parameters: Monte Carlo on the reduced model.

**Samples.**  Each parameter (any of the reduced model's: ``"mu"``, ``"E.<part>"``, ``"kn.<interface>"``, …)
has a distribution (:class:`Distribution`:
uniform [lower, upper], normal (mean, std), lognormal (mean, std of the variable itself, i.e.
ln p ~ N(m, s²) with s² = ln(1 + (std/mean)²), m = ln(mean) − s²/2)); std = 0 or lower = upper
is a degenerate distribution (the value itself).  All N samples are drawn by
``numpy.random.default_rng(seed)``, one parameter after the other in the order given, on every
rank identically, before the points are dealt round-robin to the ranks (as
:func:`fem_squeal.reduced.sweep.evaluate`): each sample is solved by the same arithmetic whatever
the rank count, so the results are rank-independent.

**Probabilities.**  For an indicator u (at least one unstable mode, Re λ > growth_tol|λ|, in a
frequency band), p̂ = mean(u) with the standard error √(p̂(1 − p̂)/N) (it falls as N^(−1/2)) and
the 95 % Wilson score interval (meaningful also when p̂ = 0 or 1, where the standard error is 0).

**Mode families.**  A family is one mode of the nominal model in the band (its eigenvalue λ⁰ⱼ).
In every sample the in-band eigenvalues are assigned to the families by the Hungarian assignment
that minimises Σ |λ − λ⁰ⱼ|/|λ⁰ⱼ| (nearest nominal eigenvalue; no eigenvectors, which keeps 10⁴
samples of a 250-vector model within two minutes: a vector solve costs as much again and a MAC
assignment more).  Each family so has a growth rate Re λ in *every* sample (stable ones included:
its distribution) and an instability probability.  Limits: a crossing of two families of nearly
equal frequency inside the scatter may exchange their labels (it does not change the per-band
probabilities); a flutter pair (λ = ±σ + iω) keeps its unstable member in the family of the
nominal unstable one when the pair is unstable at nominal; a pair that is stable at nominal and
couples in some samples appears as the family of whichever parent lies closer.

**Drivers.**  Spearman's rank correlation ρ of each parameter with the largest growth rate over
the band and with each family's growth rate, with the 95 % interval of the Fisher transform
z = atanh ρ ± 1.96·√(1.06/(N − 3)) (Fieller, Hartley & Pearson 1957 for the Spearman variance).
Beside them the first-order Sobol' index S_i = Var(E[Y | X_i])/Var(Y) of each parameter for the
largest growth rate, from the same samples (no further solves: the "given data" estimator, Plischke
2010): the samples sorted by X_i fall into M = round(√N/2) bins of equal count, S_i is the variance
of the bin means of Y over Var(Y), less its bias (M − 1)/(N − 1) for an unrelated X_i (then
clipped to [0, 1]); the 95 % interval is the percentile interval of 200 bootstrap resamples.  An
additive model Y = Σ aᵢXᵢ has Sᵢ = aᵢ²Var Xᵢ / Σ aⱼ²Var Xⱼ (tests/unit/reduced/test_robustness.py); ρ ranks
monotone drivers, S_i also catches non-monotone ones (e.g. a growth rate peaking at mid μ).
"""
from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from fem_squeal.reduced.eigensolve import TWO_PI, unstable
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.errors import ModelError

KINDS = ("uniform", "normal", "lognormal")
Z95 = 1.959963984540054


@dataclass(frozen=True)
class Distribution:
    """A parameter's distribution; ``a, b`` are (lower, upper) for uniform, (mean, std) otherwise."""

    kind: str
    a: float
    b: float

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ModelError(f"distribution: must be one of {list(KINDS)} (got {self.kind!r})")
        if not (np.isfinite(self.a) and np.isfinite(self.b)):
            raise ModelError(f"distribution: parameters must be finite (got {self.a}, {self.b})")
        if self.kind == "uniform" and self.a > self.b:
            raise ModelError(f"lower: must be <= upper (got lower {self.a} > upper {self.b})")
        if self.kind != "uniform" and self.b < 0:
            raise ModelError(f"std: must be >= 0 (got {self.b})")
        if self.kind == "lognormal" and not self.a > 0:
            raise ModelError(f"mean: must be > 0 for a lognormal distribution (got {self.a})")

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.kind == "uniform":
            return rng.uniform(self.a, self.b, n) if self.b > self.a else np.full(n, self.a)
        if self.kind == "normal":
            return rng.normal(self.a, self.b, n) if self.b > 0 else np.full(n, self.a)
        s2 = np.log1p((self.b / self.a) ** 2)
        return rng.lognormal(np.log(self.a) - s2 / 2, np.sqrt(s2), n) if self.b > 0 else np.full(n, self.a)

    def stays_positive(self) -> bool:
        """Every sample > 0: a uniform with lower > 0, a lognormal, a normal with mean > 8 std
        (P(≤ 0) < 1e-15) or a degenerate one with a positive value."""
        if self.kind == "uniform":
            return self.a > 0
        return self.kind == "lognormal" or self.a > 8 * self.b

    def stays_non_negative(self) -> bool:
        """Every sample >= 0: a uniform with lower >= 0, a lognormal, a normal with mean > 8 std or
        a degenerate one with a value >= 0."""
        if self.kind == "uniform":
            return self.a >= 0
        return self.kind == "lognormal" or self.a > 8 * self.b or (self.b == 0 and self.a >= 0)

    def as_dict(self) -> dict:
        keys = ("lower", "upper") if self.kind == "uniform" else ("mean", "std")
        return {"distribution": self.kind, keys[0]: self.a, keys[1]: self.b}


def draw(distributions: Mapping[str, Distribution], n: int, seed: int) -> dict[str, np.ndarray]:
    """``n`` samples of every parameter from one generator ``default_rng(seed)``, parameters in
    the order given (the same on every rank)."""
    if n < 1:
        raise ModelError(f"n_samples: must be >= 1 (got {n})")
    rng = np.random.default_rng(seed)
    return {name: d.sample(rng, n) for name, d in distributions.items()}


@dataclass
class Probability:
    p: float
    stderr: float
    lo95: float
    hi95: float
    n: int

    @classmethod
    def of(cls, hits: np.ndarray) -> Probability:
        hits = np.asarray(hits, bool)
        n = hits.size
        p = float(hits.mean()) if n else 0.0
        se = float(np.sqrt(p * (1 - p) / n)) if n else 0.0
        z2 = Z95 ** 2
        c = (p + z2 / (2 * n)) / (1 + z2 / n)
        h = Z95 * np.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
        return cls(p, se, float(max(c - h, 0.0)), float(min(c + h, 1.0)), n)

    def as_dict(self) -> dict:
        return {"p": self.p, "stderr": self.stderr, "ci95": [self.lo95, self.hi95], "n": self.n}


def spearman(x: np.ndarray, y: np.ndarray) -> dict:
    """Spearman's ρ with its Fisher-z 95 % interval (ρ = 0 and a full interval for a constant input)."""
    n = len(x)
    if n < 4 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return {"rho": 0.0, "ci95": [-1.0, 1.0], "constant": True}
    from scipy.stats import rankdata  # heavy: scipy.stats (0.25 s import; the drivers only)

    rx, ry = rankdata(x), rankdata(y)
    rho = float(np.corrcoef(rx, ry)[0, 1])
    z, h = np.arctanh(np.clip(rho, -0.999999, 0.999999)), Z95 * np.sqrt(1.06 / (n - 3))
    # |ρ| = 1 (a monotone driver) is clipped for arctanh: keep the interval around the estimate itself
    lo, hi = min(float(np.tanh(z - h)), rho), max(float(np.tanh(z + h)), rho)
    return {"rho": rho, "ci95": [lo, hi], "constant": False}


def sobol_first_order(x: np.ndarray, y: np.ndarray, bins: int | None = None, n_boot: int = 200,
                      seed: int = 0) -> dict:
    """First-order Sobol' index of input ``x`` for output ``y`` from given samples (module docstring):
    {"S1", "ci95", "bins", "constant"}."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    n = len(x)
    if n < 8 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return {"S1": 0.0, "ci95": [0.0, 1.0], "bins": 0, "constant": True}
    m = int(bins) if bins else max(2, int(round(np.sqrt(n) / 2)))
    if not 2 <= m <= n // 2:
        raise ModelError(f"bins: must be in 2..{n // 2} for {n} samples (got {m})")

    edges = (np.arange(m) * n) // m
    counts = np.diff(np.append(edges, n))

    def estimate(xs, ys):
        means = np.add.reduceat(ys[np.argsort(xs, kind="stable")], edges) / counts
        mean, var = ys.mean(), ys.var()
        between = float(np.sum(counts * (means - mean) ** 2)) / n
        bias = (m - 1) / (n - 1)
        return float(np.clip((between / var - bias) / (1 - bias), 0.0, 1.0)) if var > 0 else 0.0

    s1 = estimate(x, y)
    rng = np.random.default_rng(seed)
    boot = [estimate(x[i], y[i]) for i in (rng.integers(0, n, n) for _ in range(n_boot))]
    lo, hi = np.quantile(boot, [0.025, 0.975])
    return {"S1": s1, "ci95": [float(min(lo, s1)), float(max(hi, s1))], "bins": m, "constant": False}


def assign_families(lam: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """For each sample row of ``lam`` (n, m), the eigenvalue assigned to each nominal family
    (n, n_fam): Hungarian assignment minimising Σ|λ − λ⁰|/|λ⁰|."""
    n = lam.shape[0]
    out = np.empty((n, nominal.size), complex)
    scale = np.maximum(np.abs(nominal), 1e-300)
    f0 = nominal.imag
    span = (f0.min(), f0.max()) if nominal.size else (0.0, 0.0)
    for k in range(n):
        row = lam[k]
        # candidates: the eigenvalues near the families' frequency range (a margin of 50 %)
        lo, hi = span[0] - 0.5 * abs(span[0]) - 1.0, span[1] + 0.5 * abs(span[1]) + 1.0
        cand = row[(row.imag >= lo) & (row.imag <= hi)]
        if cand.size < nominal.size:
            cand = row
        cost = np.abs(cand[None, :] - nominal[:, None]) / scale[:, None]
        r, c = linear_sum_assignment(cost)
        out[k, r] = cand[c]
    return out


@dataclass
class RobustnessResult:
    samples: dict[str, np.ndarray]
    max_growth: np.ndarray            # (N,) largest Re λ in the band (−inf if no mode in it)
    band_hits: np.ndarray             # (n_bands, N) at least one unstable mode in the band
    any_hit: np.ndarray               # (N,) at least one unstable mode in the whole band
    nominal: np.ndarray               # (n_fam,) nominal eigenvalues of the families
    family_lambda: np.ndarray         # (N, n_fam)
    family_hits: np.ndarray           # (N, n_fam)
    bands_hz: list[tuple[float, float]]
    seconds: float
    ranks: int
    growth_tol: float
    extra: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.any_hit.size

    def probability(self) -> Probability:
        return Probability.of(self.any_hit)

    def band_probabilities(self) -> list[Probability]:
        return [Probability.of(h) for h in self.band_hits]

    def family_probabilities(self) -> list[Probability]:
        return [Probability.of(h) for h in self.family_hits.T]

    def drivers(self, target: np.ndarray | None = None) -> dict[str, dict]:
        """Spearman ρ of each parameter with ``target`` (default: the largest growth rate)."""
        y = self.max_growth if target is None else target
        y = np.where(np.isfinite(y), y, np.nanmin(np.where(np.isfinite(y), y, np.nan)) if np.isfinite(y).any()
                     else 0.0)
        return {name: spearman(x, y) for name, x in self.samples.items()}

    def sobol(self, target: np.ndarray | None = None) -> dict[str, dict]:
        """First-order Sobol' index of each parameter for ``target`` (default: the largest growth rate)."""
        y = self.max_growth if target is None else target
        y = np.where(np.isfinite(y), y, np.nanmin(np.where(np.isfinite(y), y, np.nan)) if np.isfinite(y).any()
                     else 0.0)
        return {name: sobol_first_order(x, y) for name, x in self.samples.items()}


def run_robustness(model: ReducedModel, distributions: Mapping[str, Distribution], n: int, seed: int,
                   band_hz: tuple[float, float], bands_hz: Sequence[tuple[float, float]],
                   growth_tol: float = 1e-6, comm=None, chunk: int = 32, bar=None) -> RobustnessResult:
    """Draw ``n`` samples, solve the reduced model at each (dealt over the ranks of ``comm``),
    and evaluate the instability indicators per band and per family."""
    t = time.perf_counter()
    model._check(distributions)
    for name, d in distributions.items():
        if name.startswith("E.") and not d.stays_positive():
            raise ModelError(f"{name}: a Young's modulus must stay > 0; its {d.kind} distribution "
                             f"{d.as_dict()} does not (a normal needs mean > 8 std; or use a lognormal)")
    samples = draw(distributions, n, seed)
    nom = solve_points(model, {})[0]
    fn = nom.imag / TWO_PI
    nominal = nom[(fn >= band_hz[0]) & (fn <= band_hz[1])]
    size, rank = (1, 0) if comm is None else (comm.size, comm.rank)
    mine = np.arange(rank, n, size)
    lam = solve_points(model, {k: v[mine] for k, v in samples.items()}, chunk=chunk, bar=bar)
    f = lam.imag / TWO_PI
    bad = unstable(lam, growth_tol)
    inside = (f >= band_hz[0]) & (f <= band_hz[1])
    band_hits = []
    for i, (lo, hi) in enumerate(bands_hz):
        sel = (f >= lo) & ((f < hi) if i < len(bands_hz) - 1 else (f <= hi))
        band_hits.append(np.any(bad & sel, axis=1))
    part = (np.max(np.where(inside, lam.real, -np.inf), axis=1), np.array(band_hits).reshape(len(bands_hz), -1),
            np.any(bad & inside, axis=1), assign_families(lam, nominal))
    if comm is not None and size > 1:
        pieces = comm.allgather((mine, part))
        full = [np.empty((n,), float), np.empty((len(bands_hz), n), bool), np.empty((n,), bool),
                np.empty((n, nominal.size), complex)]
        for idx, vals in pieces:
            full[0][idx], full[1][:, idx], full[2][idx], full[3][idx] = vals
        part = tuple(full)
    max_growth, band_hits, any_hit, fam = part
    fam_hits = unstable(fam, growth_tol)
    seconds = time.perf_counter() - t
    if comm is not None and size > 1:
        from mpi4py import MPI  # heavy: MPI initialisation

        seconds = comm.allreduce(seconds, op=MPI.MAX)
    return RobustnessResult(samples, max_growth, band_hits, any_hit, nominal, fam, fam_hits,
                            [tuple(map(float, b)) for b in bands_hz], seconds, size, growth_tol)
