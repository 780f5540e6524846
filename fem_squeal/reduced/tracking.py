"""Mode tracking along a one-parameter path (a μ or E sweep) by MAC continuation.

Branches start at ``start`` (μ = 0: the frictionless parents, labelled M1, M2, … by frequency)
and are continued outwards in both directions.  A step p_a → p_b is accepted when

* the Hungarian assignment that maximises Σ MAC(y_ref, y_b) gives every branch a MAC ≥
  ``mac_min`` (MAC(a, b) = |aᴴb|² / (|a|²|b|²); the reduced basis is M-orthonormal, so this is
  the mass-weighted MAC of the lifted shapes; for a group of eigenvalues closer than they move
  over the step, such as the sin/cos pairs of an axisymmetric disc, the MAC with the group's
  subspace), and
* no two branches swap their frequency order inside the step.

Otherwise the step is bisected (the reduced solve is cheap), down to ``max_depth`` halvings.  A
veering (weak coupling: the curves repel, the shapes rotate over a parameter width ∝ the
coupling) is resolved by the bisection and followed without a swap; a true crossing (no coupling)
keeps MAC ≈ 1 on both sides however small the step, and is accepted at the finest level.  Where
the MAC stays ambiguous at the finest level (near an exceptional point the two shapes become
parallel, or on a point of exact degeneracy) the assignment adds the distance to a linear
eigenvalue prediction, and the reference shapes of the ambiguous branches are not updated.

After tracking, every change of stability of a branch between two grid values (Re λ crossing
``growth_tol``·|λ|, see :func:`~fem_squeal.reduced.eigensolve.unstable`) is an event; its
critical parameter is where Re λ itself crosses zero (the Hopf point with damping, the exceptional
point without, where LAPACK returns real θ and hence Re λ = 0 exactly before it), refined by
bisection on Re λ of the reduced model (eigenvalues only, ``values_solve``) to ``tol``, or, given
the model's relative eigenvalue ``error``, only as far as that error warrants: to the parameter
step over which the branch's eigenvalue moves by error·|λ| (from its change over the grid step),
at most error × the range — finer bisection would locate a point the model cannot tell from its
neighbours (issue 23: refining 35 brake events to 1e-10 cost 4× the tracking itself).
The threshold only classifies: with light damping Re λ may already be positive, below the
threshold, at the grid value before the step where the threshold is crossed; the sign change is
then looked for in the earlier grid steps (see :func:`_events`), and ``bracket`` is the grid step
that holds it.  The partner is the branch nearest in frequency.  An event whose partner frequency
agrees to ``coalescence_rtol`` is a coalescence (mode coupling: for the undamped model, an
exceptional point).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.util.errors import ModelError
from fem_squeal.util.progress import ProgressBar

Solver = Callable[[float], tuple[np.ndarray, np.ndarray]]


@dataclass
class CriticalPoint:
    """A change of stability of ``branch`` between two grid values (refined to ``value``)."""

    branch: int
    partner: int | None
    value: float                    # refined critical parameter: Re λ = 0 (the Hopf point)
    bracket: tuple[float, float]    # the grid values around it
    freq_hz: float
    kind: str                       # "coalescence" or "single"
    onset: bool                     # True: becomes unstable moving away from the start
    labels: tuple[str, ...] = ()
    zero_crossing: bool = True      # False: no sign change of Re λ on the grid (Re λ > 0 up to
                                    # its end): value is where Re λ = growth_tol·|λ|

    def as_dict(self) -> dict:
        return {"branch": self.branch, "partner": self.partner, "value": self.value,
                "bracket": list(self.bracket), "freq_hz": self.freq_hz, "kind": self.kind,
                "onset": self.onset, "labels": list(self.labels), "zero_crossing": self.zero_crossing}


@dataclass
class Tracking:
    """Branch-ordered eigenvalues: ``eigenvalues[k, j]`` is branch j at ``values[k]``."""

    values: np.ndarray
    eigenvalues: np.ndarray
    parents_hz: np.ndarray
    labels: list[str]
    events: list[CriticalPoint] = field(default_factory=list)
    solves: int = 0
    ambiguous_steps: int = 0

    @property
    def freqs_hz(self) -> np.ndarray:
        return self.eigenvalues.imag / TWO_PI

    def as_dict(self) -> dict:
        return {"values": self.values, "freq_hz": self.freqs_hz, "real_part": self.eigenvalues.real,
                "parents_hz": self.parents_hz, "labels": self.labels,
                "events": [e.as_dict() for e in self.events], "solves": self.solves,
                "ambiguous_steps": self.ambiguous_steps}


def mac_matrix(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """MAC between the columns of A and of B (complex allowed)."""
    num = np.abs(A.conj().T @ B) ** 2
    den = np.outer(np.sum(np.abs(A) ** 2, axis=0), np.sum(np.abs(B) ** 2, axis=0))
    return num / np.where(den > 0, den, 1.0)


def _order_swaps(fa: np.ndarray, fb: np.ndarray, rtol: float) -> bool:
    """True if two branches change their frequency order between two points (strictly, beyond
    ``rtol``·scale at both ends)."""
    scale = rtol * max(np.max(np.abs(fa)), 1e-300)
    da = fa[:, None] - fa[None, :]
    db = fb[:, None] - fb[None, :]
    return bool(np.any((da > scale) & (db < -scale)))


def _group_mac(mac: np.ndarray, Y_ref: np.ndarray, Y_b: np.ndarray, lam_a: np.ndarray, lam_b: np.ndarray,
               assigned: np.ndarray, rtol: float) -> np.ndarray:
    """MAC of each branch's new vector with the subspace of its group at the start of the step.

    Eigenvalues that are closer at p_a than they move over the step (or equal to ``rtol``) form
    a group: their shapes may mix arbitrarily within the step (at an exactly or nearly
    degenerate pair, e.g. the sin/cos pairs of an axisymmetric disc that friction turns into
    travelling waves), so only the group's subspace is meaningful."""
    best = mac[np.arange(len(assigned)), assigned]
    move = np.abs(lam_b[assigned] - lam_a)
    gap = np.abs(lam_a[:, None] - lam_a[None, :])
    group = gap <= 2.0 * np.maximum(move[:, None], move[None, :]) + rtol * np.abs(lam_a)[:, None]
    for i in np.flatnonzero(group.sum(axis=1) > 1):
        Q = np.linalg.qr(Y_ref[:, group[i]])[0]
        y = Y_b[:, assigned[i]]
        best[i] = max(best[i], np.sum(np.abs(Q.conj().T @ y) ** 2) / np.sum(np.abs(y) ** 2))
    return best


