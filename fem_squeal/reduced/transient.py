"""Nonlinear transient of a reduced model with contact and friction laws (seed 002 §2, seed 004).

State q on a basis that keeps the contact interface explicit through its rows (modes plus
contact-static-correction vectors, :func:`fem_squeal.fe.projection.contact_attachments`).  Each
contact element j of an interface has the closure δ_j = δ₀_j + D_j q (D = −G_nΦ), the tangential
rows T_j (one or two directions) and the counter-face velocity V_j along them; its normal force
F_j(δ, δ̇) (:mod:`.contact_law`) and friction force f_j(F, w) with w = T_j q̇ − V_j
(:mod:`.friction`) act on the structure as −D_jᵀF_j + T_jᵀf_j, so

    M q̈ + C q̇ + K q + g(q, q̇) = f,      g = Σ_j D_jᵀ F_j − T_jᵀ f_j.

Time stepping: HHT-α (α ∈ [−1/3, 0]; α = 0 is the trapezoidal/average-acceleration Newmark rule)

    M a₁ + (1 + α)(C v₁ + K q₁ + g₁) − α(C v₀ + K q₀ + g₀) = f
    q₁ = q₀ + Δt v₀ + Δt²((½ − β)a₀ + β a₁),  v₁ = v₀ + Δt((1 − γ)a₀ + γa₁)
    β = (1 − α)²/4,  γ = ½ − α          (spectral radius at infinity (1 + α)/(1 − α))

solved for q₁ by Newton's method with the consistent tangent
S = M/(βΔt²) + (1 + α)(γ/(βΔt)(C + ∂g/∂q̇) + K + ∂g/∂q).  ``tangent="modified"`` keeps the last
factorised S while Newton contracts fast (at Δt ~ 1 µs the mass term M/(βΔt²) dominates, so the
tangent is refreshed only when the contact state moves a lot); ``"full"`` refreshes it at every
iteration.  Both stop on the same residual test, so they give the same solution.

Energy (trapezoidal quadrature of the powers, exact for α = 0 up to the contact potential):
E = ½q̇ᵀMq̇ + ½qᵀK_sym q,  E₁ − E₀ = W_ext + W_friction + W_normal − D_damping.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.linalg as sla

from fem_squeal.reduced.contact_rows import ContactRows, check_columns, checked_rows
from fem_squeal.reduced.laws.contact import NORMAL_LAWS, ExponentialLaw
from fem_squeal.reduced.laws.friction import ConstantFriction, CoulombState, ElasticCoulomb
from fem_squeal.reduced.masa import MasaModel, aggregate, polar_patches
from fem_squeal.reduced.masa import from_reduced as masa_model
from fem_squeal.util.atomic import write_json_atomic, write_npz_atomic
from fem_squeal.util.errors import TransientError
from fem_squeal.util.progress import ProgressBar

ENERGY_KEYS = ("kinetic", "strain", "W_ext", "W_friction", "W_normal", "D_damping", "W_skew")



def FrictionContact(D: np.ndarray, T: np.ndarray, d0: np.ndarray, normal: object, friction: object | None = None,
                    V: np.ndarray | None = None, radius: np.ndarray | None = None, x: np.ndarray | None = None,
                    name: str = "contact") -> ContactRows:
    """One contact interface (the old name): :class:`~fem_squeal.reduced.contact_rows.ContactRows` with
    closure rows D (n, m), tangential rows T (d, n, m) (or (n, m) for one direction), initial closure
    d0, normal law, friction law (None: frictionless), the counter-face velocity V (n, d) [m/s], and
    optionally the lever arm ``radius`` (n,) about the disc axis (for the braking torque Σ r f) and the
    element coordinates ``x``."""
    return checked_rows(TransientError, D=D, T=T, d0=np.asarray(d0, float), normal=normal, friction=friction,
                        V=V, radius=radius, x=x, name=name)


@dataclass
class DynamicModel:
    """M (None: identity, a mass-orthonormal basis), C, K, constant load f and the interfaces."""

    K: np.ndarray
    contacts: list[ContactRows]
    M: np.ndarray | None = None
    C: np.ndarray | None = None
    f: np.ndarray | None = None

    def __post_init__(self):
        m = self.K.shape[0]
        for name in ("K", "M", "C"):
            A = getattr(self, name)
            if A is not None and (A.shape != (m, m) or not np.all(np.isfinite(A))):
                raise TransientError(f"{name}: must be a finite {m}×{m} matrix (got shape {A.shape})")
        if self.f is not None and np.shape(self.f) != (m,):
            raise TransientError(f"f: must have {m} entries (got {np.shape(self.f)})")
        check_columns(self.contacts, m, TransientError)

    @property
    def size(self) -> int:
        return self.K.shape[0]

    def mass(self) -> np.ndarray:
        return np.eye(self.size) if self.M is None else self.M

    def digest(self) -> str:
        """Content hash (checkpoints refuse to resume a different model)."""
        h = hashlib.sha256()
        for A in (self.K, self.M, self.C, self.f):
            h.update(b"-" if A is None else np.ascontiguousarray(A).tobytes())
        for cs in self.contacts:
            for A in (cs.D, cs.T, cs.d0, cs.V):
                h.update(np.ascontiguousarray(A).tobytes())
            h.update(repr((cs.normal, cs.friction)).encode())
        return h.hexdigest()[:16]


@dataclass
class Forces:
    """Contact quantities at one state (per interface lists) and their generalised forces."""

    F: list[np.ndarray]
    f: list[np.ndarray]
    w: list[np.ndarray]
    closure: list[np.ndarray]
    g_normal: np.ndarray      # Σ Dᵀ F
    g_friction: np.ndarray    # Σ Tᵀ f  (the friction force on the structure)
    state: list


@dataclass
class State:
    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    friction: list            # per interface: the friction law's history (or None)
    step: int = 0
    forces: Forces | None = None   # contact forces the step that reached this state balanced


@dataclass
class TransientResult:
    t: np.ndarray
    q: np.ndarray                      # (n_t, m)
    v: np.ndarray
    energy: dict[str, np.ndarray]
    contact: dict[str, np.ndarray]     # per interface: "<name>.normal_force", ".friction_force", ...
    stats: dict

    def total_energy(self) -> np.ndarray:
        return self.energy["kinetic"] + self.energy["strain"]

    def energy_residual(self) -> np.ndarray:
        """E − E₀ − (W_ext + W_friction + W_normal − D_damping + W_skew): zero for α = 0 up to
        round-off (the works are trapezoidal sums of the forces the scheme balances)."""
        e = self.energy
        E = self.total_energy()
        return E - E[0] - (e["W_ext"] + e["W_friction"] + e["W_normal"] - e["D_damping"] + e["W_skew"])


def _steady_mu(law, speed: np.ndarray) -> np.ndarray:
    """The friction coefficient of steady sliding at the counter-face speed."""
    if law is None:
        return np.zeros_like(speed)
    if isinstance(law, ConstantFriction):
        return np.broadcast_to(np.asarray(law.mu, float), speed.shape)
    if isinstance(law, ElasticCoulomb):
        return np.broadcast_to(np.asarray(law.mu_d, float), speed.shape)
    return law.coefficient(speed)[0]


#: ω_t Δt above which an elastic stick spring is not resolved by the step: the belt stick–slip of
#: benchmarks/transient_order.py is right at ω_t Δt = 20 and silently turns into pure sliding at 50.
STICK_RESOLUTION = 10.0


def stick_resolution_warnings(model: DynamicModel, dt: float) -> list[str]:
    """Warn when the stick springs k_t of ElasticCoulomb elements ring faster than the step resolves:
    ω_t = √(k_t / m_t), m_t = 1/(t M⁻¹ tᵀ) the mass the element's tangential row t sees."""

    out = []
    sticky = [cs for cs in model.contacts if isinstance(cs.friction, ElasticCoulomb)]
    Minv = np.linalg.inv(model.mass()) if sticky else None    # only when there is a stick spring
    for cs in sticky:
        inv_m = np.einsum("dnm,mk,dnk->n", cs.T, Minv, cs.T) / cs.n_dir
        kt = np.broadcast_to(np.asarray(cs.friction.k_t, float), inv_m.shape)
        wdt = float(np.max(np.sqrt(kt * np.maximum(inv_m, 0.0)))) * dt
        if wdt > STICK_RESOLUTION:
            out.append(f"{cs.name}: the stick springs (k_t) ring at ω_t Δt = {wdt:.3g} > {STICK_RESOLUTION:g}: "
                       "the step does not resolve sticking, and stick–slip may silently become pure sliding "
                       f"(dt <= {STICK_RESOLUTION / wdt * dt:.3g} s resolves it; or a smaller k_t, a damper c_t, "
                       "or adaptive halving with alpha = 0)")
    return out


