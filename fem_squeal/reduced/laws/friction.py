"""Friction laws of a contact element for the transient solver, vectorised over elements.

Each element has n_dir = 1 or 2 tangential directions.  w is the velocity of the structure
relative to the counter-face (disc, belt) along them, w = T q̇ − V (V: the counter-face surface
velocity), and the law returns the friction force f on the structure along the same directions,
with its derivatives with respect to the normal force F, the relative velocity w and the
relative displacement increment Δs of the step (None where it does not depend on one).

- :class:`ConstantFriction`: f = μF V/|V|, the sliding law the CEA linearises (the counter-face
  drags the structure along its own velocity whatever the vibration does).
- :class:`ElasticCoulomb`: regularised Coulomb with a tangential stiffness k_t (seed 002 eq. 3),
  an elastic stick spring and return mapping (below).
- :class:`StribeckFriction`: μ(|w|) of seed 004 eq. 4 with the static and dynamic levels μ_s, μ_d
  and the transition velocities v_s < v_d, f = −μ(|w|) F w/|w|.
- :class:`TableFriction`: μ(p, T, Ω) of an operating condition (brake pressure scale p, disc
  temperature T, disc speed Ω), interpolated bilinearly in (T, Ω) and linearly in p in a table
  (the operating matrix's friction law; :func:`operating_mu` evaluates the constant and Stribeck
  laws at a condition too).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from fem_squeal.util.errors import ModelError

__all__ = ["FRICTION_LAWS", "ConstantFriction", "CoulombState", "ElasticCoulomb", "FrictionLaw", "FrictionState",
           "StribeckFriction", "TableFriction", "bilinear", "operating_mu", "smooth_step"]


def _check(name: str, value, positive: bool = False) -> None:
    v = np.asarray(value, float)
    bad = ~np.isfinite(v) | ((v <= 0) if positive else (v < 0))
    if np.any(bad):
        raise ModelError(f"friction law {name}: must be finite and {'> 0' if positive else '>= 0'} "
                         f"(got {np.min(v):g})")


def _col(a, ndim: int) -> np.ndarray:
    a = np.asarray(a, float)
    return a.reshape(a.shape + (1,) * (ndim - a.ndim)) if a.ndim else a


def smooth_step(x: np.ndarray, x0: float | np.ndarray, h0: float | np.ndarray, x1: float | np.ndarray,
                h1: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cubic STEP(x, x₀, h₀, x₁, h₁) of seed 004 eq. 4 (h₀ before x₀, h₁ after x₁,
    h₀ + (h₁ − h₀) a²(3 − 2a) between, a = (x − x₀)/(x₁ − x₀)) and its derivative."""
    a = np.clip((x - x0) / (x1 - x0), 0.0, 1.0)
    h = h0 + (h1 - h0) * a * a * (3.0 - 2.0 * a)
    dh = np.where((a > 0) & (a < 1), (h1 - h0) * 6.0 * a * (1.0 - a) / (x1 - x0), 0.0)
    return h, dh


class FrictionState:
    """History a law carries from step to step (elastic slip and stick flags); None if none."""


@dataclass(frozen=True)
class ConstantFriction:
    """f = μF V̂ (constant-μ sliding along the counter-face velocity V, as in the CEA)."""

    mu: np.ndarray | float

    def __post_init__(self):
        _check("mu", self.mu)

    def initial_state(self, n: int, n_dir: int):
        return None

    def evaluate(self, F, w, V, dw_disp, state):
        """(f, ∂f/∂F, ∂f/∂Δs, ∂f/∂w, new state); shapes (n, d), (n, d), (n, d, d) or None."""
        n, d = V.shape
        speed = np.linalg.norm(V, axis=1, keepdims=True)
        vhat = np.divide(V, speed, out=np.zeros_like(V), where=speed > 0)
        dfdF = _col(self.mu, 2) * vhat
        return dfdF * F[:, None], dfdF, None, None, None


