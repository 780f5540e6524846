"""Eigenvalue sensitivities of the reduced model: dλ/dp from the left and right eigenvectors.

For Q(λ, p) = λ²M + λC(p) + K(p) with Q x = 0 and yᴴQ = 0 (a simple eigenvalue), differentiating
yᴴQ(λ(p), p)x = 0 gives

    dλ/dp = −yᴴ(λ²∂M/∂p + λ∂C/∂p + ∂K/∂p)x / yᴴ(2λM + C)x.

On the affine reduced model (:mod:`fem_squeal.reduced.model`) M = I and the derivatives are
matrices of the model (:meth:`~fem_squeal.reduced.model.ReducedModel.derivative`):  ∂K/∂μ = K_f¹,
∂C/∂μ = 0;  ∂K/∂E_i = (1 + iη_i) K_i/E_i⁰, ∂C/∂E_i = β_i K_i/E_i⁰;  ∂K/∂η_i = iθ_i K_i;  per contact
c: ∂K/∂μ_c = s_c K_f,c¹, ∂K/∂k_n,c = (K_c,c + μ_c K_f,c¹)/k_n,c⁰, ∂K/∂k_t,c = K_t,c¹.
The formula is exact to first order, so for a parameter that enters linearly in λ it is exact
(the Ryzhik ring pair: Re λ ∝ μ to O(g²), tested against the closed form of eq. 10).

**Coalescence.**  At an exceptional point (two eigenvalues and their eigenvectors coalesce, the
onset of mode-coupling flutter) yᴴ(2λ + C)x → 0: λ(p) has a square-root branch and dλ/dp is
infinite.  Its approach is measured by the *local* condition number

    κ_loc(λ) = 2|λ| ‖x‖ ‖y‖ / |yᴴ(2λI + C)x|,

which is 1 for every mode of an undamped symmetric model (y = x) and is, undamped, Wilkinson's
condition number ‖x‖‖y‖/|yᴴx| of θ = −λ² as an eigenvalue of K.  The Tisseur condition number of
:func:`fem_squeal.reduced.eigensolve.condition_numbers` carries in addition the factor
(|λ|² + |λ|‖C‖ + ‖K‖)/(2|λ|²), which grows as (f_max/f)² for a low mode of a wide basis without
any coalescence; it is reported beside κ_loc but not used for the flag.  For a pair of modes
driven towards coalescence by a parameter p (a 2×2 block, the Hoffmann model) κ_loc ≈ c/√(2Δ)
with Δ = |p − p_c|/p_c the relative distance to the exceptional point and c of order one (1 for
a symmetric coupling, 0.79 for the two-DOF Hoffmann model: tests/unit/reduced/test_sensitivity.py), and the
first-order prediction λ + h dλ/dp over a relative step h has a relative error ≈ h/(4Δ) of the change.  The
default threshold κ_loc > 10 (:data:`KAPPA_COALESCENCE`) flags a mode within Δ ≈ 0.3–0.5 % of a
coalescence: there a 1 % change of the parameter (the scatter of a robustness study) already
crosses the branch point and the derivative does not describe λ(p); the number is then not
reported (None) and the mode is marked ``near_coalescence``.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fem_squeal.reduced.eigensolve import TWO_PI, eig_left_right, unstable
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.util.errors import ModelError

#: flag a mode as near a coalescence when κ_loc exceeds this (Δ ≈ c²/(2κ²) ≈ 0.3–0.5 %: module docstring)
KAPPA_COALESCENCE = 10.0


@dataclass
class ModeSensitivity:
    """dλ/dp of one eigenvalue at the nominal point (None where it is near a coalescence)."""

    index: int                      # position in the model's sorted eigenvalues (quadratic_eigs order)
    eigenvalue: complex
    kappa_local: float
    kappa: float                    # Tisseur's condition number (condition_numbers)
    near_coalescence: bool
    d_lambda: dict[str, complex]    # dλ/dp for every parameter

    @property
    def freq_hz(self) -> float:
        return float(self.eigenvalue.imag / TWO_PI)

    def as_dict(self, values: dict[str, float]) -> dict:
        """The results.json record: derivatives of Re λ [1/s per unit of p] and of f [Hz per unit of
        p], and the relative forms p ∂/∂p (the change per 100 % of p); None near a coalescence."""
        near = self.near_coalescence
        d_re = {p: None if near else float(d.real) for p, d in self.d_lambda.items()}
        d_f = {p: None if near else float(d.imag / TWO_PI) for p, d in self.d_lambda.items()}
        return {"index": self.index, "freq_hz": self.freq_hz, "real_part": float(self.eigenvalue.real),
                "kappa_local": self.kappa_local, "kappa": self.kappa, "near_coalescence": near,
                "d_real_part": d_re, "d_freq_hz": d_f,
                "rel_d_real_part": {p: None if v is None else v * values[p] for p, v in d_re.items()},
                "rel_d_freq_hz": {p: None if v is None else v * values[p] for p, v in d_f.items()}}


def parameter_derivatives(model: ReducedModel, name: str, point: dict[str, float] | None = None
                          ) -> tuple[np.ndarray, np.ndarray | None]:
    """(∂K/∂p, ∂C/∂p or None) of the affine reduced model for parameter ``name`` at ``point``."""
    return model.derivative(name, point)


def sensitivities(model: ReducedModel, point: dict[str, float] | None = None,
                  parameters: Sequence[str] | None = None, modes: Sequence[int] | None = None,
                  kappa_max: float = KAPPA_COALESCENCE) -> list[ModeSensitivity]:
    """dλ/dp for the eigenvalues ``modes`` (indices into the sorted eigenvalues; None: all) at
    ``point`` (default nominal) for ``parameters`` (default: every parameter of the model)."""
    point = point or {}
    parameters = list(model.parameters if parameters is None else parameters)
    model._check(list(parameters) + list(point))
    if not kappa_max > 1:
        raise ModelError(f"kappa_max: must be > 1 (got {kappa_max})")
    K, C = model.matrices({k: np.array([v], float) for k, v in point.items()}, 1)
    K, C = K[0], None if C is None else C[0]
    lam, X, Y = eig_left_right(K, C)
    idx = range(lam.size) if modes is None else [int(i) for i in modes]
    derivs = {p: parameter_derivatives(model, p, point) for p in parameters}
    Cm = np.zeros_like(K) if C is None else C
    nK, nC = np.linalg.norm(K, 2), np.linalg.norm(Cm, 2)
    out = []
    for i in idx:
        if not 0 <= i < lam.size:
            raise ModelError(f"modes: index {i} out of range 0..{lam.size - 1}")
        li, x, y = lam[i], X[:, i], Y[:, i]
        den = np.vdot(y, 2 * li * x + Cm @ x)
        nxy = np.linalg.norm(x) * np.linalg.norm(y)
        al = abs(li)
        kloc = float(2 * al * nxy / abs(den)) if den != 0 else np.inf
        kap = float((al ** 2 + al * nC + nK) * nxy / (al * abs(den))) if den != 0 and al > 0 else np.inf
        d = {}
        for p, (dK, dC) in derivs.items():
            num = np.vdot(y, dK @ x + (li * (dC @ x) if dC is not None else 0.0))
            d[p] = complex(-num / den) if den != 0 else complex(np.inf)
        out.append(ModeSensitivity(i, complex(li), kloc, kap, bool(kloc > kappa_max), d))
    return out


def parameter_values(model: ReducedModel, point: dict[str, float] | None = None) -> dict[str, float]:
    """The value of every parameter at ``point`` (nominal where not given)."""
    point = point or {}
    return {k: float(point.get(k, v)) for k, v in model.nominal().items()}


def ranking(record: dict) -> list[tuple[str, float]]:
    """Parameters of one results.json record by |p ∂Re λ/∂p|, largest first ([] near a coalescence)."""
    rel = {p: v for p, v in record["rel_d_real_part"].items() if v is not None}
    return sorted(rel.items(), key=lambda kv: -abs(kv[1]))


def band_records(model, lam: np.ndarray, band_hz: Sequence[float], growth_tol: float, which: str,
                 params: Sequence[str], kappa_max: float) -> tuple[list, list[dict]]:
    """The sensitivities of the modes of ``lam`` (the nominal eigenvalues of ``model``) in ``band_hz``
    (``which`` = "unstable": only those with Re λ > ``growth_tol``) to ``params``, and their records for
    results.json: :meth:`Sensitivity.as_dict` at the parameters' values, ``unstable``, and ``ranking``
    (the parameters by |dλ/dp|·|p|, :func:`ranking`)."""
    f = lam.imag / TWO_PI
    inside = (f >= band_hz[0]) & (f <= band_hz[1])
    pick = inside & unstable(lam, growth_tol) if which == "unstable" else inside
    sens = sensitivities(model, None, params, np.flatnonzero(pick), kappa_max)
    values = parameter_values(model)
    records = []
    for x in sens:
        r = x.as_dict({p: values[p] for p in params})
        r["unstable"] = bool(unstable(np.array([x.eigenvalue]), growth_tol)[0])
        r["ranking"] = [p for p, _ in ranking(r)]
        records.append(r)
    return sens, records
