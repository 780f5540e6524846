"""Parametric (affine) reduced model of λ²M + λC + K on a mass-orthonormal basis.

K(p) = K₀ + Σᵢ (θᵢ − 1) Kᵢ + μ K_f¹          θᵢ = Eᵢ / Eᵢ⁰ (part i's Young's modulus scale)
       + i Σᵢ ηᵢ θᵢ Kᵢ                          ηᵢ part i's loss factor (structural damping Kᵢ(1 + iη))
       + Σ_c [(s_c − 1) K_c,c + (k_t,c − k_t,c⁰) K_t,c¹ + (μ_c s_c − μ_c^μ) K_f,c¹]
       + Ω² K₂                                   Ω the disc speed (``speed``), K₂ = K_σc − S
       + (s − 1) K_σ,s                           s the brake pressure (``pressure``, × loads.pressure)
C(p) = C₀ + Σᵢ βᵢ (θᵢ − 1) Kᵢ                 (stiffness-proportional damping follows E)
       + Ω G₁ + (|μ|/|μ⁰|)(Ω₀/Ω) (C_d + (s − 1) C_d,s)   (gyroscopic; friction damping p |μ|/V, V = Ω r)
M    = I                                       (the basis is M-orthonormal)

K₀ is the frictionless stiffness at the nominal parameters (elasticity, springs, closed contact),
Kᵢ the elastic stiffness of part i at its nominal modulus, K_f¹ the friction stiffness for μ = 1
in the scene's sliding direction, so that a signed μ (sign(v)μ, seed 001 Fig. 8) covers forward
(> 0) and backward (< 0) sliding.  Scaling "E" of a part scales its whole elasticity tensor.

**Parameters** (:attr:`ReducedModel.parameters`): ``mu`` (every interface that has friction at
the nominal point, together: the signed sweep parameter), ``E.<part>`` (the parts whose
stiffness Kᵢ the model carries), ``eta.<part>`` (those of them listed in ``eta0``, with their
nominal loss factor: :func:`fem_squeal.fe.projection.reduce` lists every carried part), and per
contact interface c: ``mu.<c>`` (its own
signed friction coefficient; it overrides ``mu`` for that interface), ``kn.<c>`` (its normal
penalty: s_c = k_n,c/k_n,c⁰ scales its closed-contact stiffness K_c,c and its friction stiffness,
which is μ k_n), ``kt.<c>`` (its tangential penalty, 0 allowed).  The interface matrices are
formed from the interface's restricted rows (:class:`~fem_squeal.reduced.contact_rows.ContactRows`)
at the preload's closed points: K_c,c = (G_nΦ)ᵀ diag(k_n w a) (G_nΦ), K_f,c¹ = (G_sΦ)ᵀ diag(k_n w a) (G_nΦ),
K_t,c¹ = (G_t₂Φ)ᵀ diag(w a) (G_t₂Φ) (+ the same along t₁ for a contact that does not slide), w the
quadrature weights and a the closed points: the contact state of the preload is kept (a change
of k_n does not re-solve the preload; the full-order check of
:class:`fem_squeal.fe.projection.ParametricOperators` makes the same assumption).  A named rigid
plate p (a bilateral penalty layer, always closed) has the same three parameters with its
projected face matrices (:class:`PlateProjection`): K_c,p = Φᵀ∫k_n (u·n)(v·n) ds Φ,
K_f,p¹ = −Φᵀ∫k_n (u·n)(v·s) ds Φ (with a friction law μ(V): of μ(V)/μ_p⁰), K_t,p¹ = Φᵀ∫(u·t₂)(v·t₂) ds Φ.
μ_c^μ = μ·μ_c⁰/μ⁰ is what ``mu`` gives interface c (μ_c⁰ its nominal coefficient), and μ_c =
``mu.<c>`` where given, else μ_c^μ: the terms vanish at the nominal point and where the interface
parameters are not given, so these models reproduce the μ/E model exactly.

**Speed** (issue 20 items 4–6; :class:`fem_squeal.fe.assembly.OperatingTerms`).  The turning disc
in the space-fixed frame adds Ω G₁ (G₁ skew) and −Ω² S (convective), the centrifugal prestress
Ω² K_σc; K₀ holds the preload's stress stiffening K_σ0.  The friction damping C_d of the nominal
point (μ⁰, Ω₀) scales as (|μ|/|μ⁰|)(Ω₀/Ω) for a constant μ: ``speed`` is a parameter when the scene has
one of these terms and no μ(V) law (whose μ, dμ/dV and preload change with V: not affine in Ω).

**Pressure** (issue 39).  The brake pressure s (a scale of the scene's ``loads.pressure``) changes
the preload u(s) and the contact pressures p(s), and with them the stress stiffening K_σ(u(s)) (K₀ holds
K_σ(u(1))) and the friction damping C_d(p(s)) (C_d holds C_d(p(1))).  Both are linear in the state, and
with the contact set of the scene and the linear penalty the state is affine in s, so
K_σ(u(s)) = K_σ(u(1)) + (s − 1) K_σ(du/ds) and C_d(p(s)) = C_d(p(1)) + (s − 1) C_d(dp/ds) exactly:
K_σ,s = Φᵀ K_σ(du/ds) Φ (``Ksp``), C_d,s = Φᵀ C_d(dp/ds) Φ (``Cdp``, at μ⁰, Ω₀ like C_d); the pressure is
a parameter where the model has either.  Where the continued preloads open or close contact points
(``contact_states``: the closed rows of every contact at each continued scale s), K at s holds the contact
matrices of that state's closed points a(s): K(s) = K(1) + Σ_c [s_c ΔK_c,c + μ_c s_c ΔK_f,c¹ + k_t,c ΔK_t,c¹]
with ΔK the forms above on the weights w (a(s) − a(1)) (exact at each continued s; between them the state
is not known and a ModelError names the pressures the model holds).  The affine K_σ,s and C_d,s then do
not hold: ``pressure_tables`` holds each continued scale's own Φᵀ(K_σ(u(s)) − K_σ(u(1)))Φ and
Φᵀ(C_d(p(s)) − C_d(p(1)))Φ in their place (∂K/∂s, ∂C/∂s keep the slopes: the state is piecewise affine).

**Loss factor.**  η ≥ 0 makes K complex: the eigenvalues of λ²I + K(1 + iη) (one part, undamped)
are λ = iω√(1 + iη) (Im λ > 0: Re λ = −ω Im√(1 + iη) < 0, the physical branch; the roots with
Im λ < 0 belong to K(1 − iη), the other sign of the frequency, and are not kept by
:func:`~fem_squeal.reduced.eigensolve.quadratic_eigs`).  It is exact complex arithmetic here; a
scene's nominal ``materials.<part>.eta`` is the model's ``eta0``.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from fem_squeal.reduced.affine import (
    INTERFACE_PREFIXES,  # noqa: F401  (re-exported: the old path)
    MU,
    PART_PREFIXES,
    PRESSURE,
    SPEED,
    check_damping_speed,
    check_names,
    check_range,
    e_param,
    eta_param,
    friction_damping_scale,
    interface_coefficients,
    loss_coefficient,
    modulus_coefficient,
    mu_share,
    parameter_names,
    pressure_coefficient,
    split_param,
)
from fem_squeal.reduced.contact_rows import ContactRows, from_gap_rows
from fem_squeal.util.atomic import write_npz_atomic
from fem_squeal.util.errors import ModelError


def _at_points(points: Mapping[str, np.ndarray], name: str, default: float, n: int) -> np.ndarray:
    """Parameter ``name`` at each of ``n`` points (``default`` where not given), as an (n,) array."""
    return np.broadcast_to(np.asarray(points.get(name, default), float), (n,))


def format_point(point: Mapping[str, float]) -> str:
    """A parameter point for people: ``sign(v)μ = −1.000, E(disc) = 100 GPa`` (units by parameter)."""
    out = []
    for name, value in point.items():
        value = float(value)
        if name == MU:
            out.append(f"sign(v)μ = {value:+.3f}")
        elif name.startswith("E."):
            out.append(f"E({name[2:]}) = {value / 1e9:.4g} GPa")
        elif name.startswith("mu."):
            out.append(f"sign(v)μ({name[3:]}) = {value:+.3f}")
        elif name.startswith(("kn.", "kt.")):
            out.append(f"{name[:2]}({name[3:]}) = {value:.4g} N/m³")
        elif name.startswith("eta."):
            out.append(f"η({name[4:]}) = {value:.4g}")
        elif name == SPEED:
            out.append(f"Ω = {value:.4g} rad/s")
        elif name == PRESSURE:
            out.append(f"p = {value:.4g} × loads.pressure")
        else:
            out.append(f"{name} = {value:.4g}")
    return ", ".join(out)


#: the old name of the reduction's contact rows (gap convention: G_nΦ, G_t₁Φ, G_t₂Φ, gap₀)
ContactRestriction = from_gap_rows


@dataclass
class PlateProjection:
    """A rigid plate's share of the stiffness on the basis (a bilateral penalty layer: no contact
    state): K_c = Φᵀ K_c,p Φ at the nominal k_n, K_f¹ = Φᵀ K_f,p Φ for μ = 1 (None: no friction),
    K_t¹ = Φᵀ K_t,p Φ for k_t = 1 (:class:`fem_squeal.fe.assembly.PlateMatrices`)."""

    Kc: np.ndarray
    Kt: np.ndarray
    Kf: np.ndarray | None
    kn: float
    mu: float
    sliding: float
    kt: float = 0.0

    def normal_stiffness(self) -> np.ndarray:
        return self.Kc

    def friction_stiffness(self) -> np.ndarray | None:
        return self.Kf

    def tangential_stiffness(self) -> np.ndarray:
        return self.Kt

    @property
    def has_kt(self) -> bool:
        return True


@dataclass
class ReducedModel:
    """Reduced matrices (m × m NumPy arrays) and the affine parameter map; see module docstring."""

    K0: np.ndarray
    Kf1: np.ndarray | None = None
    C0: np.ndarray | None = None
    K_parts: dict[str, np.ndarray] = field(default_factory=dict)
    E0: dict[str, float] = field(default_factory=dict)        # nominal modulus of each part [Pa]
    beta: dict[str, float] = field(default_factory=dict)      # Rayleigh β of each part [s]
    mu0: float = 0.0                                          # the scene's (signed) μ
    contacts: dict[str, ContactRows] = field(default_factory=dict)
    info: dict = field(default_factory=dict)                  # basis description (sizes, timings)
    f: np.ndarray | None = None                               # Φᵀ f: the static load (preload)
    q_static: np.ndarray | None = None                        # ΦᵀM u_s: the preload displacement
    eta0: dict[str, float] = field(default_factory=dict)      # parts with a loss-factor parameter: nominal η
    plates: dict[str, PlateProjection] = field(default_factory=dict)  # named rigid plates
    # the disc's speed (issue 20 items 4–6): C += Ω G1 + (|μ|/|μ⁰|)(Ω₀/Ω) Cd0, K += Ω² K2
    speed0: float = 0.0                                       # the scene's Ω₀ [rad/s]
    G1: np.ndarray | None = None                              # gyroscopic per unit Ω (skew)
    K2: np.ndarray | None = None                              # K_σc − S per unit Ω²
    Cd0: np.ndarray | None = None                             # friction damping at (μ⁰, Ω₀) (not in C0)
    speed_varies: bool = False                                # "speed" is a parameter (no μ(V) law)
    # the brake pressure (issue 39): K += (s − 1) Ksp, s the scale of loads.pressure
    Ksp: np.ndarray | None = None                             # K_σ(du/ds): stress stiffening per unit s
    Cdp: np.ndarray | None = None                             # C_d(dp/ds) at (μ⁰, Ω₀): friction damping per unit s
    # the contact state at each continued pressure when one differs from the scene's: scale -> {contact: closed}
    contact_states: dict[float, dict[str, np.ndarray]] = field(default_factory=dict)
    # with contact_states and a pressure term: its change at each continued scale, s -> {"Ks": Φᵀ(K_σ(u(s)) −
    # K_σ(u(1)))Φ, "Cd": Φᵀ(C_d(p(s)) − C_d(p(1)))Φ at (μ⁰, Ω₀)}, in place of the affine (s − 1) Ksp, (s − 1) Cdp
    pressure_tables: dict[float, dict[str, np.ndarray]] = field(default_factory=dict)

    def __post_init__(self):
        m = self.K0.shape[0]
        if self.K0.shape != (m, m):
            raise ModelError(f"K0: must be square (got {self.K0.shape})")
        plate_mats = [(f"plates.{n}.{f}", getattr(pl, f)) for n, pl in self.plates.items()
                      for f in ("Kc", "Kt", "Kf")]
        for name, A in [("Kf1", self.Kf1), ("C0", self.C0), *self.K_parts.items(), *plate_mats,
                        ("G1", self.G1), ("K2", self.K2), ("Cd0", self.Cd0), ("Ksp", self.Ksp),
                        ("Cdp", self.Cdp)]:
            if A is not None and A.shape != (m, m):
                raise ModelError(f"{name}: must be {m}×{m} like K0 (got {A.shape})")
        if self.Cdp is not None and self.Cd0 is None:
            raise ModelError("Cdp: the friction damping's pressure slope needs the friction damping Cd0")
        missing = sorted(set(self.K_parts) - set(self.E0))
        if missing:
            raise ModelError(f"E0: no nominal modulus for part(s) {missing}")
        stray = sorted(p for p in self.eta0 if p not in self.K_parts)
        if stray:
            raise ModelError(f"eta0: loss factor of part(s) {stray} whose stiffness the model does not carry")
        for p, v in self.eta0.items():
            if not v >= 0:
                raise ModelError(f"{eta_param(p)}: must be >= 0 (got {v})")
        for sc, state in self.contact_states.items():
            if not (np.isfinite(sc) and sc > 0):
                raise ModelError(f"contact_states: a pressure scale must be a number > 0 (got {sc!r})")
            for name, c in self.contacts.items():
                if np.shape(state.get(name, ())) != (c.size,):
                    raise ModelError(f"contact_states[{sc:g}].{name}: needs the closed flags of its {c.size} rows")
        for sc, tab in self.pressure_tables.items():
            if sc not in self.contact_states:
                raise ModelError(f"pressure_tables[{sc:g}]: a pressure without a contact state in contact_states")
            for key, A in tab.items():
                if key not in ("Ks", "Cd") or np.shape(A) != (m, m):
                    raise ModelError(f"pressure_tables[{sc:g}].{key}: must be Ks or Cd, {m}×{m} like K0")
        self._interface_cache: dict[tuple, tuple] = {}

    @property
    def interfaces(self) -> dict:
        """The interfaces with per-interface parameters: contacts, then named rigid plates."""
        return {**self.contacts, **self.plates}

    @property
    def size(self) -> int:
        return self.K0.shape[0]

    @property
    def parameters(self) -> list[str]:
        """Names of the parameters this model can vary (module docstring): ``mu``, ``E.<part>``,
        ``mu.<c>`` (sliding contacts and named rigid plates c), ``kn.<c>``, ``kt.<c>``, ``eta.<part>``,
        ``speed``, ``pressure``."""
        return parameter_names(self.K_parts, self.interfaces, mu=self.Kf1 is not None,
                               eta_parts=[p for p in self.K_parts if p in self.eta0],
                               kt_interfaces=[c for c, r in self.interfaces.items() if r.has_kt],
                               speed=self.speed_varies, pressure=self.pressure_varies)

    def nominal(self) -> dict[str, float]:
        """The value of every parameter at the nominal point."""
        vals = {MU: float(self.mu0)} if self.Kf1 is not None else {}
        vals.update({e_param(p): float(self.E0[p]) for p in self.K_parts})
        for c, r in self.interfaces.items():
            if r.sliding != 0:
                vals[f"mu.{c}"] = float(r.mu)
            vals[f"kn.{c}"] = float(r.kn)
            if r.has_kt:
                vals[f"kt.{c}"] = float(r.kt)
        vals.update({eta_param(p): float(self.eta0[p]) for p in self.K_parts if p in self.eta0})
        vals[SPEED] = self.speed0
        vals[PRESSURE] = 1.0
        return {k: vals[k] for k in self.parameters}

    @property
    def pressure_varies(self) -> bool:
        """The brake pressure is a parameter (a stress stiffening or friction damping term per unit s, or
        contact states that change with it)."""
        return self.Ksp is not None or self.Cdp is not None or bool(self.contact_states)

    def contact_state(self, pressure: float) -> dict[str, np.ndarray] | None:
        """The closed rows of every contact at pressure scale ``pressure`` (None: the preload's, at s = 1 or
        when the contact set does not change with the pressure); a ModelError for a pressure between the
        continued ones when it does (the state there is not known: the preload was not solved there)."""
        if not self.contact_states or pressure == 1.0:
            return None
        if pressure not in self.contact_states:
            raise ModelError(f"pressure: the contact set changes with the pressure, and this model holds it at "
                             f"{sorted([1.0, *self.contact_states])} × loads.pressure only (got {pressure:g}: "
                             f"continue the preload there, e.g. add it to analyses.operating_matrix.pressure)")
        return self.contact_states[pressure]

    def _friction_damping(self, pressure) -> np.ndarray:
        """C_d + (s − 1) C_d,s at the pressure scale(s) ``pressure`` (a number: (m, m); an array of n
        points: (n, m, m)); C_d without the term."""
        if self.Cdp is None:
            return self.Cd0
        s = np.asarray(pressure, float)
        if self.pressure_tables:
            return self.Cd0 + self._pressure_change("Cd", s.reshape(-1)).reshape(s.shape + self.Cd0.shape)
        return self.Cd0 + pressure_coefficient(s)[..., None, None] * self.Cdp

    def _pressure_change(self, key: str, s: np.ndarray) -> np.ndarray:
        """(n, m, m): the table ``key`` (Ks or Cd) at each scale of ``s`` (zero at 1; a ModelError between the
        continued scales, :meth:`contact_state`)."""
        out = np.zeros((s.size, self.size, self.size))
        for p in np.unique(s):
            if self.contact_state(float(p)) is not None:
                out[s == p] = self.pressure_tables[float(p)][key]
        return out

    @property
    def complex_stiffness(self) -> bool:
        """K is complex at the nominal point (a part has a loss factor η > 0)."""
        return any(v != 0 for v in self.eta0.values())

    def interface_matrices(self, name: str, pressure: float = 1.0
                           ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(K_c, K_f¹ or None without sliding, K_t¹ or None) of contact or plate ``name`` (module
        docstring), with the contact state at the pressure scale ``pressure`` (:meth:`contact_state`)."""
        state = self.contact_state(pressure) if name in self.contacts else None
        key = (name, 1.0 if state is None else float(pressure))
        if key not in self._interface_cache:
            c = self.interfaces[name]
            if state is None:
                self._interface_cache[key] = (c.normal_stiffness(),
                                              c.friction_stiffness() if c.sliding != 0 else None,
                                              c.tangential_stiffness())
            else:
                self._interface_cache[key] = tuple(
                    None if A is None else A + dA
                    for A, dA in zip(self.interface_matrices(name), self.contact_change(name, pressure)))
        return self._interface_cache[key]

    def contact_change(self, name: str, pressure: float
                       ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """(ΔK_c, ΔK_f¹, ΔK_t¹) of contact ``name`` from the preload's contact state to that at pressure
        scale ``pressure`` (None each where the state is the preload's or the term absent):
        :meth:`~fem_squeal.reduced.contact_rows.ContactRows.stiffness_change`."""
        state = self.contact_state(pressure)
        if state is None:
            return None, None, None
        key = ("change", name, float(pressure))
        if key not in self._interface_cache:
            self._interface_cache[key] = self.contacts[name].stiffness_change(state[name])
        return self._interface_cache[key]

    def _contact_terms(self, points: Mapping[str, np.ndarray], n: int) -> np.ndarray | None:
        """Σ_c [s_c ΔK_c,c + μ_c s_c ΔK_f,c¹ + k_t,c ΔK_t,c¹] at each of ``n`` points' pressure: the contact
        stiffness of its own contact state minus the preload's (s_c = k_n,c/k_n,c⁰, μ_c = ``mu.<c>`` or
        μ·μ_c⁰/μ⁰, k_t,c its tangential penalty: the full coefficients of the three matrices in K);
        None without contact states or pressure."""
        if not self.contact_states or PRESSURE not in points:
            return None
        def vec(key, default):
            return _at_points(points, key, default, n)

        ps = vec(PRESSURE, 1.0)
        out = np.zeros((n, self.size, self.size))
        mu = vec(MU, self.mu0)
        for p in np.unique(ps):
            at = ps == p
            for name, c in self.contacts.items():
                dKc, dKf, dKt = self.contact_change(name, float(p))
                if dKc is None:
                    continue
                sc = vec(f"kn.{name}", c.kn)[at] / c.kn
                out[at] += sc[:, None, None] * dKc
                if dKf is not None:
                    mu_c = vec(f"mu.{name}", 0.0) if f"mu.{name}" in points else mu * self._mu_share(c)
                    out[at] += (mu_c[at] * sc)[:, None, None] * dKf
                if dKt is not None:
                    out[at] += vec(f"kt.{name}", c.kt)[at][:, None, None] * dKt
        return out

    def _mu_share(self, c: ContactRows | PlateProjection) -> float:
        """μ_c⁰/μ⁰: what a unit ``mu`` gives contact c (0 for a contact without friction at nominal)."""
        return mu_share(c.mu, self.mu0, c.sliding != 0 and self.Kf1 is not None)

    @property
    def damped(self) -> bool:
        return self.C0 is not None or self.G1 is not None or self.Cd0 is not None or \
            any(self.beta.get(p, 0.0) > 0 for p in self.K_parts)

    def _check(self, names) -> None:
        check_names(names, self.parameters, " of this reduced model")

    def coefficients(self, points: Mapping[str, np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
        """Affine coefficients of K and C for ``n`` points: arrays (n, 1 + n_terms)."""
        self._check(points)
        for name, v in points.items():
            check_range(name, v)
        parts = list(self.K_parts)
        ck = np.zeros((n, 2 + len(parts)))
        cc = np.zeros((n, len(parts)))
        ck[:, 0] = 1.0
        mu = np.broadcast_to(np.asarray(points.get(MU, self.mu0), float), (n,))
        ck[:, 1] = mu
        for j, part in enumerate(parts):
            E = np.broadcast_to(np.asarray(points.get(e_param(part), self.E0[part]), float), (n,))
            ck[:, 2 + j] = modulus_coefficient(E, self.E0[part])
            cc[:, j] = self.beta.get(part, 0.0) * ck[:, 2 + j]
        return ck, cc

    def extra_terms(self, points: Mapping[str, np.ndarray], n: int
                    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Coefficients (n, t) (complex with a loss factor) and matrices (t, m, m) of the loss-factor
        and interface terms of K for ``n`` points; None when none applies (only μ and E vary and no
        part has a loss factor: K is then the μ/E model's, bit for bit)."""
        def vec(name, default):
            return _at_points(points, name, default, n)

        coefs, mats = [], []
        for part, Kp in self.K_parts.items():
            name = eta_param(part)
            if name in points or self.eta0.get(part, 0.0) != 0:
                coefs.append(loss_coefficient(vec(name, self.eta0.get(part, 0.0)),
                                              vec(e_param(part), self.E0[part]), self.E0[part], 1j))
                mats.append(Kp)
        mu = vec(MU, self.mu0)
        given = {k: vec(k, 0.0) for k in points}
        for cname, c in self.interfaces.items():
            terms = interface_coefficients(given, cname, c.kn, c.kt, mu, self._mu_share(c))
            if terms:
                ifm = self.interface_matrices(cname)
                for j, coef in terms:
                    if ifm[j] is not None:
                        coefs.append(coef)
                        mats.append(ifm[j])
        if not coefs:
            return None
        return np.stack(coefs, axis=1), np.stack(mats)

    def derivative(self, name: str, point: Mapping[str, float] | None = None
                   ) -> tuple[np.ndarray, np.ndarray | None]:
        """(∂K/∂p, ∂C/∂p or None) at ``point`` (nominal where not given) for parameter ``name``:
        ∂K/∂μ = K_f¹ (− μ_c⁰/μ⁰ K_f,c¹ for a contact whose ``mu.<c>`` is given, + μ_c⁰/μ⁰ (s_c − 1)
        K_f,c¹ for one whose k_n is changed); ∂K/∂E_i = (1 + iη_i) K_i/E_i⁰, ∂C/∂E_i = β_i K_i/E_i⁰;
        ∂K/∂η_i = i θ_i K_i; ∂K/∂μ_c = s_c K_f,c¹; ∂K/∂k_n,c = (K_c,c + μ_c K_f,c¹)/k_n,c⁰;
        ∂K/∂k_t,c = K_t,c¹; ∂C/∂μ = sign(μ)(Ω₀/Ω) C_d/|μ⁰|; ∂K/∂Ω = 2Ω K₂, ∂C/∂Ω = G₁ − (|μ|/|μ⁰|)(Ω₀/Ω²) C_d;
        ∂K/∂s = K_σ,s, ∂C/∂s = (|μ|/|μ⁰|)(Ω₀/Ω) C_d,s (the pressure; C_d above at s: C_d + (s − 1) C_d,s)."""
        point = dict(point or {})
        self._check([name, *point])
        val = {**self.nominal(), **{k: float(v) for k, v in point.items()}}
        prefix, target = split_param(name)
        w, mu = val.get(SPEED, self.speed0), val.get(MU, self.mu0)
        Cd = self._friction_damping(val.get(PRESSURE, 1.0)) if self.Cd0 is not None else None
        if name == PRESSURE:
            m = self.size
            dK = self.Ksp.copy() if self.Ksp is not None else np.zeros((m, m))
            dC = friction_damping_scale(mu, self.mu0, w, self.speed0) * self.Cdp if self.Cdp is not None else None
            return dK, dC
        if name == SPEED:
            m = self.size
            dK = 2.0 * w * self.K2 if self.K2 is not None else np.zeros((m, m))
            dC = self.G1.copy() if self.G1 is not None else np.zeros((m, m))
            if Cd is not None:
                dC = dC - friction_damping_scale(mu, self.mu0, w, self.speed0) / w * Cd
            return dK, dC
        p = val.get(PRESSURE, 1.0)
        if name == MU:
            dC = np.sign(mu) * friction_damping_scale(1.0, self.mu0, w, self.speed0) * Cd \
                if Cd is not None else None
            dK = self.Kf1.copy()
            for cname, c in self.interfaces.items():
                share = self._mu_share(c)
                if share == 0:
                    continue
                if f"mu.{cname}" in point:     # its friction is its own: none of mu's (at the scene's state)
                    dK = dK - share * self.interface_matrices(cname)[1]
                    continue
                sc = val.get(f"kn.{cname}", c.kn) / c.kn
                if sc != 1.0:
                    dK = dK + share * (sc - 1.0) * self.interface_matrices(cname)[1]
                dKf = self.contact_change(cname, p)[1] if cname in self.contacts else None
                if dKf is not None:            # the closed rows at this pressure, not the scene's
                    dK = dK + share * sc * dKf
            return dK, dC
        if prefix in PART_PREFIXES:
            Kp, E0 = self.K_parts[target], self.E0[target]
            eta = val.get(eta_param(target), 0.0)
            if prefix == "eta":
                return 1j * (val[e_param(target)] / E0) * Kp, None
            Ki = Kp / E0
            beta = self.beta.get(target, 0.0)
            return (Ki if eta == 0 else (1.0 + 1j * eta) * Ki), (beta * Ki if beta else None)
        c = self.interfaces[target]
        Kc, Kf, Kt = self.interface_matrices(target, p)
        s = val[f"kn.{target}"] / c.kn
        if prefix == "kt":
            return Kt.copy(), None
        mu_c = val.get(f"mu.{target}", 0.0) if f"mu.{target}" in point else \
            (val.get(MU, 0.0) * self._mu_share(c))
        if prefix == "mu":
            return s * Kf, None
        return (Kc + mu_c * Kf if Kf is not None else Kc) / c.kn, None

    def stiffness_terms(self) -> np.ndarray:
        """(2 + n_parts, m, m): K0, K_f¹ (zero when frictionless), K_i."""
        m = self.size
        Kf = self.Kf1 if self.Kf1 is not None else np.zeros((m, m))
        return np.stack([self.K0, Kf, *self.K_parts.values()])

    def matrices(self, points: Mapping[str, np.ndarray] | None = None, n: int = 1
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        """K(p) and C(p) (None if undamped) as (n, m, m) stacks for ``n`` points (K complex when
        a part has a loss factor)."""
        points = points or {}
        ck, cc = self.coefficients(points, n)
        K = np.tensordot(ck, self.stiffness_terms(), axes=1)
        extra = self.extra_terms(points, n)
        if extra is not None:
            K = K + np.tensordot(extra[0], extra[1], axes=1)
        speed = self._speed(points, n)
        if self.K2 is not None:
            K = K + (speed ** 2)[:, None, None] * self.K2
        if self.Ksp is not None and PRESSURE in points:
            s = np.broadcast_to(np.asarray(points[PRESSURE], float), (n,))
            K = K + (self._pressure_change("Ks", s) if self.pressure_tables else
                     pressure_coefficient(s)[:, None, None] * self.Ksp)
        contact = self._contact_terms(points, n)
        if contact is not None:
            K = K + contact
        if not self.damped:
            return K, None
        C = np.broadcast_to(self.C0 if self.C0 is not None else np.zeros((self.size,) * 2),
                            K.shape).copy()
        if self.K_parts:
            C += np.tensordot(cc, np.stack(list(self.K_parts.values())), axes=1)
        if self.G1 is not None:
            C += speed[:, None, None] * self.G1
        if self.Cd0 is not None:
            mu = np.broadcast_to(np.asarray(points.get(MU, self.mu0), float), (n,))
            Cd = self.Cd0 if self.Cdp is None or PRESSURE not in points else \
                self._friction_damping(np.broadcast_to(np.asarray(points[PRESSURE], float), (n,)))
            C += friction_damping_scale(mu, self.mu0, speed, self.speed0)[:, None, None] * Cd
        return K, C

    def _speed(self, points: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """Ω at each of ``n`` points (the nominal Ω₀ where not given), checked: ≥ 0, > 0 with friction
        damping (C_d ∝ 1/Ω)."""
        speed = np.broadcast_to(np.asarray(points.get(SPEED, self.speed0), float), (n,))
        if SPEED in points:
            check_range(SPEED, speed)
            if self.Cd0 is not None and self.speed0:
                check_damping_speed(speed)
        return speed

    def frictionless_frequencies(self) -> np.ndarray:
        """√eig(K₀)/2π [Hz] of the nominal frictionless reduced model, ascending (the parents)."""
        w2 = np.linalg.eigvalsh(0.5 * (self.K0 + self.K0.T))
        return np.sign(w2) * np.sqrt(np.abs(w2)) / (2 * np.pi)

    def save(self, path) -> None:
        """Write every array to a ``.npz`` (atomically)."""

        arrays = {"K0": self.K0, "mu0": np.array(self.mu0)}
        for name in ("f", "q_static"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        if self.Kf1 is not None:
            arrays["Kf1"] = self.Kf1
        if self.C0 is not None:
            arrays["C0"] = self.C0
        for p, A in self.K_parts.items():
            arrays[f"K_part/{p}"] = A
            arrays[f"E0/{p}"] = np.array(self.E0[p])
            arrays[f"beta/{p}"] = np.array(self.beta.get(p, 0.0))
            if p in self.eta0:
                arrays[f"eta0/{p}"] = np.array(self.eta0[p])
        for name, c in self.contacts.items():
            for f in ("Gn", "Gt", "weight", "gap", "active", "gap0", "x", "pressure", "Gt2"):
                if getattr(c, f) is not None:
                    arrays[f"contact/{name}/{f}"] = getattr(c, f)
            for f in ("kn", "mu", "sliding", "kt"):
                arrays[f"contact/{name}/{f}"] = np.array(getattr(c, f))
        for name in ("G1", "K2", "Cd0", "Ksp", "Cdp"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        if self.speed0 or self.speed_varies:
            arrays["speed0"] = np.array(self.speed0)
            arrays["speed_varies"] = np.array(self.speed_varies)
        for name, pl in self.plates.items():
            for f in ("Kc", "Kt", "Kf", "kn", "mu", "sliding", "kt"):
                if getattr(pl, f) is not None:
                    arrays[f"plate/{name}/{f}"] = np.asarray(getattr(pl, f))
        for i, (sc, state) in enumerate(sorted(self.contact_states.items())):
            arrays[f"contact_state/{i}/scale"] = np.array(sc)
            for name, a in state.items():
                arrays[f"contact_state/{i}/{name}"] = np.asarray(a, bool)
            for key, A in self.pressure_tables.get(sc, {}).items():
                arrays[f"pressure_table/{i}/{key}"] = A
        # the basis description's counts (modes first: the couplings of a cached model need them)
        for k, v in self.info.items():
            if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
                arrays[f"info/{k}"] = np.array(int(v))
        write_npz_atomic(path, arrays)

    @classmethod
    def load(cls, path) -> ReducedModel:
        """Read a model written by :meth:`save` (also one written before k_t, η and the interface
        parameters existed: no G_t₂Φ, k_t = 0, η = 0; or before its basis counts were saved: ``info``
        empty, so no coupling is named on it)."""
        with np.load(path) as z:
            d = {k: z[k] for k in z.files}
        parts = sorted(k.split("/", 1)[1] for k in d if k.startswith("K_part/"))
        contacts = {}
        for name in sorted({k.split("/")[1] for k in d if k.startswith("contact/")}):
            g = {f: d.get(f"contact/{name}/{f}") for f in ("Gn", "Gt", "weight", "gap", "active", "gap0", "x",
                                                          "pressure", "Gt2")}
            s = {f: float(d[f"contact/{name}/{f}"]) for f in ("kn", "mu", "sliding")}
            s["kt"] = float(d.get(f"contact/{name}/kt", 0.0))
            contacts[name] = from_gap_rows(**g, **s, name=name)
        plates = {}
        for name in sorted({k.split("/")[1] for k in d if k.startswith("plate/")}):
            plates[name] = PlateProjection(
                d[f"plate/{name}/Kc"], d[f"plate/{name}/Kt"], d.get(f"plate/{name}/Kf"),
                **{f: float(d[f"plate/{name}/{f}"]) for f in ("kn", "mu", "sliding", "kt")})
        return cls(K0=d["K0"], Kf1=d.get("Kf1"), C0=d.get("C0"),
                   K_parts={p: d[f"K_part/{p}"] for p in parts}, E0={p: float(d[f"E0/{p}"]) for p in parts},
                   beta={p: float(d[f"beta/{p}"]) for p in parts}, mu0=float(d["mu0"]), contacts=contacts,
                   f=d.get("f"), q_static=d.get("q_static"),
                   eta0={p: float(d[f"eta0/{p}"]) for p in parts if f"eta0/{p}" in d}, plates=plates,
                   speed0=float(d.get("speed0", 0.0)), G1=d.get("G1"), K2=d.get("K2"), Cd0=d.get("Cd0"),
                   speed_varies=bool(d.get("speed_varies", False)), Ksp=d.get("Ksp"),
                   Cdp=d.get("Cdp"), info={k.split("/", 1)[1]: int(d[k]) for k in d if k.startswith("info/")},
                   contact_states=_contact_states(d), pressure_tables=_pressure_tables(d))


def _pressure_tables(d: Mapping[str, np.ndarray]) -> dict[float, dict[str, np.ndarray]]:
    """The ``pressure_table/<i>/…`` arrays of a saved model by their contact state's scale ({} if none)."""
    out: dict[float, dict[str, np.ndarray]] = {}
    for k in d:
        if k.startswith("pressure_table/"):
            _, i, key = k.split("/")
            out.setdefault(float(d[f"contact_state/{i}/scale"]), {})[key] = d[k]
    return out


def _contact_states(d: Mapping[str, np.ndarray]) -> dict[float, dict[str, np.ndarray]]:
    """The ``contact_state/<i>/…`` arrays of a saved model as {scale: {contact: closed}} ({} if none)."""
    out: dict[float, dict[str, np.ndarray]] = {}
    for i in sorted({int(k.split("/")[1]) for k in d if k.startswith("contact_state/")}):
        head = f"contact_state/{i}/"
        out[float(d[head + "scale"])] = {k[len(head):]: np.asarray(d[k], bool) for k in d
                                         if k.startswith(head) and k != head + "scale"}
    return out
