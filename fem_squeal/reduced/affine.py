"""The affine parameter form of the operators, defined once:

K(p) = K₀ + μ K_f¹ + Σᵢ (θᵢ − 1) Kᵢ + i Σᵢ ηᵢ θᵢ Kᵢ                 θᵢ = Eᵢ/Eᵢ⁰, ηᵢ part i's loss factor
       + Σ_c [(s_c − 1) K_c,c + (μ_c s_c − μ_c^μ) K_f,c¹ + (k_t,c − k_t,c⁰) K_t,c¹]     s_c = k_n,c/k_n,c⁰
       + Ω² K₂ + (s − 1) K_σ,s                                                s = ``pressure``
C(p) = C₀ + Σᵢ βᵢ (θᵢ − 1) Kᵢ + Ω G₁ + (|μ|/|μ⁰|)(Ω₀/Ω) (C_d + (s − 1) C_d,s)

μ_c^μ = μ·μ_c⁰/μ⁰ is what ``mu`` gives interface c, μ_c = ``mu.<c>`` where given (else μ_c^μ): the
interface terms vanish at the nominal point and where an interface's parameters are not given.  The
meaning of every matrix is in :mod:`fem_squeal.reduced.model`.  Here: the parameter names, their
ranges and the coefficient of every term as a function of the parameter values (numbers, or arrays of
points).  The reduced model (:class:`fem_squeal.reduced.model.ReducedModel`) applies them to its
projected matrices, :class:`fem_squeal.fe.projection.ParametricOperators` to the full ones, term by
term (there K_f = μ⁰K_f¹ and C₀ holds C_d: coefficients μ/μ⁰ and the damping scale − 1; and the
stress stiffening and the friction damping at a pressure s are assembled from the preload state at s, not
from the affine terms).

An operator given as an expression of named matrices (a ``[matrices]`` scene,
:mod:`fem_squeal.reduced.expressions`) has the same form with its own terms: A(p) = Σ_k c_k(p) A_k,
an :class:`AffineOperator` of :class:`AffineTerm` (the coefficient c_k a function of the parameter
values, the matrix A_k by name).
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from fem_squeal.util.errors import ModelError, UnknownNameError

MU = "mu"
#: the disc speed Ω [rad/s] (issue 20 item 6): G ∝ Ω, K_σc − S ∝ Ω², friction damping ∝ |μ|/Ω
SPEED = "speed"
#: the brake pressure as a scale s of the scene's ``loads.pressure`` (issue 39): with the contact set of the
#: scene and the linear penalty the preload u(s) is affine in s, so its stress stiffening K_σ(u(s)) and the
#: friction damping C_d(p(s)) (∝ the contact pressure) are too; where the continued preloads open or close
#: contact points the model holds each pressure's contact state (``ReducedModel.contact_states``)
PRESSURE = "pressure"
#: prefixes of the per-part and per-interface parameters: ``<prefix>.<part or interface>``
PART_PREFIXES = ("E", "eta")
INTERFACE_PREFIXES = ("mu", "kn", "kt")
#: parameters that must be > 0 (the others of a range: >= 0)
_POSITIVE = ("E", "kn", PRESSURE)
_NON_NEGATIVE = ("eta", "kt", SPEED)


def e_param(part: str) -> str:
    """Name of the parameter that sets part ``part``'s Young's modulus [Pa]."""
    return f"E.{part}"


def eta_param(part: str) -> str:
    """Name of the parameter that sets part ``part``'s loss factor η (structural damping K(1 + iη))."""
    return f"eta.{part}"


def split_param(name: str) -> tuple[str, str | None]:
    """('mu', None) for ``mu``, (prefix, target) for ``<prefix>.<part or interface>``."""
    prefix, dot, target = name.partition(".")
    return (prefix, target) if dot else (prefix, None)


def parameter_names(parts: Iterable[str], interfaces: Mapping[str, object], *, mu: bool = True,
                    eta_parts: Iterable[str] | None = None, kt_interfaces: Iterable[str] | None = None,
                    speed: bool = False, pressure: bool = False) -> list[str]:
    """``mu`` (with friction), ``E.<part>``, ``mu.<c>`` (the sliding interfaces), ``kn.<c>``, ``kt.<c>``
    (``kt_interfaces``, default all), ``eta.<part>`` (``eta_parts``, default all), ``speed``, ``pressure``."""
    parts = list(parts)
    out = ([MU] if mu else []) + [e_param(p) for p in parts]
    out += [f"mu.{c}" for c, it in interfaces.items() if it.sliding != 0]
    out += [f"kn.{c}" for c in interfaces]
    out += [f"kt.{c}" for c in (interfaces if kt_interfaces is None else kt_interfaces)]
    return out + [eta_param(p) for p in (parts if eta_parts is None else eta_parts)] + ([SPEED] if speed else []) \
        + ([PRESSURE] if pressure else [])