class NewmarkHHT:
    """The HHT-α/Newmark integrator of the module docstring, owning the factorised tangent."""

    def __init__(self, model: DynamicModel, dt: float, *, alpha: float = 0.0, rtol: float = 1e-9,
                 max_iterations: int = 30, tangent: str = "modified", refresh_ratio: float = 0.25,
                 adaptive: bool = False, max_halvings: int = 6, event_limit: int = 0):
        if not dt > 0:
            raise TransientError(f"dt: must be > 0 (got {dt})")
        if not -1.0 / 3.0 <= alpha <= 0.0:
            raise TransientError(f"alpha: must be in [-1/3, 0] (HHT; got {alpha})")
        if tangent not in ("modified", "full"):
            raise TransientError(f"tangent: must be 'modified' or 'full' (got {tangent!r})")
        self.model, self.dt, self.alpha = model, float(dt), float(alpha)
        self.beta, self.gamma = (1 - alpha) ** 2 / 4, 0.5 - alpha
        self.rtol, self.max_iterations, self.tangent = rtol, max_iterations, tangent
        self.refresh_ratio, self.adaptive, self.max_halvings = refresh_ratio, adaptive, max_halvings
        self.event_limit = event_limit
        self.M = model.mass()
        self.C = model.C
        self.K = model.K
        self.f = np.zeros(model.size) if model.f is None else np.asarray(model.f, float)
        Ks = 0.5 * (self.K + self.K.T)
        self.K_skew = self.K - Ks
        self.K_sym = Ks
        self.has_skew = bool(np.abs(self.K_skew).max() > 1e-13 * np.abs(self.K).max())
        # one stacked row matrix per interface: [D; T_1; (T_2)]
        self.rows = [np.vstack([cs.D, *cs.T]) for cs in model.contacts]
        self._lus: dict[float, tuple] = {}     # factorised tangent per step size (adaptive halving)
        self.stats = {"steps": 0, "iterations": 0, "factorisations": 0, "halvings": 0, "events": 0,
                      "stalled": 0}
        self.warnings = stick_resolution_warnings(model, self.dt)
        for w in self.warnings:
            warnings.warn(w, RuntimeWarning, stacklevel=2)

    # ---------------------------------------------------------------- forces
    def forces(self, q: np.ndarray, v: np.ndarray, q0: np.ndarray | None, dt: float,
               states: list, derivatives: bool = False):
        """Contact forces at (q, v); Δs = T(q − q0) − VΔt for displacement-driven friction."""
        m = self.model.size
        gN, gT = np.zeros(m), np.zeros(m)
        out = Forces([], [], [], [], gN, gT, [])
        tangents = []
        for cs, A, st in zip(self.model.contacts, self.rows, states):
            n, d = cs.size, cs.n_dir
            X = A @ np.column_stack([q, v] if q0 is None else [q, v, q - q0])
            delta = cs.d0 + X[:n, 0]
            ddot = X[:n, 1]
            F, kF, cF = cs.normal.evaluate(delta, ddot)
            Tv = X[n:, 1].reshape(d, n).T
            w = Tv - cs.V
            if cs.friction is None:
                f = np.zeros((n, d))
                dfdF, Jd, Jv, new = f, None, None, None
            else:
                ds = (X[n:, 2].reshape(d, n).T - cs.V * dt) if (q0 is not None) else np.zeros((n, d))
                f, dfdF, Jd, Jv, new = cs.friction.evaluate(F, w, cs.V, ds, st)
            gN += A[:n].T @ F
            gT += A[n:].T @ f.T.ravel()
            out.F.append(F)
            out.f.append(f)
            out.w.append(w)
            out.closure.append(delta)
            out.state.append(new)
            tangents.append((kF, cF, dfdF, Jd, Jv))
        return (out, tangents) if derivatives else out

    def _contact_jacobian(self, tangents, wq: float, wv: float) -> np.ndarray:
        """wq ∂g/∂q + wv ∂g/∂q̇ from the per-interface law derivatives (kF, cF, ∂f/∂F, ∂f/∂Δs,
        ∂f/∂w):  Σ Bᵀ diag(wq kF + wv cF) D − Σ Tᵢᵀ diag(wq Jd + wv Jv)ᵢⱼ Tⱼ,  B = D − Σ (∂f/∂F)ᵢ Tᵢ."""
        G = np.zeros((self.model.size,) * 2)
        for cs, (kF, cF, dfdF, Jd, Jv) in zip(self.model.contacts, tangents):
            kk = wq * kF + (wv * cF if wv else 0.0)
            if np.any(kk):
                B = cs.D - sum(dfdF[:, i, None] * cs.T[i] for i in range(cs.n_dir))
                G += B.T @ (kk[:, None] * cs.D)
            J = (0.0 if Jd is None or not wq else wq * Jd) + (0.0 if Jv is None or not wv else wv * Jv)
            if np.any(J):
                for i in range(cs.n_dir):
                    for j in range(cs.n_dir):
                        if np.any(J[:, i, j]):
                            G -= cs.T[i].T @ (J[:, i, j][:, None] * cs.T[j])
        return G

    def _tangent(self, tangents, dt: float) -> np.ndarray:
        """S = M/(βΔt²) + (1+α)(γ/(βΔt)(C + ∂g/∂q̇) + K + ∂g/∂q)."""
        c1, c2 = self.gamma / (self.beta * dt), 1.0 / (self.beta * dt * dt)
        G = self.K + self._contact_jacobian(tangents, 1.0, c1)
        if self.C is not None:
            G += c1 * self.C
        return c2 * self.M + (1 + self.alpha) * G

    def tangent_matrices(self, q: np.ndarray, v: np.ndarray, states: list | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
        """K_t = K + ∂g/∂q and C_t = C + ∂g/∂q̇ at the state (q, q̇): the linearised (tangent)
        CEA matrices of seed 002 §3.2.2's dynamic stability diagram."""
        if states is None:
            states = self.sliding_states(q, v)
        _, tg = self.forces(q, v, q, 0.0, states, derivatives=True)
        Kt = self.K + self._contact_jacobian(tg, 1.0, 0.0)
        Ct = self._contact_jacobian(tg, 0.0, 1.0)
        if self.C is not None:
            Ct += self.C
        return Kt, Ct

    # ---------------------------------------------------------------- start
    def sliding_states(self, q: np.ndarray, v: np.ndarray) -> list:
        """Friction histories of steady sliding at (q, q̇): the elastic Coulomb stick springs
        stretched to their sliding limit μ_d F along V (other laws have no history)."""
        states = []
        for cs in self.model.contacts:
            if isinstance(cs.friction, ElasticCoulomb):
                F = cs.normal.evaluate(cs.d0 + cs.D @ q, cs.D @ v)[0]
                f = ConstantFriction(cs.friction.mu_d).evaluate(F, cs.V, cs.V, None, None)[0]
                states.append(CoulombState(-f / np.asarray(cs.friction.k_t, float).reshape(-1, 1),
                                           np.zeros(cs.size, bool)))
            else:
                states.append(None if cs.friction is None else cs.friction.initial_state(cs.size, cs.n_dir))
        return states

    def initial_state(self, q0: np.ndarray, v0: np.ndarray | None = None, t0: float = 0.0) -> State:
        """State at t0 with the acceleration from the equation of motion; friction histories in
        steady sliding (elastic stick springs at their sliding limit)."""
        m = self.model.size
        q0 = np.asarray(q0, float)
        v0 = np.zeros(m) if v0 is None else np.asarray(v0, float)
        if q0.shape != (m,) or v0.shape != (m,):
            raise TransientError(f"initial state: q0 and v0 must have {m} entries")
        states = self.sliding_states(q0, v0)
        fr = self.forces(q0, v0, None, 0.0, states)
        rhs = self.f - self.K @ q0 - fr.g_normal + fr.g_friction
        if self.C is not None:
            rhs -= self.C @ v0
        a0 = np.linalg.solve(self.M, rhs)
        return State(t0, q0.copy(), v0.copy(), a0, states, forces=fr)

    def steady_sliding(self, q0: np.ndarray | None = None, tol: float = 1e-10, max_iterations: int = 50
                       ) -> np.ndarray:
        """The static state of steady sliding, K q + g(q, 0) = f with f_j = μ(|V_j|) F_j V̂_j:
        Newton with backtracking (the starting point of a squeal transient)."""
        m = self.model.size
        q = np.zeros(m) if q0 is None else np.array(q0, float)
        consts = []
        for cs in self.model.contacts:
            speed = np.linalg.norm(cs.V, axis=1)
            consts.append(ConstantFriction(_steady_mu(cs.friction, speed)) if cs.friction is not None else None)

        def residual(q):
            r = self.K @ q - self.f
            mats = []
            for cs, law in zip(self.model.contacts, consts):
                delta = cs.d0 + cs.D @ q
                F, kF, _ = cs.normal.evaluate(delta, np.zeros(cs.size))
                # for a singular tangent (all contacts open, e.g. q = 0 with zero gaps): the
                # tangent of slightly closed elements, so that Newton can close them
                probe = cs.normal.evaluate(np.maximum(delta, 1e-12), np.zeros(cs.size))[1]
                f, dfdF = (np.zeros((cs.size, cs.n_dir)),) * 2
                if law is not None:
                    f, dfdF = law.evaluate(F, cs.V, cs.V, None, None)[:2]
                r += cs.D.T @ F - sum(cs.T[i].T @ f[:, i] for i in range(cs.n_dir))
                mats.append((kF, np.where(kF > 0, kF, probe), dfdF))
            return r, mats

        scale = max(np.linalg.norm(self.f), 1e-300)
        r, mats = residual(q)
        history = [np.linalg.norm(r) / scale]
        for _ in range(max_iterations):
            if history[-1] <= tol:
                return q
            def tangent(which, mats=mats):
                return self.K + self._contact_jacobian([(m[which], 0.0, m[2], None, None) for m in mats], 1.0, 0.0)

            try:
                dq = np.linalg.solve(tangent(0), -r)
            except np.linalg.LinAlgError:
                dq = np.linalg.solve(tangent(1), -r)
            step = 1.0
            while True:
                rn, mn = residual(q + step * dq)
                if np.linalg.norm(rn) <= (1 - 1e-4 * step) * np.linalg.norm(r) or step < 2 ** -20:
                    break
                step *= 0.5
            q, r, mats = q + step * dq, rn, mn
            history.append(np.linalg.norm(r) / scale)
        if history[-1] <= tol:
            return q
        raise TransientError(f"steady sliding state: ‖R‖/‖f‖ = {history[-1]:.2e} > {tol:.0e}; history "
                             f"{[f'{h:.1e}' for h in history]}")

    # ---------------------------------------------------------------- one step
    def _factor(self, tangents, dt):
        self._lus[dt] = sla.lu_factor(self._tangent(tangents, dt), check_finite=False)
        self.stats["factorisations"] += 1

    def try_step(self, s: State, dt: float) -> tuple[State, Forces, Forces, dict]:
        """One step of size dt from ``s`` (raises TransientError with the residual history)."""
        al, be, ga = self.alpha, self.beta, self.gamma
        c2 = 1.0 / (be * dt * dt)
        f0 = s.forces if s.forces is not None else self.forces(s.q, s.v, None, 0.0, s.friction)
        base = self.K @ s.q + f0.g_normal - f0.g_friction
        if self.C is not None:
            base += self.C @ s.v
        # force scale of the step: the dynamic forces (inertia M a, M v/Δt), not the static load
        # they vibrate about (a vibration 1e-3 of the static deflection must still be resolved
        # to rtol), with a floor of 1e-4 of the static forces (their balance has round-off
        # ~1e-12 of them on a brake)
        ref = max(np.linalg.norm(self.M @ s.a), np.linalg.norm(self.M @ s.v) / dt,
                  1e-4 * max(np.linalg.norm(self.f), np.linalg.norm(base)), 1e-300)
        rhs_const = self.f + al * base
        q = s.q + dt * s.v + 0.5 * dt * dt * s.a
        a_star = s.q + dt * s.v + dt * dt * (0.5 - be) * s.a      # q = a_star + βΔt² a
        history = []
        if dt not in self._lus or self.tangent == "full":
            # at the predictor the Newmark velocity is v + Δt a (a = c2 (q − a_star) = a_n)
            _, tg = self.forces(q, s.v + dt * s.a, s.q, dt, s.friction, derivatives=True)
            self._factor(tg, dt)
        def residual(q):
            a = c2 * (q - a_star)
            v = s.v + dt * ((1 - ga) * s.a + ga * a)
            fr, tg = self.forces(q, v, s.q, dt, s.friction, derivatives=True)
            inner = self.K @ q + fr.g_normal - fr.g_friction
            if self.C is not None:
                inner += self.C @ v
            r = self.M @ a + (1 + al) * inner - rhs_const
            return r, np.linalg.norm(r) / ref, a, v, fr, tg

        stalled = False
        r, rn, a, v, fr, tg = residual(q)
        history.append(rn)
        for _ in range(self.max_iterations):
            if rn <= self.rtol:
                break
            if self.tangent == "full" or (len(history) > 1 and history[-1] > self.refresh_ratio * history[-2]
                                          and rn > 1e2 * self.rtol):
                self._factor(tg, dt)
            if (rn <= max(1e2 * self.rtol, 1e-6) and len(history) >= 3 and history[-1] > 0.5 * history[-2]
                    and history[-2] > 0.5 * history[-3]):
                stalled = True      # round-off floor: the residual no longer decreases
                self.stats["stalled"] += 1
                break
            dq = sla.lu_solve(self._lus[dt], -r, check_finite=False)
            theta = 1.0
            while True:   # backtracking: stick/slip and open/closed switches can make full steps cycle
                trial = residual(q + theta * dq)
                if trial[1] < (1 - 1e-4 * theta) * rn or theta < 2 ** -10 or not np.isfinite(trial[1]):
                    break
                theta *= 0.5
            q = q + theta * dq
            r, rn, a, v, fr, tg = trial
            history.append(rn)
            if not np.isfinite(rn):
                break
        self.stats["iterations"] += len(history)
        if history[-1] > self.rtol and not stalled:
            raise TransientError(f"Newton did not converge in step t = {s.t:.6e} → {s.t + dt:.6e} s "
                                 f"(Δt {dt:.2e}): ‖R‖/ref history {[f'{h:.1e}' for h in history]}")
        new = State(s.t + dt, q, v, a, fr.state, s.step + 1, fr)
        return new, f0, fr, {"iterations": len(history), "history": history}

    def _events(self, old: list, f0: Forces, f1: Forces) -> int:
        """Elements that opened/closed or switched stick/slip in the step."""
        n = 0
        for F0, F1, s0, s1 in zip(f0.F, f1.F, old, f1.state):
            n += int(np.count_nonzero((F0 > 0) != (F1 > 0)))
            if isinstance(s1, CoulombState) and isinstance(s0, CoulombState):
                n += int(np.count_nonzero(s0.stick != s1.stick))
        return n

    def advance(self, s: State, dt: float, energy: dict, level: int = 0) -> State:
        """One base step, recursively halved (adaptive) on Newton failure or too many contact
        events; accumulates the works in ``energy``."""
        try:
            new, f0, f1, _ = self.try_step(s, dt)
            events = self._events(s.friction, f0, f1)
            ok = not self.adaptive or level >= self.max_halvings or events <= self.event_limit
        except TransientError:
            if not self.adaptive or level >= self.max_halvings:
                raise
            ok = False
        if not ok:
            self.stats["halvings"] += 1
            mid = self.advance(s, dt / 2, energy, level + 1)
            end = self.advance(mid, dt / 2, energy, level + 1)
            end.step = s.step + (level == 0)
            return end
        self.stats["events"] += events
        self.stats["steps"] += 1
        dq = new.q - s.q
        energy["W_ext"] += dq @ self.f
        energy["W_friction"] += 0.5 * dq @ (f0.g_friction + f1.g_friction)
        energy["W_normal"] -= 0.5 * dq @ (f0.g_normal + f1.g_normal)
        if self.C is not None:
            energy["D_damping"] += 0.5 * dq @ (self.C @ (s.v + new.v))
        if self.has_skew:
            energy["W_skew"] -= 0.5 * dq @ (self.K_skew @ (s.q + new.q))
        new.step = s.step + (level == 0)          # steps count base steps
        return new

    # ---------------------------------------------------------------- records
    def record(self, s: State, energy: dict, elements: bool = True) -> dict:
        """The recorded quantities at ``s``: state, energies, contact totals per interface and,
        with ``elements``, every element's normal force F and relative velocity w."""
        fr = s.forces if s.forces is not None else self.forces(s.q, s.v, None, 0.0, s.friction)
        rec = {"t": s.t, "q": s.q.copy(), "v": s.v.copy(),
               "kinetic": 0.5 * s.v @ (self.M @ s.v), "strain": 0.5 * s.q @ (self.K_sym @ s.q)}
        rec.update({k: energy[k] for k in ENERGY_KEYS[2:]})
        for cs, F, f, w, st in zip(self.model.contacts, fr.F, fr.f, fr.w, fr.state):
            rec[f"{cs.name}.normal_force"] = F.sum()
            rec[f"{cs.name}.friction_force"] = f[:, 0].sum()
            rec[f"{cs.name}.closed"] = int(np.count_nonzero(F > 0))
            if cs.radius is not None:
                rec[f"{cs.name}.torque"] = float(cs.radius @ f[:, 0])
            if isinstance(st, CoulombState):
                rec[f"{cs.name}.stuck"] = int(np.count_nonzero(st.stick))
            if elements:
                rec[f"{cs.name}.F"] = F.copy()
                rec[f"{cs.name}.w"] = w.copy()
        return rec


# -------------------------------------------------------------------- runs, output, checkpoints
def _stack(records: list[dict]) -> dict[str, np.ndarray]:
    return {k: np.asarray([r[k] for r in records]) for k in records[0]}


def _state_arrays(s: State, energy: dict) -> dict[str, np.ndarray]:
    out = {"t": np.array(s.t), "q": s.q, "v": s.v, "a": s.a, "step": np.array(s.step)}
    out.update({f"energy.{k}": np.array(v) for k, v in energy.items()})
    for i, st in enumerate(s.friction):
        if isinstance(st, CoulombState):
            out[f"friction{i}.z"] = st.z
            out[f"friction{i}.stick"] = st.stick
    return out


def run_transient(model: DynamicModel, q0: np.ndarray, v0: np.ndarray | None, t_end: float, dt: float, *,
                  record_every: int = 1, folder: str | os.PathLike | None = None, checkpoint_every: int = 0,
                  resume: bool = False, progress: bool = False, record_elements: bool = True,
                  **options) -> TransientResult:
    """Integrate from (q0, v0) at t = 0 to ``t_end`` with base step ``dt`` (options: see
    :class:`NewmarkHHT`).  Every ``record_every`` base steps the state, energies and contact
    totals are recorded.  With a ``folder`` the records are streamed there in chunks, each written
    atomically together with a checkpoint every ``checkpoint_every`` steps; ``resume`` restarts
    from that checkpoint (same model and options).  A Newton failure saves the last good state
    as the checkpoint and raises :class:`TransientError` naming it."""
    if not t_end > 0:
        raise TransientError(f"t_end: must be > 0 (got {t_end})")
    if record_every < 1:
        raise TransientError(f"record_every: must be >= 1 (got {record_every})")
    n_steps = int(round(t_end / dt))
    # a whole number of steps gives t_end/dt within round-off of an integer (1e-11 at 1e5 steps);
    # 1e-6 of a step accepts any round-off and refuses every real partial step
    if n_steps < 1 or abs(t_end / dt - n_steps) > 1e-6:
        raise TransientError(f"t_end: {t_end:g} s is not a whole number of steps dt = {dt:g} s "
                             f"(t_end/dt = {t_end / dt:.6g})")
    integ = NewmarkHHT(model, dt, **options)
    folder = Path(folder) if folder is not None else None
    meta = {"model": model.digest(), "dt": dt, "record_every": record_every,
            "options": {k: options[k] for k in sorted(options)}}
    energy = {k: 0.0 for k in ENERGY_KEYS[2:]}
    s = integ.initial_state(q0, v0)
    n_chunks, records = 0, []
    if folder is not None and resume and (folder / "checkpoint.npz").exists():
        s, energy, n_chunks = _load_checkpoint(folder, meta, model)
    elif folder is not None:
        for old in folder.glob("chunk_*.npz"):
            old.unlink()
    if s.step == 0:
        records.append(integ.record(s, energy, record_elements))
    t0 = time.perf_counter()

    def flush(state):
        nonlocal n_chunks, records
        if folder is None:
            return
        if records:
            write_npz_atomic(folder / f"chunk_{n_chunks:05d}.npz", _stack(records))
            n_chunks += 1
            records = []
        write_npz_atomic(folder / "checkpoint.npz", _state_arrays(state, energy))
        write_json_atomic(folder / "checkpoint.json",
                          {**meta, "chunks": n_chunks, "step": state.step, "t": state.t})

    with ProgressBar(n_steps, "transient", enabled=progress, unit=" steps") as bar:
        while s.step < n_steps:
            try:
                s = integ.advance(s, dt, energy)
            except TransientError as e:
                flush(s)
                where = f"; last good state (t = {s.t:.6e} s, step {s.step}) saved to {folder}" if folder else ""
                raise TransientError(f"{e}{where}") from e
            if s.step % record_every == 0:
                records.append(integ.record(s, energy, record_elements))
            if checkpoint_every and s.step % checkpoint_every == 0:
                flush(s)
            if progress and s.step % 200 == 0:
                bar.update(s.step)
    if s.step % record_every:          # the final state is always recorded
        records.append(integ.record(s, energy, record_elements))
    wall = time.perf_counter() - t0
    if folder is not None:
        flush(s)
        data = load_history(folder)
    else:
        data = _stack(records)
    stats = dict(integ.stats, wall_s=wall, n_steps=n_steps, model_size=model.size,
                 contact_elements=sum(cs.size for cs in model.contacts))
    return _result(data, stats)


def _result(data: dict[str, np.ndarray], stats: dict) -> TransientResult:
    energy = {k: data[k] for k in ENERGY_KEYS}
    contact = {k: v for k, v in data.items() if "." in k}
    return TransientResult(data["t"], data["q"], data["v"], energy, contact, stats)


def load_history(folder: str | os.PathLike) -> dict[str, np.ndarray]:
    """The records streamed to ``folder``, concatenated in time."""
    chunks = sorted(Path(folder).glob("chunk_*.npz"))
    if not chunks:
        raise TransientError(f"{folder}: no transient records (chunk_*.npz)")
    parts = [dict(np.load(c)) for c in chunks]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _load_checkpoint(folder: Path, meta: dict, model: DynamicModel):
    info = json.loads((folder / "checkpoint.json").read_text())
    for k in ("model", "dt", "record_every", "options"):
        if info.get(k) != json.loads(json.dumps(meta[k])):
            raise TransientError(f"resume: checkpoint in {folder} has a different {k} "
                                 f"({info.get(k)!r} vs {meta[k]!r}); remove it or run without resume")
    z = np.load(folder / "checkpoint.npz")
    states = []
    for i in range(len(model.contacts)):
        key = f"friction{i}"
        states.append(CoulombState(z[f"{key}.z"], z[f"{key}.stick"]) if f"{key}.z" in z else None)
    s = State(float(z["t"]), z["q"], z["v"], z["a"], states, int(z["step"]))
    energy = {k: float(z[f"energy.{k}"]) for k in ENERGY_KEYS[2:]}
    n_chunks = int(info["chunks"])
    for extra in sorted(folder.glob("chunk_*.npz"))[n_chunks:]:
        extra.unlink()     # written after the checkpoint by a run that then died
    return s, energy, n_chunks


def from_masa(model, speed: float | np.ndarray = 1.0, friction=None, radius=None) -> DynamicModel:
    """The dynamic model of a :class:`~fem_squeal.reduced.masa.MasaModel` (same K, C, f, points
    and normal laws).  Each interface's counter-face moves at ``speed`` [m/s] (per point, e.g.
    Ω r on a disc) in the direction of its signed μ; ``friction`` (a law, or a callable
    ``name -> law``) replaces the constant-μ sliding of the CEA/MASA, which is the default."""
    contacts = []
    for cs in model.contacts:
        sign = 1.0 if cs.mu >= 0 else -1.0
        V = (sign * np.broadcast_to(np.asarray(speed, float), (cs.size,)))[:, None]
        law = friction(cs.name) if callable(friction) else friction
        if law is None and cs.mu != 0:
            law = ConstantFriction(abs(cs.mu))
        r = radius(cs) if callable(radius) else radius
        contacts.append(FrictionContact(D=cs.D, T=cs.T, d0=cs.d0, normal=cs.normal, friction=law, V=V,
                                        radius=r, x=cs.x, name=cs.name))
    return DynamicModel(K=model.K, contacts=contacts, C=model.C, f=model.f)


def out_of_band_damping(K: np.ndarray, f_cut: float, zeta: float = 0.2) -> np.ndarray:
    """Modal damping 2ζω_j on the eigenvectors of sym(K) (M = I) above ``f_cut`` [Hz]:
    C_h = Σ_{f_j > f_cut} 2ζω_j φ_jφ_jᵀ.

    A reduced basis is accurate in its band only; its out-of-band vectors (static corrections,
    attachments) carry spurious high-frequency flutter that a transient would resolve and amplify
    (seed 002 keeps exact real modes for that reason).  Damping them leaves the in-band
    eigenvalues almost unchanged (check with :func:`~fem_squeal.reduced.eigensolve.quadratic_eigs`)."""
    if not f_cut > 0 or not zeta >= 0:
        raise TransientError(f"out-of-band damping: f_cut must be > 0 and zeta >= 0 (got {f_cut}, {zeta})")
    return modal_damping(K, lambda f: np.where(f > f_cut, zeta, 0.0))


def modal_damping(K: np.ndarray, zeta) -> np.ndarray:
    """C = Σ_j 2ζ(f_j)ω_j φ_jφ_jᵀ on the eigenvectors of sym(K) (M = I); ``zeta`` maps the
    frequencies f_j [Hz] to damping ratios (a number: the same ratio on every mode)."""
    w2, Phi = np.linalg.eigh(0.5 * (K + K.T))
    w = np.sqrt(np.maximum(w2, 0.0))
    z = zeta(w / (2 * np.pi)) if callable(zeta) else np.full_like(w, float(zeta))
    return (Phi * (2 * z * w)) @ Phi.T


def from_reduced(rm, omega: float, *, params: dict | None = None, cubic_share: float = 0.3, c_max: float = 0.0,
                 depth: float = np.inf, patches: tuple[int, int] | None = (8, 16), friction=None,
                 f_cut: float | None = None, zeta_cut: float = 0.2, axis=(0.0, 0.0, 1.0),
                 normal: str = "cubic", zeta: float = 0.0) -> DynamicModel:
    """The dynamic model of a reduced brake (:class:`~fem_squeal.reduced.model.ReducedModel`).

    ``normal="cubic"``: the contact laws of :func:`fem_squeal.reduced.masa.from_reduced` (tuned
    per interface at the mean preload pressure, with ``cubic_share`` and the damping c_max,
    depth).  ``normal="exponential"``: seed 002 eq. 2, p = p₀e^(λδ) per element with, per
    interface, λ = k_n/p̄ and p₀ = p̄/e (p̄: the area-weighted mean preload pressure), so that at
    the linear penalty's mean closure δ = p̄/k_n the pressure is p̄ and its tangent k_n.
    The points of each pad are grouped into n_r × n_θ polar ``patches`` (None: every
    quadrature point is an element).  The disc turns at ``omega`` [rad/s] about ``axis``: each
    element's counter-face speed is Ω r in the interface's sliding direction and its lever arm
    is r.  ``f_cut`` adds :func:`out_of_band_damping` above that frequency, and ``zeta`` a
    structural damping ratio on every mode (both on the tangent at steady sliding with the final
    laws; the reduced model itself carries no damping unless its materials do).

    Tangential penalty: a contact's k_t [N/m³] (``interfaces.<name>.kt``) acts across the sliding
    direction only and is linear in K (from the reduction, see :func:`~fem_squeal.reduced.masa.
    from_reduced`); the friction rows T are along the sliding direction only, so an
    :class:`~fem_squeal.reduced.laws.friction.ElasticCoulomb` stick spring k_t [N/m per element] is
    the same penalty along s: nothing is counted twice.  The two are consistent when the element's
    stick spring is the interface's k_t times the element's area (k_t·A_e): then a sticking element is
    held by k_t in both tangential directions, and in steady sliding the tangent along s vanishes (as
    in the CEA) while k_t stays across it."""

    if normal not in NORMAL_LAWS:
        raise TransientError(f"normal: must be one of {list(NORMAL_LAWS)} (got {normal!r})")
    exponential = NORMAL_LAWS[normal].law is ExponentialLaw
    mm = masa_model(rm, params, cubic_share=0.0 if exponential else cubic_share,
                    c_max=0.0 if exponential else c_max, depth=depth)
    sets = [aggregate(cs, polar_patches(cs.x, *patches, axis)) if patches else cs for cs in mm.contacts]
    a = np.asarray(axis, float) / np.linalg.norm(axis)

    def radius(cs):
        return np.linalg.norm(cs.x - np.outer(cs.x @ a, a), axis=1)

    dm = from_masa(MasaModel(K=mm.K, contacts=sets, C=mm.C, f=mm.f), speed=1.0, friction=friction, radius=radius)
    for cs in dm.contacts:
        cs.V = cs.V * (omega * cs.radius[:, None])
        if exponential:                     # the linear law's k_l is k_n × element area
            cr = rm.contacts[cs.name]
            closed = cr.active & (cr.pressure > 0)
            p_mean = float(cr.pressure[closed] @ cr.weight[closed] / cr.weight[closed].sum())
            kn = float(np.mean(cr.kn))
            cs.normal = ExponentialLaw(p0=p_mean / np.e, lam=kn / p_mean, weight=np.asarray(cs.normal.k_l) / kn)
    if f_cut or zeta:
        if zeta < 0 or (f_cut and not f_cut > 0):
            raise TransientError(f"damping: zeta must be >= 0 and f_cut > 0 (got {zeta}, {f_cut})")
        integ = NewmarkHHT(dm, 1.0)
        q = integ.steady_sliding(rm.q_static)
        Kt, _ = integ.tangent_matrices(q, np.zeros_like(q))
        Ch = modal_damping(Kt, lambda f: zeta + np.where(f > (f_cut or np.inf), zeta_cut, 0.0))
        dm.C = Ch if dm.C is None else dm.C + Ch
    return dm
