"""A contact interface's rows restricted to the basis: the one reduced contact type.

Rows are contact points (slave quadrature points, in a rank-independent order) or elements (patches
of points, :func:`fem_squeal.reduced.masa.aggregate`).  With coordinates q on the basis Φ, row j has

    δ_j = d0_j + D_j q      D = −G_nΦ  (closure: > 0 closed; d0 = −gap₀, the undeformed closure)
    s_j = T_j q             T[0] = G_t₁Φ along the sliding direction, T[1] = G_t₂Φ across it (t₂ = n × t₁)

The same rows serve the linear reduced model (penalties k_n, k_t and μ of the interface, the preload
state: :meth:`ContactRows.normal_stiffness` and the other matrices of
:class:`fem_squeal.reduced.model.ReducedModel`), MASA (a normal law and the signed μ at the analysed
point: B = D − μT[0]) and the transient (normal and friction laws, counter-face velocity V, lever arm).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from fem_squeal.util.errors import ModelError


@dataclass
class ContactRows:
    """One contact interface on the basis (module docstring).  Every field but D and T is optional:
    the reduction fills the penalties and the preload state, MASA the normal law and μ, the transient
    the laws, V and the lever arm."""

    D: np.ndarray                          # (n, m) closure per unit q (= −G_nΦ)
    T: np.ndarray                          # (d, n, m), d = 1 or 2 (an (n, m) array: d = 1): tangential rows
    d0: np.ndarray | None = None           # (n,) closure at q = 0 (= −gap₀) [m]
    weight: np.ndarray | None = None       # (n,) quadrature weights or element areas [m²]
    x: np.ndarray | None = None            # (n, 3) coordinates
    name: str = "contact"
    kn: float = 0.0                        # normal penalty [N/m³]
    kt: float = 0.0                        # tangential penalty [N/m³]
    mu: float = 0.0                        # signed friction coefficient sign(v)μ along T[0]
    sliding: float = 0.0                   # the interface slides (≠ 0) along T[0]
    gap: np.ndarray | None = None          # (n,) static gap at the preload (< 0: closed)
    active: np.ndarray | None = None       # (n,) closed at the preload
    pressure: np.ndarray | None = None     # (n,) contact pressure at the preload [Pa]
    normal: object | None = None           # normal law F(δ, δ̇) (fem_squeal.reduced.laws.contact)
    friction: object | None = None         # friction law (fem_squeal.reduced.laws.friction), None: none
    V: np.ndarray | None = None            # (n, d) counter-face velocity along T [m/s] (None: at rest)
    radius: np.ndarray | None = None       # (n,) lever arm about the disc axis (braking torque Σ r f)

    def __post_init__(self):
        self.D = np.asarray(self.D, float)
        n, m = self.D.shape
        T = np.asarray(self.T, float)
        self.T = T[None] if T.ndim == 2 else T
        if self.T.shape[1:] != (n, m) or self.T.shape[0] not in (1, 2):
            raise ModelError(f"{self.name}.T: shape {T.shape}, expected ({n}, {m}) or (d, {n}, {m}), d = 1, 2")
        for f in ("d0", "weight", "gap", "active", "pressure", "radius"):
            if getattr(self, f) is not None and np.shape(getattr(self, f)) != (n,):
                raise ModelError(f"{self.name}.{f}: shape {np.shape(getattr(self, f))}, expected ({n},)")
        if self.x is not None and np.shape(self.x)[:1] != (n,):
            raise ModelError(f"{self.name}.x: {np.shape(self.x)[0]} coordinates for {n} rows")
        if not np.isfinite(self.mu):  # signed: sign(v)μ, < 0 for backward sliding
            raise ModelError(f"{self.name}.mu: must be finite (got {self.mu})")
        d = self.n_dir
        self.V = np.zeros((n, d)) if self.V is None else np.broadcast_to(np.asarray(self.V, float), (n, d)).copy()
        if not np.all(np.isfinite(self.V)):
            raise ModelError(f"{self.name}.V: counter-face velocities must be finite")

    @property
    def size(self) -> int:
        return self.D.shape[0]

    @property
    def n_dir(self) -> int:
        return self.T.shape[0]

    def closure(self, q: np.ndarray) -> np.ndarray:
        """δ = d0 + D q."""
        return self.d0 + self.D @ q

    @cached_property
    def B(self) -> np.ndarray:
        """D − μT[0], formed once: the normal push plus the friction drag μF of the sliding
        counter-face (MASA's Newton residuals and state matrices)."""
        return self.D - self.mu * self.T[0]

    # ---- the gap convention of the reduction (G_nΦ, G_t₁Φ, G_t₂Φ, gap₀)
    @property
    def Gn(self) -> np.ndarray:
        """G_nΦ = −D: normal gap rate per basis vector."""
        return -self.D

    @property
    def Gt(self) -> np.ndarray:
        """G_t₁Φ = T[0]: along the sliding direction."""
        return self.T[0]

    @property
    def Gt2(self) -> np.ndarray | None:
        """G_t₂Φ = T[1]: across the sliding direction (None with one direction)."""
        return self.T[1] if self.n_dir == 2 else None

    @property
    def gap0(self) -> np.ndarray | None:
        """gap₀ = −d0: the gap of the undeformed geometry."""
        return None if self.d0 is None else -self.d0

    @property
    def law(self) -> object | None:
        """The normal law (MASA's name for it)."""
        return self.normal

    # ---- the linearised penalty at the preload (fem_squeal.reduced.model)
    def closed_weight(self) -> np.ndarray:
        """w a: the quadrature weights of the points closed at the preload (0 at the open ones)."""
        return self.weight * np.asarray(self.active, bool)

    def normal_stiffness(self, wa: np.ndarray | None = None) -> np.ndarray:
        """K_c = (G_nΦ)ᵀ diag(k_n w a) (G_nΦ): the closed-contact stiffness at the nominal k_n (``wa``: the
        closed weights w a to use, :meth:`closed_weight` when not given)."""
        wa = self.closed_weight() if wa is None else wa
        Gn = self.Gn
        return Gn.T @ ((self.kn * wa)[:, None] * Gn)

    def friction_stiffness(self, wa: np.ndarray | None = None) -> np.ndarray:
        """K_f¹ = (G_sΦ)ᵀ diag(k_n w a) (G_nΦ): the friction stiffness for μ = 1 at the nominal k_n."""
        wa = self.closed_weight() if wa is None else wa
        return self.Gt.T @ ((self.kn * wa)[:, None] * self.Gn)

    def tangential_stiffness(self, wa: np.ndarray | None = None) -> np.ndarray | None:
        """K_t¹ for k_t = 1: (G_t₂Φ)ᵀ diag(w a) (G_t₂Φ), + (G_t₁Φ)ᵀ diag(w a) (G_t₁Φ) without sliding
        (None when G_t₂Φ was not stored: a model saved before k_t became a parameter)."""
        if self.Gt2 is None:
            return None
        wa = (self.closed_weight() if wa is None else wa)[:, None]
        T = self.Gt2.T @ (wa * self.Gt2)
        return T if self.sliding != 0 else T + self.Gt.T @ (wa * self.Gt)

    def stiffness_change(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(ΔK_c, ΔK_f¹ or None without sliding, ΔK_t¹ or None): the change of the three matrices above from
        the preload's closed points to those flagged ``active``, the same forms with the weights
        w (a − a₀) (exact: they are linear in the weights; only the rows that opened or closed enter)."""
        changed = np.flatnonzero(np.asarray(active, bool) != np.asarray(self.active, bool))
        sub = ContactRows(D=self.D[changed], T=self.T[:, changed], weight=self.weight[changed], kn=self.kn,
                          sliding=self.sliding, active=np.ones(changed.size, bool), name=self.name)
        wa = np.where(np.asarray(active, bool)[changed], 1.0, -1.0) * sub.weight
        return (sub.normal_stiffness(wa), sub.friction_stiffness(wa) if self.sliding != 0 else None,
                sub.tangential_stiffness(wa))

    @property
    def has_kt(self) -> bool:
        """k_t is a parameter (G_t₂Φ stored)."""
        return self.n_dir == 2


def check_columns(sets, m: int, error: type[Exception]) -> None:
    """Every set of rows in ``sets`` has ``m`` columns (the model's DOFs: its basis vectors), else ``error``."""
    for cs in sets:
        if cs.D.shape[1] != m:
            raise error(f"{cs.name}: rows have {cs.D.shape[1]} columns, the model has {m} DOFs")


def checked_rows(error: type[Exception], **fields) -> ContactRows:
    """ContactRows(**fields), a refused field raised as ``error`` (the caller's error class)."""
    try:
        return ContactRows(**fields)
    except ModelError as e:
        raise error(str(e)) from e


def from_gap_rows(Gn: np.ndarray, Gt: np.ndarray, weight: np.ndarray, kn: float, mu: float, sliding: float,
                  gap: np.ndarray, active: np.ndarray, gap0: np.ndarray | None = None, x: np.ndarray | None = None,
                  pressure: np.ndarray | None = None, Gt2: np.ndarray | None = None, kt: float = 0.0,
                  name: str = "contact") -> ContactRows:
    """The rows of the reduction from the restricted operators in the gap convention: D = −G_nΦ,
    T = [G_t₁Φ, G_t₂Φ] (G_t₁Φ alone without G_t₂Φ), d0 = −gap₀."""
    T = np.stack([Gt, Gt2]) if Gt2 is not None else Gt
    return ContactRows(D=-np.asarray(Gn, float), T=T, d0=None if gap0 is None else -np.asarray(gap0, float),
                       weight=weight, x=x, name=name, kn=kn, kt=kt, mu=mu, sliding=sliding, gap=gap,
                       active=active, pressure=pressure)