@dataclass(frozen=True)
class StribeckFriction:
    """μ(s) of seed 004 eq. 4 as a magnitude, s = |w|:

        μ(s) = μ_s (2a²(3 − 2a) − 1), a = (s + v_s)/(2v_s)    for s < v_s  (μ(0) = 0, μ(v_s) = μ_s)
        μ(s) = STEP(s, v_s, μ_s, v_d, μ_d)                      for v_s ≤ s < v_d
        μ(s) = μ_d                                              for s ≥ v_d

    and f = −μ(s) F w/s (μ(s)/s → μ'(0) = 3μ_s/(2v_s) as s → 0, so f is smooth through w = 0:
    there is no true stick, only creep below v_s)."""

    mu_s: np.ndarray | float
    mu_d: np.ndarray | float
    v_s: np.ndarray | float
    v_d: np.ndarray | float

    def __post_init__(self):
        _check("mu_s", self.mu_s)
        _check("mu_d", self.mu_d)
        _check("v_s", self.v_s, positive=True)
        _check("v_d", self.v_d, positive=True)
        if np.any(np.asarray(self.v_d, float) <= np.asarray(self.v_s, float)):
            raise ModelError("friction law v_d: must be > v_s (the static level is reached first)")

    def initial_state(self, n: int, n_dir: int):
        return None

    def coefficient(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """μ(s) and μ'(s) for s ≥ 0."""
        mu_s, mu_d = np.asarray(self.mu_s, float), np.asarray(self.mu_d, float)
        v_s, v_d = np.asarray(self.v_s, float), np.asarray(self.v_d, float)
        low, dlow = smooth_step(s, -v_s, -mu_s, v_s, mu_s)
        mid, dmid = smooth_step(s, v_s, mu_s, v_d, mu_d)
        return np.where(s < v_s, low, mid), np.where(s < v_s, dlow, dmid)

    def evaluate(self, F, w, V, dw_disp, state):
        n, d = w.shape
        s = np.linalg.norm(w, axis=1)
        mu, dmu = self.coefficient(s)
        slope0 = 1.5 * np.asarray(self.mu_s, float) / np.asarray(self.v_s, float)
        tiny = s < 1e-12 * np.maximum(np.asarray(self.v_s, float), 1e-300)
        ratio = np.where(tiny, slope0, mu / np.where(tiny, 1.0, s))          # μ(s)/s
        what = np.divide(w, s[:, None], out=np.zeros_like(w), where=~tiny[:, None])
        dfdF = -ratio[:, None] * w
        # ∂(μ(s) w/s)/∂w = (μ/s) I + (μ' − μ/s) ŵŵᵀ
        J = ratio[:, None, None] * np.eye(d) + (np.where(tiny, slope0, dmu) - ratio)[:, None, None] * (
            what[:, :, None] * what[:, None, :])
        return dfdF * F[:, None], dfdF, None, -F[:, None, None] * J, None


@dataclass
class CoulombState:
    z: np.ndarray        # (n, d) elastic tangential displacement of the stick spring [m]
    stick: np.ndarray    # (n,) True where the element sticks


@dataclass(frozen=True)
class ElasticCoulomb:
    """Regularised Coulomb with a tangential stiffness k_t (seed 002 eq. 3).

    Each element carries an elastic stick spring of stiffness k_t [N/m] (and an optional
    Kelvin–Voigt damper c_t [N s/m] that damps its ringing); the spring extension z follows the
    relative displacement Δs = T Δq − VΔt of the step.  Trial force f* = −k_t(z + Δs) − c_t w;

        stick  (f = f*,  z ← z + Δs)           while |f*| ≤ μ F  (μ = μ_s if it stuck, else μ_d)
        slip   (f = μ_d F f*/|f*|, z = −f/k_t)  otherwise (return mapping)

    which is seed 002's "f_t = k_t w_s while k_t|w_s| ≤ μ f_n, μ f_n beyond", read with w_s the
    elastic slip (the inequality as printed, μ·w_s ≤ k_t·f_n, is not dimensionally consistent;
    this reading makes f_t continuous at the switch).  With μ_s > μ_d a sliding element re-sticks
    only when its slip stops, and breaks loose at μ_s F: the static/dynamic stick–slip of a belt.
    Without c_t the stick spring rings undamped after every stick onset (its frequency is
    √(k_t/m) for a mass m); that ringing is part of the regularised model, not of Coulomb's."""

    mu_s: np.ndarray | float
    mu_d: np.ndarray | float
    k_t: np.ndarray | float
    c_t: np.ndarray | float = 0.0

    def __post_init__(self):
        _check("mu_s", self.mu_s)
        _check("mu_d", self.mu_d)
        _check("k_t", self.k_t, positive=True)
        _check("c_t", self.c_t)
        if np.any(np.asarray(self.mu_d, float) > np.asarray(self.mu_s, float)):
            raise ModelError("friction law mu_d: must be <= mu_s")

    def initial_state(self, n: int, n_dir: int) -> CoulombState:
        return CoulombState(np.zeros((n, n_dir)), np.zeros(n, bool))

    def evaluate(self, F, w, V, dw_disp, state: CoulombState):
        """(f, ∂f/∂F, ∂f/∂Δs, ∂f/∂w, new state)."""
        n, d = dw_disp.shape
        kt = np.broadcast_to(np.asarray(self.k_t, float), (n,))
        ct = np.broadcast_to(np.asarray(self.c_t, float), (n,))
        z_trial = state.z + dw_disp
        trial = -kt[:, None] * z_trial - ct[:, None] * w
        mag = np.linalg.norm(trial, axis=1)
        limit = np.where(state.stick, np.asarray(self.mu_s, float), np.asarray(self.mu_d, float)) * F
        stick = mag <= limit
        mu_d = np.broadcast_to(np.asarray(self.mu_d, float), (n,))
        safe = np.where(mag > 0, mag, 1.0)
        dirn = trial / safe[:, None]
        f = np.where(stick[:, None], trial, (mu_d * F)[:, None] * dirn)
        dfdF = np.where(stick[:, None], 0.0, mu_d[:, None] * dirn)
        # slip: ∂(μF f*/|f*|)/∂f* = μF/|f*| (I − n̂n̂ᵀ); stick: ∂f/∂f* = I;  ∂f*/∂Δs = −k_t, ∂f*/∂w = −c_t
        eye = np.eye(d)
        P = np.where(stick[:, None, None], eye, (mu_d * F / safe)[:, None, None]
                     * (eye - dirn[:, :, None] * dirn[:, None, :]))
        new = CoulombState(np.where(stick[:, None], z_trial, -f / kt[:, None]), stick)
        return f, dfdF, -kt[:, None, None] * P, -ct[:, None, None] * P, new


class FrictionLaw(Protocol):
    """What the transient asks of a friction law: the friction force f of each element from its normal
    force F, its slip velocity w and the counter-face velocity V, with the derivatives its Newton needs,
    and the law's state (a stick spring's extension).  One sign convention: f opposes the slip."""

    def initial_state(self, n: int, n_dir: int):
        """The state of ``n`` elements with ``n_dir`` tangential directions (None: stateless)."""

    def evaluate(self, F, w, V, dw_disp, state):
        """(f, ∂f/∂F, ∂f/∂Δs, ∂f/∂w, new state)."""


class FrictionLawEntry(NamedTuple):
    """A friction law the scene can choose by name, and how its parameters come from the scene:
    ``make(mu, mu_s, mu_d, v_s, v_d, k_t, c_t)`` (``mu``: the scene's |μ|; ``mu_s``/``mu_d`` 0 = ``mu``)."""

    doc: str
    make: Callable[..., FrictionLaw]


#: the friction laws by their scene name (``analyses.transient.friction``); the first is the default
FRICTION_LAWS: dict[str, FrictionLawEntry] = {
    "constant": FrictionLawEntry("constant μ along the sliding direction (the CEA's sliding law; never "
                                 "reverses, so it cannot bound a cycle by stick-slip)",
                                 lambda mu, mu_s, mu_d, v_s, v_d, k_t, c_t: ConstantFriction(mu)),
    "stribeck": FrictionLawEntry("Stribeck μ(v) (seed 004 eq. 4)",
                                 lambda mu, mu_s, mu_d, v_s, v_d, k_t, c_t:
                                 StribeckFriction(mu_s or mu, mu_d or mu, v_s, v_d)),
    "coulomb": FrictionLawEntry("elastic Coulomb with stick springs (seed 002 eq. 3)",
                                lambda mu, mu_s, mu_d, v_s, v_d, k_t, c_t:
                                ElasticCoulomb(mu_s or mu, mu_d or mu, k_t, c_t)),
}



def _interp_weights(axis: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lower index i, weight t of i + 1) of linear interpolation on an increasing ``axis`` (one value:
    i = 0, t = 0: the table does not depend on this variable)."""
    if axis.size == 1:
        return np.zeros(x.shape, int), np.zeros(x.shape)
    i = np.clip(np.searchsorted(axis, x, side="right") - 1, 0, axis.size - 2)
    return i, (x - axis[i]) / (axis[i + 1] - axis[i])


def bilinear(axis0: np.ndarray, axis1: np.ndarray, table: np.ndarray, x0: np.ndarray, x1: np.ndarray,
             layer: np.ndarray | None = None) -> np.ndarray:
    """The bilinear interpolant of ``table`` (len(axis0), len(axis1)) at (x0, x1), written in differences
    from the lower corner, v₀₀ + s(v₁₀ − v₀₀) + t(v₀₁ − v₀₀) + st(v₁₁ − v₁₀ − v₀₁ + v₀₀), so that a constant
    table returns its value bit for bit (an axis of one value: independent of that variable; no range
    check here).  ``layer``: ``table`` is (n_layers, len(axis0), len(axis1)), read in the layers given
    per point (a pressure layer of :class:`TableFriction`)."""
    i, s = _interp_weights(axis0, x0)
    j, t = _interp_weights(axis1, x1)
    i1 = np.minimum(i + 1, table.shape[-2] - 1)
    j1 = np.minimum(j + 1, table.shape[-1] - 1)
    at = (lambda a, b: table[a, b]) if layer is None else (lambda a, b: table[layer, a, b])  # noqa: E731
    m00, m10, m01, m11 = at(i, j), at(i1, j), at(i, j1), at(i1, j1)
    return m00 + s * (m10 - m00) + t * (m01 - m00) + s * t * (m11 - m10 - m01 + m00)


@dataclass(frozen=True)
class TableFriction:
    """μ(p, T, Ω) at an operating condition: bilinear in a table over the disc temperature T and the disc
    speed |Ω| [rad/s] (the operating matrix's variables, not the local slip velocity), and linear between
    pressure layers when the table has a ``pressure`` axis (p: the scale of the scene's loads.pressure):

        μ(T, Ω) = μ₀₀ + s(μ₁₀ − μ₀₀) + t(μ₀₁ − μ₀₀) + st(μ₁₁ − μ₁₀ − μ₀₁ + μ₀₀)
        s = (T − T_i)/(T_{i+1} − T_i),  t = (|Ω| − Ω_j)/(Ω_{j+1} − Ω_j),  μ_ab = μ[i+a, j+b]
        μ(p, T, Ω) = μ_k(T, Ω) + r (μ_{k+1}(T, Ω) − μ_k(T, Ω)),  r = (p − p_k)/(p_{k+1} − p_k)

(the interpolants written in differences, so that a constant table returns its value exactly; the
trilinear interpolant of a 3-D table).  Without ``pressure``, ``mu`` has shape (n_T, n_Ω); with it,
(n_p, n_T, n_Ω) (one (T, Ω) table per pressure).

    An axis of one value means "independent of this variable" (any value is accepted); a condition
    outside an axis of two or more values is a :class:`ModelError` naming the variable and the range
    (no extrapolation).  ``name`` prefixes the messages (the scene key)."""

    temperature: np.ndarray
    speed: np.ndarray
    mu: np.ndarray
    name: str = "friction table"
    pressure: np.ndarray | None = None

    def __post_init__(self):
        T, V = (np.atleast_1d(np.asarray(a, float)) for a in (self.temperature, self.speed))
        axes = [("temperature", T), ("speed", V)]
        P = None
        if self.pressure is not None:
            P = np.atleast_1d(np.asarray(self.pressure, float))
            axes.insert(0, ("pressure", P))
        mu = np.asarray(self.mu, float)
        for key, a in axes:
            if a.ndim != 1 or a.size == 0 or not np.all(np.isfinite(a)):
                raise ModelError(f"{self.name}.{key}: must be a non-empty list of finite numbers "
                                 f"(got {a.tolist()})")
            if np.any(np.diff(a) <= 0):
                raise ModelError(f"{self.name}.{key}: must be strictly increasing (got {a.tolist()})")
        if np.any(V < 0):
            raise ModelError(f"{self.name}.speed: must be >= 0 (the disc speed |Ω|; got {V.tolist()})")
        if P is not None and np.any(P <= 0):
            raise ModelError(f"{self.name}.pressure: must be > 0 (scales of loads.pressure; got {P.tolist()})")
        if P is None:
            if mu.ndim == 1 and 1 in (T.size, V.size):
                mu = mu.reshape(T.size, V.size) if mu.size == T.size * V.size else mu
            if mu.shape != (T.size, V.size):
                raise ModelError(f"{self.name}.mu: must have one row per temperature and one column per speed, "
                                 f"shape ({T.size}, {V.size}) (got {mu.shape})")
        elif mu.shape != (P.size, T.size, V.size):
            raise ModelError(f"{self.name}.mu: with a pressure axis, one (temperature × speed) table per "
                             f"pressure, shape ({P.size}, {T.size}, {V.size}) (got {mu.shape})")
        _check(f"{self.name}.mu", mu)
        object.__setattr__(self, "temperature", T)
        object.__setattr__(self, "speed", V)
        object.__setattr__(self, "mu", mu)
        object.__setattr__(self, "pressure", P)

    def check_range(self, temperature, speed, pressure=None) -> None:
        """Refuse conditions outside the table (ModelError naming the variable, the value and the range);
        a table with a pressure axis of two or more values needs the pressure."""
        checks = [("temperature", self.temperature, np.asarray(temperature, float)),
                  ("speed", self.speed, np.abs(np.asarray(speed, float)))]
        if self.pressure is not None and self.pressure.size > 1:
            if pressure is None:
                raise ModelError(f"{self.name}: the table depends on the pressure; a condition without one "
                                 f"cannot be evaluated")
            checks.insert(0, ("pressure", self.pressure, np.asarray(pressure, float)))
        for key, axis, x in checks:
            if axis.size > 1:
                out = (x < axis[0]) | (x > axis[-1]) | ~np.isfinite(x)
                if np.any(out):
                    raise ModelError(f"{self.name}: {key} {x[out].ravel()[0]:g} is outside the table's range "
                                     f"[{axis[0]:g}, {axis[-1]:g}]")

    def coefficient(self, temperature, speed, pressure=None) -> np.ndarray:
        """μ at the conditions (p, T, Ω) (arrays broadcast together; ``pressure`` needed only by a table
        with a pressure axis of two or more values); the range is checked first."""
        if pressure is None:
            T, V = np.broadcast_arrays(np.asarray(temperature, float), np.abs(np.asarray(speed, float)))
            p = None
        else:
            T, V, p = np.broadcast_arrays(np.asarray(temperature, float), np.abs(np.asarray(speed, float)),
                                          np.asarray(pressure, float))
        self.check_range(T, V, p)
        if self.pressure is None:
            return bilinear(self.temperature, self.speed, self.mu, T, V)
        if p is None:
            p = np.full(T.shape, self.pressure[0])
        k, r = _interp_weights(self.pressure, p)
        k1 = np.minimum(k + 1, self.mu.shape[0] - 1)
        lo = bilinear(self.temperature, self.speed, self.mu, T, V, layer=k)
        hi = bilinear(self.temperature, self.speed, self.mu, T, V, layer=k1)
        return lo + r * (hi - lo)



def operating_mu(law, temperature, speed, radius: float = 0.0, pressure=None) -> np.ndarray:
    """|μ| of a friction law at operating conditions (p, T, Ω): a :class:`ConstantFriction`'s μ, a
    :class:`StribeckFriction`'s μ(V) at the sliding speed V = |Ω| r (``radius`` r [m] > 0), a
    :class:`TableFriction`'s μ(p, T, Ω) (range checked; ``pressure``: the scale of loads.pressure, needed
    by a table with a pressure axis)."""
    T, V = np.broadcast_arrays(np.asarray(temperature, float), np.abs(np.asarray(speed, float)))
    if isinstance(law, TableFriction):
        return law.coefficient(T, V) if pressure is None else law.coefficient(T, V, pressure)
    if isinstance(law, ConstantFriction):
        return np.broadcast_to(np.asarray(law.mu, float), T.shape).copy()
    if isinstance(law, StribeckFriction):
        if not radius > 0:
            raise ModelError(f"friction law radius: must be > 0 for a Stribeck law at a disc speed (got {radius})")
        return law.coefficient(V * radius)[0]
    raise ModelError(f"friction law: {type(law).__name__} has no coefficient at an operating condition")