def check_names(names: Iterable[str], known: list[str], what: str = "") -> None:
    """Refuse a name that is not in ``known`` (the message lists them)."""
    unknown = sorted(set(names) - set(known))
    if unknown:
        raise UnknownNameError(f"{unknown[0]}: not a parameter{what}; parameters: {known}")


def check_range(name: str, value) -> None:
    """``E.<part>``, ``kn.<c>``, ``pressure`` > 0; ``eta.<part>``, ``kt.<c>``, ``speed`` >= 0 (a number or an array
    of points; other parameters take any value)."""
    prefix = split_param(name)[0]
    v = np.asarray(value, float)
    if prefix in _POSITIVE and np.any(~(v > 0)):
        raise ModelError(f"{name}: must be > 0 (got {np.min(v)})")
    if prefix in _NON_NEGATIVE and np.any(~(v >= 0)):
        raise ModelError(f"{name}: must be >= 0 (got {np.min(v)})")


def check_damping_speed(speed) -> None:
    """Ω > 0 where there is friction damping (C_d ∝ 1/Ω)."""
    if np.any(~(np.asarray(speed, float) > 0)):
        raise ModelError(f"{SPEED}: must be > 0 with friction damping (C_d ∝ 1/Ω; got {np.min(speed)})")


def friction_damping_scale(mu, mu0: float, speed, speed0: float):
    """(|μ|/|μ⁰|)(Ω₀/Ω): the factor of the friction damping C_d = ∫ p |μ|/|V| t₂t₂ᵀ ds (V = Ω r) of the
    nominal point at (μ, Ω), a constant friction law (with μ(V) the damping is not affine in Ω).  The
    signed μ (sign(v)μ) turns the friction force, not this damping: a transverse velocity turns the
    force towards −t₂ whichever way the counter-face slides.  Ω₀ = 0 (the nominal speed not known):
    |μ|/|μ⁰|, the damping of the nominal speed."""
    return (np.abs(mu) / abs(mu0)) * (speed0 / speed if speed0 else 1.0)


def pressure_coefficient(scale):
    """s − 1: the coefficient of the stress stiffening and the friction damping per unit pressure scale,
    K_σ,s = K_σ(du/ds) and C_d,s = C_d(dp/ds) (those of the scene's preload, s = 1, are in K₀ and C_d)."""
    return scale - 1.0


def modulus_coefficient(E, E0: float):
    """θ − 1 = E/E⁰ − 1: the coefficient of K_i (and, times β_i, of K_i in C)."""
    return E / E0 - 1.0


def loss_coefficient(eta, E, E0: float, unit: complex = 1.0):
    """unit·η θ: the coefficient of K_i in the loss stiffness (unit = i in the complex K(p); 1 for its
    imaginary part alone)."""
    return unit * eta * E / E0


def mu_share(mu_c: float, mu0: float, friction: bool) -> float:
    """μ_c⁰/μ⁰: what a unit ``mu`` gives interface c (0 without friction at the nominal point)."""
    return mu_c / mu0 if mu0 != 0 and friction else 0.0


def interface_coefficients(point: Mapping[str, object], name: str, kn0: float, kt0: float, mu, share: float
                           ) -> list[tuple[int, object]]:
    """[(j, coefficient)] of interface ``name``'s terms j = 0: K_c (s − 1), 1: K_f¹ (μ_c s − μ_c^μ, or
    μ_c^μ(s − 1) where ``mu.<name>`` is not given), 2: K_t¹ (k_t − k_t⁰): only the terms that its given
    parameters (``point``'s ``mu.<name>``, ``kn.<name>``, ``kt.<name>``) change; μ_c^μ = ``mu``·share,
    k_n⁰, k_t⁰ its nominal penalties."""
    mu_key, kn_key, kt_key = f"mu.{name}", f"kn.{name}", f"kt.{name}"
    out = []
    s = point.get(kn_key, kn0) / kn0
    if kn_key in point:
        out.append((0, s - 1.0))
    if kn_key in point or mu_key in point:
        mu_default = mu * share
        out.append((1, point[mu_key] * s - mu_default if mu_key in point else mu_default * (s - 1.0)))
    if kt_key in point:
        out.append((2, point[kt_key] - kt0))
    return out