class _Walker:
    def __init__(self, solve: Solver, mac_min: float, max_depth: int, order_rtol: float,
                 cluster_rtol: float, budget: int, watch=None):
        self.solve, self.mac_min, self.max_depth, self.order_rtol = solve, mac_min, max_depth, order_rtol
        self.watch = watch   # λ -> mask of the branches whose ambiguity refines a step (None: all)
        self.cluster_rtol, self.budget = cluster_rtol, budget
        self.left = budget
        self.solves = 0
        self.ambiguous = 0

    def eig(self, p: float):
        self.solves += 1
        self.left -= 1
        return self.solve(p)

    def step(self, st: dict, p_b: float, depth: int = 0) -> dict:
        if depth == 0:
            self.left = self.budget  # bisection budget of this grid interval
        lam_b, Y_b = self.eig(p_b)
        mac = mac_matrix(st["Y"], Y_b)
        rows, cols = linear_sum_assignment(-mac)
        assigned = np.empty_like(cols)
        assigned[rows] = cols
        best = _group_mac(mac, st["Y"], Y_b, st["lam"], lam_b, assigned, self.cluster_rtol)
        w = self.watch(st["lam"]) if self.watch is not None else slice(None)
        ok = bool(np.all(best[w] >= self.mac_min)) and \
            not _order_swaps(st["lam"].imag[w], lam_b[assigned].imag[w], self.order_rtol)
        if not ok and depth < self.max_depth and self.left >= 2:
            mid = 0.5 * (st["p"] + p_b)
            return self.step(self.step(st, mid, depth + 1), p_b, depth + 1)
        Y_new = st["Y"].astype(complex)
        if not ok:
            self.ambiguous += 1
            # eigenvalue prediction by linear extrapolation, mixed with the MAC
            if st["p_prev"] is not None and st["p"] != st["p_prev"]:
                pred = st["lam"] + (st["lam"] - st["lam_prev"]) * (p_b - st["p"]) / (st["p"] - st["p_prev"])
            else:
                pred = st["lam"]
            scale = np.maximum(np.abs(st["lam"] - pred), 1e-6 * np.abs(st["lam"]) + 1e-300)
            cost = np.abs(pred[:, None] - lam_b[None, :]) / scale[:, None] + (1.0 - mac)
            rows, cols = linear_sum_assignment(cost)
            assigned[rows] = cols
            sure = _group_mac(mac, st["Y"], Y_b, st["lam"], lam_b, assigned, self.cluster_rtol) \
                >= self.mac_min
            Y_new[:, sure] = Y_b[:, assigned[sure]]
        else:
            Y_new = Y_b[:, assigned]
        return {"p": p_b, "lam": lam_b[assigned], "Y": Y_new, "p_prev": st["p"], "lam_prev": st["lam"]}


