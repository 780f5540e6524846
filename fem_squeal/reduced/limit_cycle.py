"""Limit-cycle and time–frequency analysis of transient and pseudo-trajectories (seed 002 §3–4).

- :func:`detect_limit_cycle`: envelope saturation, frequency and amplitude of the cycle.
- :func:`space_time_svd`: the space–time decomposition X = U S Vᵀ of the cycle (seed 002 Fig. 8),
  optionally in the strain-energy norm ‖x‖²_W = xᵀWx (shapes W^(−½)U of the SVD of W^(½)X).
- :func:`mac`: modal assurance criterion |aᴴb|²/(aᴴa bᴴb) of two shape sets (Fig. 9), and
  :func:`plane_mac`: the share of a real shape in the plane of a complex mode.
- :func:`dynamic_stability`: tangent CEA at time samples along a cycle (Fig. 10).
- :func:`strain_energy_shares`: per-component share Re(ψᴴK_cψ)/Σ of a shape (Fig. 11).
- :func:`mode_cycle`: the complex-mode pseudo-trajectory Re(αψe^(iωt)) (eq. 6) or, with
  ``equilibrium``, its statically re-equilibrated version (eq. 7); braking torque and friction
  work per cycle along it (§4.2–4.3).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fem_squeal.reduced.eigensolve import TWO_PI, quadratic_eigs
from fem_squeal.util.errors import ModelError


@dataclass
class LimitCycle:
    saturated: bool
    frequency_hz: float
    amplitude: float           # half the peak-to-peak of the last window
    t_saturation: float        # first time the envelope is within ``tol`` of its final level
    growth_rate: float         # fitted e-folding rate of the envelope before saturation [1/s]
    envelope: np.ndarray

    def as_dict(self) -> dict:
        return {"saturated": self.saturated, "frequency_hz": self.frequency_hz, "amplitude": self.amplitude,
                "t_saturation": self.t_saturation, "growth_rate": self.growth_rate}


def dominant_frequency(t: np.ndarray, x: np.ndarray) -> float:
    """Peak of the Hann-windowed spectrum, refined by parabolic interpolation of log |X| [Hz]."""
    x = np.asarray(x, float) - np.mean(x)
    dt = float(np.mean(np.diff(t)))
    X = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    k = int(np.argmax(X[1:])) + 1
    if 1 <= k < len(X) - 1 and np.all(X[k - 1:k + 2] > 0):
        a, b, c = np.log(X[k - 1:k + 2])
        k = k + 0.5 * (a - c) / (a - 2 * b + c)
    return float(k / (len(x) * dt))


def detect_limit_cycle(t: np.ndarray, x: np.ndarray, *, window: float | None = None, tol: float = 0.05
                       ) -> LimitCycle:
    """Envelope saturation of the signal x(t).

    The envelope is |analytic signal| of x minus its moving mean (Hilbert), smoothed over ``window`` (default:
    10 periods of the dominant frequency of the last quarter).  The response has saturated when
    the envelope over the last three windows varies by less than ``tol`` (relative); the cycle's
    amplitude is half its peak-to-peak over the last window."""
    t, x = np.asarray(t, float), np.asarray(x, float)
    if len(t) < 16:
        raise ModelError(f"limit cycle: {len(t)} samples are too few")
    tail = t >= t[0] + 0.75 * (t[-1] - t[0])
    f = dominant_frequency(t[tail], x[tail])
    window = window or 10.0 / f
    dt = float(np.mean(np.diff(t)))
    n_w = max(int(round(window / dt)), 4)
    box = np.ones(min(n_w, len(x))) / min(n_w, len(x))
    trend = np.convolve(np.pad(x, (len(box) // 2, len(box) - 1 - len(box) // 2), mode="edge"), box, mode="valid")
    from scipy.signal import hilbert  # heavy: scipy.signal (0.6 s import; only the envelope needs it)

    env = np.abs(hilbert(x - trend))          # about the moving mean (the static offset can drift)
    env = np.convolve(np.pad(env, (len(box) // 2, len(box) - 1 - len(box) // 2), mode="edge"), box, mode="valid")
    last = x[-n_w:] if len(x) >= n_w else x
    amplitude = 0.5 * float(np.ptp(last))
    ends = [env[max(len(env) - k * n_w - n_w // 2, 0)] for k in (1, 2, 3)]
    final = ends[0]
    saturated = bool(len(env) > 4 * n_w and max(ends) - min(ends) <= tol * final)
    near = np.where(np.abs(env - final) <= tol * final)[0]
    near = near[near >= n_w // 2]
    t_sat = float(t[near[0]]) if saturated and len(near) else float("nan")
    grow = (env > 0) & (t < (t_sat if saturated else t[-1])) & (env < 0.5 * final)
    grow &= np.arange(len(t)) >= n_w // 2
    rate = float(np.polyfit(t[grow], np.log(env[grow]), 1)[0]) if grow.sum() > 8 else float("nan")
    return LimitCycle(saturated, f, amplitude, t_sat, rate, env)


def _sqrt_weight(W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """W^(½) and W^(−½) of the symmetric part of W (eigenvalues below 1e-12 max are dropped)."""
    w, V = np.linalg.eigh(0.5 * (W + W.T))
    keep = w > 1e-12 * w.max()
    s = np.sqrt(w[keep])
    return (V[:, keep] * s) @ V[:, keep].T, (V[:, keep] / s) @ V[:, keep].T


@dataclass
class SpaceTimeSVD:
    shapes: np.ndarray        # (m, r) columns, unit norm (2-norm, or the W-norm when weighted)
    singular: np.ndarray      # (r,)
    time: np.ndarray          # (r, n_t) participation (unit 2-norm rows)

    def energy_fraction(self) -> np.ndarray:
        s2 = self.singular ** 2
        return s2 / s2.sum()


def space_time_svd(X: np.ndarray, weight: np.ndarray | None = None, rank: int | None = None,
                   center: bool = True) -> SpaceTimeSVD:
    """SVD of the snapshots X (n_t, m) of a cycle (seed 002 Fig. 8).  ``weight`` W: SVD of
    W^(½)Xᵀ, shapes mapped back by W^(−½) (the strain-energy SVD when W is the stiffness)."""
    X = np.asarray(X, float)
    if center:
        X = X - X.mean(axis=0)
    A = X.T
    if weight is not None:
        Wh, Wih = _sqrt_weight(weight)
        A = Wh @ A
    U, S, Vt = np.linalg.svd(A, full_matrices=False)
    r = rank or len(S)
    U, S, Vt = U[:, :r], S[:r], Vt[:r]
    if weight is not None:
        U = Wih @ U
    return SpaceTimeSVD(U, S, Vt)


def mac(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """MAC matrix (columns of A against columns of B), complex shapes allowed."""
    A = np.atleast_2d(np.asarray(A).T).T
    B = np.atleast_2d(np.asarray(B).T).T
    num = np.abs(A.conj().T @ B) ** 2
    return num / np.outer(np.sum(np.abs(A) ** 2, axis=0), np.sum(np.abs(B) ** 2, axis=0))


def plane_mac(U: np.ndarray, Psi: np.ndarray) -> np.ndarray:
    """Share ‖P_j u_i‖²/‖u_i‖² of each real shape u_i (columns of U) in the plane span{Re ψ_j, Im ψ_j}
    of each complex mode (columns of Psi).  A complex (travelling) mode moves in that plane, so a
    real cycle shape made of it scores 1 here while its plain :func:`mac` with ψ can be as low
    as ½; for a real mode it equals the MAC."""
    U = np.atleast_2d(np.asarray(U, float).T).T
    out = np.empty((U.shape[1], Psi.shape[1]))
    for j in range(Psi.shape[1]):
        P = np.column_stack([Psi[:, j].real, Psi[:, j].imag])
        Q, R = np.linalg.qr(P)
        Q = Q[:, np.abs(np.diag(R)) > 1e-12 * np.abs(R).max()]
        out[:, j] = np.sum((Q.T @ U) ** 2, axis=0) / np.sum(U ** 2, axis=0)
    return out


def _mass_scaled(K: np.ndarray, C: np.ndarray | None, M: np.ndarray | None):
    if M is None:
        return K, C, None
    L = np.linalg.cholesky(0.5 * (M + M.T))
    Li = np.linalg.inv(L)
    return Li @ K @ Li.T, (Li @ C @ Li.T if C is not None else None), Li.T


def tangent_eigs(K: np.ndarray, C: np.ndarray | None, M: np.ndarray | None = None, vectors: bool = False):
    """Eigenvalues (and vectors in the model's coordinates) of λ²M + λC + K."""
    Ks, Cs, back = _mass_scaled(K, C, M)
    if not vectors:
        return quadratic_eigs(Ks, Cs)
    lam, Y = quadratic_eigs(Ks, Cs, vectors=True)
    return lam, (Y if back is None else back @ Y)


@dataclass
class DynamicStability:
    t: np.ndarray                 # (n_s,)
    eigenvalues: np.ndarray       # (n_s, m)
    shapes: np.ndarray | None     # (n_s, m, m) or None

    def in_band(self, band_hz: Sequence[float]) -> np.ndarray:
        f = self.eigenvalues.imag / TWO_PI
        return (f >= band_hz[0]) & (f <= band_hz[1])


def dynamic_stability(integ, t: np.ndarray, Q: np.ndarray, V: np.ndarray, vectors: bool = False
                      ) -> DynamicStability:
    """Tangent CEA (K_t, C_t of :meth:`NewmarkHHT.tangent_matrices`) at each sample (t, q, q̇)."""
    lams, shapes = [], []
    M = integ.model.M
    for q, v in zip(Q, V):
        Kt, Ct = integ.tangent_matrices(q, v)
        if vectors:
            lam, Y = tangent_eigs(Kt, Ct, M, vectors=True)
            shapes.append(Y)
        else:
            lam = tangent_eigs(Kt, Ct, M)
        lams.append(lam)
    return DynamicStability(np.asarray(t), np.array(lams), np.array(shapes) if vectors else None)


def strain_energy_shares(psi: np.ndarray, K_parts: dict[str, np.ndarray]) -> dict[str, float]:
    """Share Re(ψᴴK_cψ)/Σ_c of each component's strain energy in the shape ψ (seed 002 Fig. 11)."""
    e = {k: float(np.real(np.conj(psi) @ (K @ psi))) for k, K in K_parts.items()}
    tot = sum(e.values())
    return {k: v / tot for k, v in e.items()} if tot > 0 else {k: float("nan") for k in e}


def follow_mode(ds: DynamicStability, start: complex) -> np.ndarray:
    """Index per sample of the eigenvalue continuing ``start`` (nearest to the previous one)."""
    idx, prev = [], start
    for lam in ds.eigenvalues:
        j = int(np.argmin(np.abs(lam - prev)))
        idx.append(j)
        prev = lam[j]
    return np.array(idx)


@dataclass
class ModeCycle:
    t: np.ndarray             # pseudo-time over one period
    q: np.ndarray             # (n_t, m)
    v: np.ndarray
    torque: np.ndarray        # Σ r f along the first tangential direction [N m] (nan without radii)
    friction_work: float      # ∮ (Σ Tᵀf)ᵀ q̇ dt over the cycle [J]
    normal_force: np.ndarray  # total normal force along the cycle [N]
    converged: np.ndarray     # eq. 7's static solves (all True for eq. 6)


def mode_cycle(integ, q_s: np.ndarray, psi: np.ndarray, omega: float, alpha: float, *, n: int = 64,
               equilibrium: bool = False, tol: float = 1e-10, max_iterations: int = 30) -> ModeCycle:
    """The complex-mode cycle ψ(t) = q_s + Re(αψe^(iωt)) of seed 002 eq. 6, or with
    ``equilibrium`` its re-equilibrated version eq. 7: at each pseudo-time q̃ solves
    K q̃ + g(q̃, ψ̇) = f − Mψ̈ − Cψ̇ (inertia and damping of the trajectory as loads), and the
    velocity is then the finite difference of q̃ around the (periodic) cycle."""
    model = integ.model
    t = np.arange(n) * (TWO_PI / omega) / n
    e = np.exp(1j * omega * t)[:, None]
    Q = q_s + np.real(alpha * psi[None, :] * e)
    Vel = np.real(1j * omega * alpha * psi[None, :] * e)
    Acc = np.real(-omega ** 2 * alpha * psi[None, :] * e)
    states = [cs.friction.initial_state(cs.size, cs.n_dir) if cs.friction is not None else None
              for cs in model.contacts]
    ok = np.ones(n, bool)
    if equilibrium:
        M = model.mass()
        Qe = np.empty_like(Q)
        q = q_s.copy()
        for k in range(n):
            load = integ.f - M @ Acc[k] - (integ.C @ Vel[k] if integ.C is not None else 0.0)
            for _ in range(max_iterations):
                fr = integ.forces(q, Vel[k], None, 0.0, states)
                r = integ.K @ q + fr.g_normal - fr.g_friction - load
                if np.linalg.norm(r) <= tol * max(np.linalg.norm(load), 1e-300):
                    break
                Kt, _ = integ.tangent_matrices(q, Vel[k], states)
                q = q - np.linalg.solve(Kt, r)
            else:
                ok[k] = False
            Qe[k] = q
        Q = Qe
        h = t[1] - t[0]
        Vel = (np.roll(Q, -1, axis=0) - np.roll(Q, 1, axis=0)) / (2 * h)
    torque, work_rate, normal = np.zeros(n), np.zeros(n), np.zeros(n)
    has_r = any(cs.radius is not None for cs in model.contacts)
    for k in range(n):
        fr = integ.forces(Q[k], Vel[k], None, 0.0, states)
        work_rate[k] = fr.g_friction @ Vel[k]
        normal[k] = sum(F.sum() for F in fr.F)
        torque[k] = sum(float(cs.radius @ f[:, 0]) for cs, f in zip(model.contacts, fr.f)
                        if cs.radius is not None) if has_r else np.nan
    work = float(work_rate.sum() * (t[1] - t[0]))     # periodic trapezoid = rectangle rule
    return ModeCycle(t, Q, Vel, torque, work, normal, ok)
