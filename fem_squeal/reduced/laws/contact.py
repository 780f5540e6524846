"""Normal contact laws of a contact element (seed 000 eq. 3, seed 004 eq. 3).

With δ the closure of an element (δ > 0: penetration, the opposite of the gap g = −δ) and δ̇ its
rate, the normal force pressing the two sides apart is

    F(δ, δ̇) = k_l δ + k_nl δ³ + c(δ) δ̇    for δ > 0,      F = 0 otherwise (loss of contact),

    c(δ) = c_max (3 δ²/l² − 2 δ³/l³) for 0 < δ ≤ l,  c_max for δ > l      (seed 004 eq. 3).

The damping term is optional (c_max = 0 gives the purely elastic law of seed 000); c(0) = 0 and
c'(0) = 0, so the force has no jump when contact is made or lost.  k_l [N/m], k_nl [N/m³], c_max
[N s/m] and l [m] are per element (arrays broadcast against the element axis).  The friction
force is μF along the sliding direction (sliding is assumed maintained, as in seed 000).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple, Protocol

import numpy as np

from fem_squeal.util.errors import ModelError

__all__ = ["NORMAL_LAWS", "ExponentialLaw", "NormalLaw", "UnilateralLaw", "exponential_like", "tune_cubic"]


class NormalLaw(Protocol):
    """What the preload, MASA and the transient ask of a normal contact law, with one sign convention:
    δ = −g is the closure (> 0: penetration) and F ≥ 0 the force pressing the two sides apart."""

    #: MASA's first-harmonic AFT (seed 000 eqs. 7-18) applies: a piecewise polynomial law that is exactly
    #: zero when open, so its describing function and the loss of contact are those MASA tabulates
    aft: ClassVar[bool]
    damped: bool

    def force(self, d: np.ndarray, v: np.ndarray | float = 0.0) -> np.ndarray:
        """F(δ, δ̇)."""

    def stiffness(self, d: np.ndarray) -> np.ndarray:
        """∂F/∂δ at rest."""

    def viscosity(self, d: np.ndarray) -> np.ndarray:
        """∂F/∂δ̇."""

    def evaluate(self, d: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """F, ∂F/∂δ, ∂F/∂δ̇ in motion (the transient)."""


@dataclass(frozen=True)
class UnilateralLaw:
    """The law of the module docstring, one value (or an (n_elements,) array) per parameter."""

    k_l: np.ndarray | float
    k_nl: np.ndarray | float = 0.0
    c_max: np.ndarray | float = 0.0
    depth: np.ndarray | float = np.inf   # l: penetration at which the damping reaches c_max [m]

    aft: ClassVar[bool] = True

    def __post_init__(self):
        for name in ("k_l", "k_nl", "c_max"):
            v = np.asarray(getattr(self, name), float)
            if np.any(~np.isfinite(v)) or np.any(v < 0):
                raise ModelError(f"contact law {name}: must be finite and >= 0 (got min {np.min(v):g})")
        if np.any(np.asarray(self.c_max) > 0) and np.any(~(np.asarray(self.depth, float) > 0)):
            raise ModelError("contact law depth: must be > 0 where c_max > 0")
        if np.all(np.asarray(self.k_l) == 0) and np.all(np.asarray(self.k_nl) == 0):
            raise ModelError("contact law: k_l and k_nl are both zero (no contact stiffness)")

    @property
    def damped(self) -> bool:
        return bool(np.any(np.asarray(self.c_max) > 0))

    def _p(self, name: str, ndim: int) -> np.ndarray:
        """Parameter shaped to broadcast along the leading (element) axis of an ``ndim`` array."""
        v = np.asarray(getattr(self, name), float)
        return v.reshape(v.shape + (1,) * (ndim - v.ndim)) if v.ndim else v

    def damping(self, d: np.ndarray) -> np.ndarray:
        """c(δ) (zero where open)."""
        d = np.asarray(d, float)
        c_max, depth = self._p("c_max", d.ndim), self._p("depth", d.ndim)
        s = np.clip(d / depth, 0.0, 1.0)
        return c_max * s * s * (3.0 - 2.0 * s)

    def force(self, d: np.ndarray, v: np.ndarray | float = 0.0) -> np.ndarray:
        """F(δ, δ̇) [N]."""
        d = np.asarray(d, float)
        k_l, k_nl = self._p("k_l", d.ndim), self._p("k_nl", d.ndim)
        f = k_l * d + k_nl * d ** 3
        if self.damped:
            f = f + self.damping(d) * v
        return np.where(d > 0.0, f, 0.0)

    def stiffness(self, d: np.ndarray) -> np.ndarray:
        """∂F/∂δ at rest (δ̇ = 0): k_l + 3 k_nl δ² where closed, 0 where open."""
        d = np.asarray(d, float)
        k_l, k_nl = self._p("k_l", d.ndim), self._p("k_nl", d.ndim)
        return np.where(d > 0.0, k_l + 3.0 * k_nl * d ** 2, 0.0)

    def remainder(self, d_static: np.ndarray, dd: np.ndarray, v: np.ndarray) -> np.ndarray:
        """F(δ_s + Δ, v) − F(δ_s, 0) − ∂_δF(δ_s) Δ − ∂_δ̇F(δ_s) v (seed 000 eq. 8 for one element).

        ``d_static`` has one more trailing axis than needed to broadcast against ``dd``.  Where
        the element stays closed the polynomial part is evaluated as k_nl Δ²(3δ_s + Δ), which
        avoids the cancellation of the direct difference (relative 1e-9 at Δ = 1e-2 δ_s)."""
        d = d_static + dd
        r = self.force(d, v) - self.force(d_static) - self.stiffness(d_static) * dd
        if self.damped:
            r -= self.viscosity(d_static) * v
        both = (d > 0) & (d_static > 0)
        k_nl = self._p("k_nl", dd.ndim)
        smooth = k_nl * dd * dd * (3.0 * d_static + dd)
        if self.damped:
            smooth = smooth + (self.damping(d) - self.damping(d_static)) * v
        return np.where(both, smooth, r)

    def viscosity(self, d: np.ndarray) -> np.ndarray:
        """∂F/∂δ̇ = c(δ)."""
        return self.damping(d) if self.damped else np.zeros_like(np.asarray(d, float))

    def evaluate(self, d: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """F, ∂F/∂δ, ∂F/∂δ̇ in motion, for the transient.  The damped force is clipped at zero,
        F = max(k_l δ + k_nl δ³ + c(δ)δ̇, 0) (seed 004 eq. 2): a separating element does not pull."""
        d = np.asarray(d, float)
        k_l, k_nl = self._p("k_l", d.ndim), self._p("k_nl", d.ndim)
        closed = d > 0.0
        F = k_l * d + k_nl * d ** 3
        dF = k_l + 3.0 * k_nl * d ** 2
        dV = np.zeros_like(d)
        if self.damped:
            c_max, depth = self._p("c_max", d.ndim), self._p("depth", d.ndim)
            s = np.clip(d / depth, 0.0, 1.0)
            c = c_max * s * s * (3.0 - 2.0 * s)
            dc = np.where((s > 0) & (s < 1), c_max * 6.0 * s * (1.0 - s) / depth, 0.0)
            F = F + c * v
            dF = dF + dc * v
            dV = c
            closed &= F > 0.0
        return (np.where(closed, F, 0.0), np.where(closed, dF, 0.0), np.where(closed, dV, 0.0))


def tune_cubic(k_target: np.ndarray | float, preload_force: np.ndarray | float,
               cubic_share: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """k_l, k_nl (and the static closure δ₀) that give the tangent stiffness ``k_target`` at the
    closure where the element carries ``preload_force``, with ``cubic_share`` of that tangent
    coming from the cubic term:

        k_l + 3 k_nl δ₀² = k_t,   3 k_nl δ₀² = s k_t,   k_l δ₀ + k_nl δ₀³ = F₀
        ⇒ δ₀ = F₀ / (k_t (1 − 2s/3)),  k_l = (1 − s) k_t,  k_nl = s k_t / (3 δ₀²).

    s = 0 is the linear penalty; s → 1 a purely cubic (Hertz-like) law.  Elements without load
    (F₀ = 0) get the linear law k_l = k_t."""
    s = float(cubic_share)
    if not 0.0 <= s <= 1.0:
        raise ModelError(f"cubic_share: must be in [0, 1] (got {cubic_share})")
    kt = np.asarray(k_target, float)
    F0 = np.asarray(preload_force, float)
    if np.any(~(kt > 0)):
        raise ModelError("k_target: must be > 0")
    if np.any(F0 < 0):
        raise ModelError("preload_force: must be >= 0")
    kt, F0 = np.broadcast_arrays(kt, F0)
    d0 = F0 / (kt * (1.0 - 2.0 * s / 3.0))
    loaded = d0 > 0
    k_nl = np.where(loaded, s * kt / (3.0 * np.where(loaded, d0, 1.0) ** 2), 0.0)
    k_l = np.where(loaded, (1.0 - s) * kt, kt)
    return k_l, k_nl, d0


@dataclass(frozen=True)
class ExponentialLaw:
    """p(g) = p₀ e^(−λg) (seed 002 eq. 2) as an element force F = w p₀ e^(λδ) with δ = −g.

    Never exactly zero: an open element (g > 0) keeps a force that decays over the length 1/λ,
    which makes opening smooth; the tangent is λF.  ``p0`` [Pa] (or [N] with w = 1), ``lam``
    [1/m] and the area ``weight`` are per element.  Elements open by more than 700/λ are clipped
    to F = 0 so that the exponential never overflows."""

    p0: np.ndarray | float
    lam: np.ndarray | float
    weight: np.ndarray | float = 1.0

    aft: ClassVar[bool] = False     # never exactly open: MASA's contact-loss AFT does not describe it

    def __post_init__(self):
        for name in ("p0", "lam", "weight"):
            v = np.asarray(getattr(self, name), float)
            if np.any(~np.isfinite(v)) or np.any(v <= 0):
                raise ModelError(f"exponential contact law {name}: must be finite and > 0 (got min {np.min(v):g})")

    damped = False

    def evaluate(self, d: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """F, ∂F/∂δ = λF, ∂F/∂δ̇ = 0."""
        d = np.asarray(d, float)
        x = np.minimum(np.asarray(self.lam) * d, 700.0)
        F = np.where(x > -700.0, np.asarray(self.weight) * np.asarray(self.p0) * np.exp(x), 0.0)
        return F, np.asarray(self.lam) * F, np.zeros_like(d)

    def force(self, d: np.ndarray, v: np.ndarray | float = 0.0) -> np.ndarray:
        return self.evaluate(d, np.zeros_like(np.asarray(d, float)))[0]

    def stiffness(self, d: np.ndarray) -> np.ndarray:
        return self.evaluate(d, np.zeros_like(np.asarray(d, float)))[1]

    def viscosity(self, d: np.ndarray) -> np.ndarray:
        return np.zeros_like(np.asarray(d, float))


def exponential_like(k_target: np.ndarray | float, preload_force: np.ndarray | float,
                     weight: np.ndarray | float = 1.0) -> ExponentialLaw:
    """The exponential law whose tangent is ``k_target`` where the element carries
    ``preload_force`` at zero gap: F₀ = w p₀, λ = k_t/F₀ (so the static state of a linear
    penalty model with the same tangent and load is matched to first order)."""
    kt, F0, w = np.broadcast_arrays(*(np.asarray(a, float) for a in (k_target, preload_force, weight)))
    if np.any(~(F0 > 0)):
        raise ModelError("preload_force: the exponential law needs a preload > 0 on every element")
    return ExponentialLaw(p0=F0 / w, lam=kt / F0, weight=w)


class NormalLawEntry(NamedTuple):
    """A normal law the scene can choose by name."""

    doc: str
    law: type        # the class; its ``aft`` says whether MASA's AFT applies


#: the normal laws by their scene name (``analyses.transient.normal``); the first is the default
NORMAL_LAWS: dict[str, NormalLawEntry] = {
    "cubic": NormalLawEntry("k_l δ + k_nl δ³ (+ c(δ) δ̇), zero when open (seed 000 eq. 3, seed 004 eq. 3); "
                            "cubic_share 0 is the linear penalty", UnilateralLaw),
    "exponential": NormalLawEntry("p₀ e^(λδ) (seed 002 eq. 2), smooth opening", ExponentialLaw),
}