def track(solve: Solver, values: np.ndarray, *, start: float | None = None, mac_min: float = 0.8,
          max_depth: int = 10, budget: int = 48, order_rtol: float = 1e-9, cluster_rtol: float = 1e-8,
          growth_tol: float = 1e-6,
          coalescence_rtol: float = 1e-3, tol: float = 1e-10, labels: list[str] | None = None,
          progress: bool = False, values_solve: Callable[[float], np.ndarray] | None = None,
          error: float | None = None, band_hz: tuple[float, float] | None = None) -> Tracking:
    """Track every eigenvalue of ``solve(p) -> (λ (m,), Y (m, m))`` over the sorted ``values``.

    ``start`` (default 0 if inside the range, else the first value) is where branches are
    labelled; critical points are refined to ``tol`` × (range of values), or with ``error`` (the
    model's relative eigenvalue error) as far as it warrants (module docstring), never finer than
    ``tol``; ``values_solve(p) -> λ`` (eigenvalues only) serves the refinement; ``band_hz``: only the
    stability changes of branches in this band (their frequency on the unstable side) are located
    and reported (the others cost refinement solves for nothing), and only an ambiguous step (MAC
    below ``mac_min``, a change of frequency order) of a branch within the band widened by 10 % of
    its width on each side is bisected; the other branches follow the assignment.  ``budget`` caps the
    extra solves spent bisecting one grid interval; ``cluster_rtol`` is the relative distance
    under which eigenvalues count as one degenerate cluster."""
    values = np.asarray(values, float)
    if values.ndim != 1 or values.size < 2 or np.any(np.diff(values) <= 0):
        raise ModelError("values: must be at least 2 strictly increasing numbers")
    if start is None:
        start = 0.0 if values[0] <= 0.0 <= values[-1] else float(values[0])
    watch = None
    if band_hz is not None:
        margin = 0.1 * (band_hz[1] - band_hz[0])
        lo, hi = TWO_PI * (band_hz[0] - margin), TWO_PI * (band_hz[1] + margin)
        watch = lambda lam: (lam.imag >= lo) & (lam.imag <= hi)  # noqa: E731
    walker = _Walker(solve, mac_min, max_depth, order_rtol, cluster_rtol, budget, watch)
    lam0, Y0 = walker.eig(start)
    m = lam0.size
    parents_hz = lam0.imag / TWO_PI
    labels = labels or [f"M{j + 1}" for j in range(m)]
    out = np.empty((values.size, m), complex)
    done = 0
    with ProgressBar(values.size, "sweep", enabled=progress, unit=" values") as bar:
        for side in (values[values >= start], values[values < start][::-1]):
            st = {"p": start, "lam": lam0, "Y": Y0, "p_prev": None, "lam_prev": None}
            for p in side:
                if p != start:
                    st = walker.step(st, float(p))
                out[np.searchsorted(values, p)] = st["lam"]
                done += 1
                bar.update(done)
    tr = Tracking(values, out, parents_hz, labels)
    vsolve = values_solve if values_solve is not None else (lambda p: solve(p)[0])
    tr.events = _events(tr, vsolve, start, growth_tol, coalescence_rtol, tol * (values[-1] - values[0]), error,
                        band_hz)
    tr.solves, tr.ambiguous_steps = walker.solves, walker.ambiguous
    return tr


def _growth(lam: np.ndarray) -> np.ndarray:
    return lam.real / np.maximum(np.abs(lam), 1e-300)


# Re λ ≤ _ZERO·|λ| at a grid point counts as Re λ = 0 when looking for the Hopf point: 100× the
# round-off of Re λ for an undamped mode in the companion-form solve (~6e-15 relative, measured on a
# random m = 200 basis), so such noise never starts a search; a genuine growth that small moves the
# located point by at most _ZERO·|λ| / |d Re λ / dp|.  (On a grid value that is an exceptional
# point the round-off is ~√ε·|λ|; the search then steps one grid value back, where Re λ = 0, and
# bisects the step that ends at the exceptional point: the same point, found from the other side.)
_ZERO = 1e-12


