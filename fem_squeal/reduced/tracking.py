"""Mode tracking along a one-parameter path (a μ or E sweep) by MAC continuation.

Branches start at ``start`` (μ = 0: the frictionless parents, labelled M1, M2, … by frequency)
and are continued outwards in both directions.  A step p_a → p_b is accepted when

* the Hungarian assignment that maximises Σ MAC(y_ref, y_b) gives every branch a MAC ≥
  ``mac_min`` (MAC(a, b) = |aᴴb|² / (|a|²|b|²); the reduced basis is M-orthonormal, so this is
  the mass-weighted MAC of the lifted shapes; for a group of eigenvalues closer than they move
  over the step, such as the sin/cos pairs of an axisymmetric disc, the MAC with the group's
  subspace), and
* no two branches swap their frequency order inside the step.

Otherwise the step is bisected (the reduced solve is cheap), down to ``max_depth`` halvings (and,
given the model's relative eigenvalue ``error``, not below error × the range).  A
veering (weak coupling: the curves repel, the shapes rotate over a parameter width ∝ the
coupling) is resolved by the bisection and followed without a swap; a true crossing (no coupling)
keeps MAC ≈ 1 on both sides however small the step, and is accepted at the finest level.  Where
the MAC stays ambiguous at the finest level (near an exceptional point the two shapes become
parallel, or on a point of exact degeneracy) the assignment adds the distance to a linear
eigenvalue prediction, and the reference shapes of the ambiguous branches are not updated.

Given ``values_solve`` (eigenvalues only: 0.6 of a solve with eigenvectors for the 233-vector
brake), a step is first taken on eigenvalues alone where that is unambiguous: every watched
eigenvalue at p_a farther from the others than 4× its predicted movement, and at p_b the one
nearest each branch's linear prediction nearer than 0.2× the next one, no frequency order changed.
The MAC references are then re-solved only before the next step that needs them (near
coalescences and veerings).  On the brake sweep (201 values) this leaves 120 of 264 solves with
eigenvectors and the same branches (tests/unit/reduced/test_reduced.py: equal to MAC continuation at every step).

After tracking, every change of stability of a branch between two grid values (Re λ crossing
``growth_tol``·|λ|, see :func:`~fem_squeal.reduced.eigensolve.unstable`) is an event; its
critical parameter is where Re λ itself crosses zero (the Hopf point with damping, the exceptional
point without, where LAPACK returns real θ and hence Re λ = 0 exactly before it), refined on Re λ
of the reduced model (eigenvalues only, ``values_solve``; a safeguarded regula falsi,
:func:`_bisect`) to ``tol``, or, given
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
    solves: int = 0                 # reduced solves while tracking (with and without eigenvectors)
    vector_solves: int = 0          # of which with eigenvectors
    ambiguous_steps: int = 0

    @property
    def freqs_hz(self) -> np.ndarray:
        return self.eigenvalues.imag / TWO_PI

    def as_dict(self) -> dict:
        return {"values": self.values, "freq_hz": self.freqs_hz, "real_part": self.eigenvalues.real,
                "parents_hz": self.parents_hz, "labels": self.labels,
                "events": [e.as_dict() for e in self.events], "solves": self.solves,
                "vector_solves": self.vector_solves, "ambiguous_steps": self.ambiguous_steps}


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


#: a values-only step is tried only where every watched eigenvalue at p_a lies farther from the others
#: than _SEPARATION × its predicted movement over the step, and accepted only where every watched
#: branch's new eigenvalue is nearer its linear prediction than _MARGIN × the next nearest one's distance
_SEPARATION, _MARGIN = 4.0, 0.2


class _Walker:
    def __init__(self, solve: Solver, mac_min: float, max_depth: int, order_rtol: float,
                 cluster_rtol: float, budget: int, watch=None, values=None, min_step: float = 0.0):
        self.solve, self.mac_min, self.max_depth, self.order_rtol = solve, mac_min, max_depth, order_rtol
        self.min_step = min_step  # no bisection below this parameter step (the model's resolution)
        self.watch = watch   # λ -> mask of the branches whose ambiguity refines a step (None: all)
        self.values = values  # p -> λ (eigenvalues only), for the unambiguous steps (None: vectors always)
        self.cluster_rtol, self.budget = cluster_rtol, budget
        self.left = budget
        self.solves = 0
        self.vector_solves = 0
        self.ambiguous = 0

    def eig(self, p: float):
        self.solves += 1
        self.vector_solves += 1
        self.left -= 1
        return self.solve(p)

    def _mask(self, lam: np.ndarray):
        return self.watch(lam) if self.watch is not None else np.ones(lam.size, bool)

    @staticmethod
    def _predict(st: dict, p_b: float) -> np.ndarray:
        """Each branch's eigenvalue at p_b, extrapolated linearly from its last two values (its
        value at p_a where there is only one)."""
        if st["p_prev"] is None or st["p"] == st["p_prev"]:
            return st["lam"]
        return st["lam"] + (st["lam"] - st["lam_prev"]) * (p_b - st["p"]) / (st["p"] - st["p_prev"])

    def values_step(self, st: dict, p_b: float) -> dict | None:
        """The step by eigenvalues alone where it is unambiguous (None: the vectors decide).

        Each branch is predicted by linear extrapolation from its last two values; the step is
        tried where the watched eigenvalues at p_a are separated by more than _SEPARATION × their
        predicted movement, and accepted where each watched branch's nearest new eigenvalue is
        nearer than _MARGIN × the distance to the next one and no two watched branches change
        their frequency order.  The MAC references are then kept (refreshed before the next step
        that needs them)."""
        if self.values is None or st["p_prev"] is None or st["p"] == st["p_prev"]:
            return None
        lam_a = st["lam"]
        pred = self._predict(st, p_b)
        w = self._mask(lam_a)
        if not w.any():
            return None
        gap = np.abs(lam_a[w][:, None] - lam_a[None, :])
        gap[np.arange(gap.shape[0]), np.flatnonzero(w)] = np.inf
        move = np.abs(pred - lam_a)[w]
        if not np.all(gap.min(axis=1) > _SEPARATION * move + self.cluster_rtol * np.abs(lam_a[w])):
            return None
        self.solves += 1
        lam_b = self.values(p_b)
        dist = np.abs(pred[:, None] - lam_b[None, :])
        assigned = np.argmin(dist, axis=1)
        if np.unique(assigned).size != assigned.size:   # collisions (of unwatched branches): optimal assignment
            rows, cols = linear_sum_assignment(dist)
            assigned[rows] = cols
        d = dist[np.arange(dist.shape[0]), assigned][w]
        second = np.partition(dist[w], 1, axis=1)[:, 1] if lam_b.size > 1 else np.full(d.size, np.inf)
        if not np.all(d <= _MARGIN * second) or \
                _order_swaps(lam_a.imag[w], lam_b[assigned].imag[w], self.order_rtol):
            return None
        return {**st, "p": p_b, "lam": lam_b[assigned], "p_prev": st["p"], "lam_prev": lam_a, "fresh": False}

    def refresh(self, st: dict) -> dict:
        """``st`` with its MAC references re-solved at its own point after values-only steps (the
        references held at an ambiguous step stay held)."""
        if st.get("fresh", True):
            return st
        lam_v, Y_v = self.eig(st["p"])
        rows, cols = linear_sum_assignment(np.abs(st["lam"][:, None] - lam_v[None, :]))
        match = np.empty_like(cols)
        match[rows] = cols
        Y = st["Y"].astype(complex)
        upd = ~st["held"]
        Y[:, upd] = Y_v[:, match[upd]]
        return {**st, "Y": Y, "fresh": True}

    def step(self, st: dict, p_b: float, depth: int = 0) -> dict:
        if depth == 0:
            self.left = self.budget  # bisection budget of this grid interval
        fast = self.values_step(st, p_b)
        if fast is not None:
            return fast
        st = self.refresh(st)
        lam_b, Y_b = self.eig(p_b)
        mac = mac_matrix(st["Y"], Y_b)
        rows, cols = linear_sum_assignment(-mac)
        assigned = np.empty_like(cols)
        assigned[rows] = cols
        best = _group_mac(mac, st["Y"], Y_b, st["lam"], lam_b, assigned, self.cluster_rtol)
        w = self._mask(st["lam"])
        ok = bool(np.all(best[w] >= self.mac_min)) and \
            not _order_swaps(st["lam"].imag[w], lam_b[assigned].imag[w], self.order_rtol)
        if not ok and depth < self.max_depth and self.left >= 2 and 0.5 * abs(p_b - st["p"]) >= self.min_step:
            mid = 0.5 * (st["p"] + p_b)
            return self.step(self.step(st, mid, depth + 1), p_b, depth + 1)
        Y_new = st["Y"].astype(complex)
        held = np.zeros(lam_b.size, bool)
        if not ok:
            self.ambiguous += 1
            pred = self._predict(st, p_b)   # the eigenvalue prediction, mixed with the MAC
            scale = np.maximum(np.abs(st["lam"] - pred), 1e-6 * np.abs(st["lam"]) + 1e-300)
            cost = np.abs(pred[:, None] - lam_b[None, :]) / scale[:, None] + (1.0 - mac)
            rows, cols = linear_sum_assignment(cost)
            assigned[rows] = cols
            sure = _group_mac(mac, st["Y"], Y_b, st["lam"], lam_b, assigned, self.cluster_rtol) \
                >= self.mac_min
            Y_new[:, sure] = Y_b[:, assigned[sure]]
            held = ~sure
        else:
            Y_new = Y_b[:, assigned]
        return {"p": p_b, "lam": lam_b[assigned], "Y": Y_new, "p_prev": st["p"], "lam_prev": st["lam"],
                "fresh": True, "held": held}


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
    ``tol``; ``values_solve(p) -> λ`` (eigenvalues only) serves the refinement and the
    unambiguous steps (module docstring); ``band_hz``: only the
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
    # with the model's error, steps are not bisected below error × the range: a veering narrower
    # than that (a gap below the eigenvalue error) is not resolved by the model itself
    min_step = error * (values[-1] - values[0]) if error else 0.0
    walker = _Walker(solve, mac_min, max_depth, order_rtol, cluster_rtol, budget, watch, values_solve, min_step)
    lam0, Y0 = walker.eig(start)
    m = lam0.size
    parents_hz = lam0.imag / TWO_PI
    labels = labels or [f"M{j + 1}" for j in range(m)]
    out = np.empty((values.size, m), complex)
    done = 0
    with ProgressBar(values.size, "sweep", enabled=progress, unit=" values") as bar:
        for side in (values[values >= start], values[values < start][::-1]):
            st = {"p": start, "lam": lam0, "Y": Y0, "p_prev": None, "lam_prev": None, "fresh": True,
                  "held": np.zeros(m, bool)}
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
    tr.solves, tr.vector_solves, tr.ambiguous_steps = walker.solves, walker.vector_solves, walker.ambiguous
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


def _bisect(solve, v: np.ndarray, lam: np.ndarray, j: int, i: int, level: float, tol: float,
            error: float | None = None) -> float:
    """The parameter where the growth Re λ/|λ| of branch ``j`` crosses ``level`` between the grid values
    v[i] and v[i + 1] (``lam``: the tracked eigenvalues, values × branches), located to ``tol`` (or,
    with the model's relative ``error``, to the step over which λ moves by error·|λ|, at most error ×
    the range); ``solve(p) -> λ``; the branch is followed by the eigenvalue nearest to the linear
    interpolation over the grid step.

    A safeguarded regula falsi (Illinois), keeping the sign change bracketed, on a function that is
    smooth through the root, where the secant estimates converge superlinearly (issue 23: ~2
    reduced solves per event at the warranted tolerance against 4–5 by bisection, ~6 at 1e-10 of the
    range against 27): the growth − ``level`` at a Hopf point (damped: a simple root), and at the
    exceptional point of an undamped model (Re λ = 0 exactly on the stable side, ∝ √(p − p_c) on the
    other) the discriminant D = (ΔRe² − ΔIm²)/|λ|² of λ and its nearest neighbour, which changes sign
    linearly there (the pair's imaginary parts split ∝ √(p_c − p) before it, their real parts
    after).  The bracket follows the growth's own test, as bisection would; the secant steps only
    while D agrees with it (a third eigenvalue near the pair can make the nearest neighbour another
    mode: then bisection).  When the next estimate moves by less than tol/2, the point evaluated
    instead is 0.9 tol beyond the last one towards it, which closes the bracket if the estimate is
    right; where two steps have not halved the bracket, the next is a bisection.  The result is the
    middle of a bracket within ``tol``, as by bisection."""
    lo, hi, la, lb = v[i], v[i + 1], lam[i, j], lam[i + 1, j]
    if error is not None and error > 0:
        rate = abs(lb - la) / (hi - lo)       # |dλ/dp| over the grid step
        warranted = error * (v[-1] - v[0])
        if rate > 0:
            warranted = min(warranted, error * max(abs(la), abs(lb)) / rate)
        tol = max(tol, warranted)
    g_a, g_b = _growth(np.array([la, lb])) - level
    exceptional = level == 0 and (g_a == 0 or g_b == 0)

    def f(p: float) -> tuple[float, bool]:
        """(the function the secant steps follow, whether the branch is above ``level`` at p)."""
        k = i if p == lo else i + 1 if p == hi else None
        ev = lam[k] if k is not None else solve(p)
        x = ev[j] if k is not None else ev[np.argmin(np.abs(ev - (la + (lb - la) * (p - lo) / (hi - lo))))]
        g = float(_growth(np.array([x]))[0] - level)
        if not exceptional:
            return g, g > 0
        d = np.abs(ev - x)
        d[np.argmin(d)] = np.inf            # x itself
        y = ev[np.argmin(d)] if ev.size > 1 else x
        return float(((x.real - y.real) ** 2 - (x.imag - y.imag) ** 2) / max(abs(x) ** 2, 1e-300)), g > 0

    a, b = lo, hi
    (fa, s_lo), (fb, _) = f(lo), f(hi)
    # the bracket follows the growth itself; the secant steps only while their function agrees with
    # it (a third eigenvalue near the coalescing pair can make the nearest neighbour another mode)
    trusted = (fa > 0) == s_lo and (fb > 0) != s_lo
    side, c_prev, widths = 0, None, [b - a]
    while b - a > tol:
        width = b - a
        # the bracket must halve every two steps (Illinois converges superlinearly at a simple root);
        # where it does not, bisect
        secant = trusted and (len(widths) < 3 or width <= 0.5 * widths[-3])
        signed = (fa > 0) != (fb > 0) and fa != 0 and fb != 0
        c = b - fb * (b - a) / (fb - fa) if secant and signed else 0.5 * (a + b)
        c = min(max(c, a + 1e-3 * width), b - 1e-3 * width)
        if c_prev is not None and abs(c - c_prev) <= 0.5 * tol:
            # converged estimate: probe 0.9 tol beyond the last point towards it, which closes the
            # bracket to within tol if the estimate is right (one solve instead of several halvings)
            c = min(max(c_prev + np.copysign(0.9 * tol, c - c_prev), a + 1e-3 * width), b - 1e-3 * width)
        fc, above = f(c)
        trusted = trusted and (fc > 0) == above
        if above == s_lo:
            a, fa = c, fc
            if side == -1:
                fb *= 0.5     # Illinois: the end kept twice in a row counts half
            side = -1
        else:
            b, fb = c, fc
            if side == 1:
                fa *= 0.5
            side = 1
        widths.append(b - a)
        c_prev = c
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
                crit = _bisect(solve, v, lam, j, k, growth_tol, tol, error)
                bracket, crossing = (v[k], v[k + 1]), False
            else:                            # Re λ changes sign between v[i] and its neighbour
                i_lo = min(i, i - step)
                # Re λ exactly ≤ 0 (undamped before an exceptional point, or damped): refine on
                # the sign itself; within round-off of zero: on the same margin as the walk
                z = 0.0 if lam[i, j].real <= 0.0 else zero
                crit = _bisect(solve, v, lam, j, i_lo, z, tol, error)
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