@dataclass(frozen=True)
class AffineTerm:
    """One term c(p) A of an affine operator: the coefficient ``coefficient(values)`` (numbers, or
    arrays of points, by parameter name), the parameters it reads and its text, and the matrix by name."""

    matrix: str
    coefficient: Callable[[Mapping[str, Any]], Any]
    parameters: frozenset[str] = frozenset()
    text: str = "1"
    #: ∂c/∂p: ``derivative(values, name)`` (None: not known; then :meth:`AffineOperator.derivatives` refuses)
    derivative: Callable[[Mapping[str, Any], str], Any] | None = None


@dataclass(frozen=True)
class AffineOperator:
    """A(p) = Σ_k c_k(p) A_k (``name``: what the operator is, e.g. ``K``; at most one term per matrix)."""

    name: str
    terms: tuple[AffineTerm, ...]

    @property
    def matrices(self) -> tuple[str, ...]:
        return tuple(t.matrix for t in self.terms)

    @property
    def parameters(self) -> frozenset[str]:
        """The parameters its coefficients read."""
        return frozenset().union(*(t.parameters for t in self.terms))

    def coefficients(self, values: Mapping[str, Any]) -> list:
        """c_k at ``values`` (every parameter the terms read), each checked finite (a ModelError names
        the operator, the matrix and the values where it is not)."""
        out = []
        for t in self.terms:
            with np.errstate(all="ignore"):
                c = t.coefficient(values)
            if not np.all(np.isfinite(c)):
                raise ModelError(f"{self.name}: the coefficient {t.text} of {t.matrix} is not a finite number at "
                                 f"{_first_bad_point(values, t.parameters, c) or 'every point'}")
            out.append(c)
        return out

    def derivatives(self, values: Mapping[str, Any], name: str) -> list:
        """∂c_k/∂p at ``values`` for the parameter ``name`` (0 for a term that does not read it), each
        checked finite."""
        out = []
        for t in self.terms:
            if name not in t.parameters:
                out.append(0.0)
                continue
            if t.derivative is None:
                raise ModelError(f"{self.name}: the derivative of the coefficient {t.text} of {t.matrix} is "
                                 "not known")
            with np.errstate(all="ignore"):
                d = t.derivative(values, name)
            if not np.all(np.isfinite(d)):
                raise ModelError(f"{self.name}: the derivative of the coefficient {t.text} of {t.matrix} with "
                                 f"respect to {name} is not a finite number at "
                                 f"{_first_bad_point(values, t.parameters | {name}, d)}")
            out.append(d)
        return out

    def evaluate(self, values: Mapping[str, Any], matrices: Mapping[str, Any]):
        """Σ_k c_k(values) A_k of the named ``matrices`` (SciPy sparse, NumPy arrays: anything with
        ``*`` by a number and ``+``) at one point.  Sparse matrices are summed on the union of their
        stored patterns, explicit zeros kept (SciPy's ``+`` drops them), each entry in the order of the
        terms: the sum of an exported model's terms is then its operator entry for entry, pattern and all
        (``fem-squeal export``)."""
        coefs = self.coefficients(values)
        mats = [matrices[t.matrix] for t in self.terms]
        if all(sp.issparse(A) for A in mats):
            parts = [sp.coo_matrix(A) for A in mats]
            data = np.concatenate([float(c) * A.data for c, A in zip(coefs, parts)])
            ij = (np.concatenate([A.row for A in parts]), np.concatenate([A.col for A in parts]))
            return sp.csr_matrix((data, ij), shape=parts[0].shape)
        total = None
        for c, t in zip(coefs, self.terms):
            term = float(c) * matrices[t.matrix]
            total = term if total is None else total + term
        return total

    def __str__(self) -> str:
        def factor(t: AffineTerm) -> str:
            if t.text == "1":
                return t.matrix
            simple = t.text.isidentifier() or t.text.replace(".", "", 1).isdigit()
            return f"{t.text}*{t.matrix}" if simple else f"({t.text})*{t.matrix}"
        return " + ".join(factor(t) for t in self.terms)


def _first_bad_point(values: Mapping[str, Any], names, c) -> str:
    """``"W = 0.0"``: each of the parameters ``names`` at the first point where the (possibly vectorised)
    value ``c`` is not finite, for a one-line error message."""
    c = np.asarray(c)
    i = int(np.flatnonzero(~np.isfinite(c))[0]) if c.ndim else 0
    at = []
    for k in sorted(names):
        v = np.asarray(values[k], float)
        x = v.ravel()[min(i, v.size - 1)] if v.shape != c.shape else v.ravel()[i]
        at.append(f"{k} = {float(x)!r}")
    return ", ".join(at)