def _bisect(solve, v: np.ndarray, lam_j: np.ndarray, i: int, above, tol: float,
            error: float | None = None) -> float:
    """The parameter where ``above(λ)`` of one branch changes between the grid values v[i] and
    v[i + 1] (``lam_j``: the branch's tracked eigenvalues), bisected to ``tol`` (or, with the model's
    relative ``error``, to the step over which λ moves by error·|λ|, at most error × the range);
    ``solve(p) -> λ``; the branch is followed by the eigenvalue nearest to the linear interpolation
    over the grid step."""
    lo, hi, la, lb = v[i], v[i + 1], lam_j[i], lam_j[i + 1]
    if error is not None and error > 0:
        rate = abs(lb - la) / (hi - lo)       # |dλ/dp| over the grid step
        warranted = error * (v[-1] - v[0])
        if rate > 0:
            warranted = min(warranted, error * max(abs(la), abs(lb)) / rate)
        tol = max(tol, warranted)
    s_lo = bool(above(la))
    a, b = lo, hi
    while b - a > tol:
        mid = 0.5 * (a + b)
        ev = solve(mid)
        if bool(above(ev[np.argmin(np.abs(ev - (la + (lb - la) * (mid - lo) / (hi - lo))))])) == s_lo:
            a = mid
        else:
            b = mid
    return 0.5 * (a + b)


def _events(tr: Tracking, solve, start: float, growth_tol: float, coalescence_rtol: float,
            tol: float, error: float | None = None, band_hz: tuple[float, float] | None = None
            ) -> list[CriticalPoint]:
    """Stability changes of every branch between grid values (the threshold test, as
    :func:`~fem_squeal.reduced.eigensolve.unstable`), each located at its Hopf point Re λ = 0.

    The classification and the location are separate questions.  A branch may have
    0 < Re λ ≤ growth_tol·|λ| on the stable side of the grid step where the threshold is crossed
    (light damping: the growth rises slowly past the Hopf point); Re λ then changed sign earlier,
    so the stable side's grid values are walked away from the step, along the branch, to the
    first one with Re λ ≤ 0 (to :data:`_ZERO`·|λ|), and the sign change is refined in that grid step.
    The walk stops at a value where the branch is unstable by the threshold (a dip of the growth
    that stays above zero) or at the end of the grid: then there is no sign change of Re λ on
    the grid, and the event is located where Re λ crosses growth_tol·|λ| in its own step
    (``zero_crossing`` False)."""
    v, lam = tr.values, tr.eigenvalues
    growth = _growth(lam)
    grow = growth > growth_tol
    zero = min(_ZERO, growth_tol)
    events = []
    k0 = int(np.searchsorted(v, start))
    for k in range(v.size - 1):
        outward = k >= k0  # walking away from the start: increasing p on the right, decreasing on the left
        for j in np.flatnonzero(grow[k] != grow[k + 1]):
            g_lo = bool(grow[k, j])
            k_un, k_st = (k, k + 1) if g_lo else (k + 1, k)
            if band_hz is not None and not band_hz[0] <= lam[k_un, j].imag / TWO_PI <= band_hz[1]:
                continue
            step = k_st - k_un               # walk away from the unstable side
            i = k_st
            while 0 <= i + step < v.size and growth[i, j] > zero and not grow[i + step, j]:
                i += step
            if growth[i, j] > zero:          # no sign change of Re λ on the grid: the threshold
                crit = _bisect(solve, v, lam[:, j], k, lambda x: _growth(x) > growth_tol, tol, error)
                bracket, crossing = (v[k], v[k + 1]), False
            else:                            # Re λ changes sign between v[i] and its neighbour
                i_lo = min(i, i - step)
                # Re λ exactly ≤ 0 (undamped before an exceptional point, or damped): refine on
                # the sign itself; within round-off of zero: on the same margin as the walk
                z = 0.0 if lam[i, j].real <= 0.0 else zero
                crit = _bisect(solve, v, lam[:, j], i_lo, lambda x, z=z: _growth(x) > z, tol, error)
                bracket, crossing = (v[i_lo], v[i_lo + 1]), True
            f = lam[k_un].imag
            others = np.delete(np.arange(lam.shape[1]), j)
            partner = int(others[np.argmin(np.abs(f[others] - f[j]))]) if others.size else None
            close = partner is not None and abs(f[partner] - f[j]) <= coalescence_rtol * abs(f[j])
            onset = (not g_lo) if outward else g_lo
            events.append(CriticalPoint(
                int(j), partner, float(crit), (float(bracket[0]), float(bracket[1])), float(f[j] / TWO_PI),
                "coalescence" if close else "single", bool(onset),
                (tr.labels[j],) + ((tr.labels[partner],) if partner is not None else ()), crossing))
    return events
