"""Segmented (sintered) brake pad of a high-speed train on a rotating disc (seed 004): a lumped
multibody model, no finite elements.

N friction elements (default 9, a 3 × 3 grid) of mass m_e sit on the disc face at radius R about
the disc axis.  Each has three DOFs (in-plane x, y and normal z, z > 0 away from the disc).
Neighbouring elements are linked by in-plane springs k (seed: 400 N/mm); the outer ones are also
linked in-plane to the plate, which only moves along z (translation joint).  Every element hangs
on the plate through a normal spring k_z; the plate (mass m_p) is pressed with the force F toward
the disc.  Element j touches the disc through the normal law of seed 004 eqs. 2–3
(F_j = max(k_c δ + c(δ)δ̇, 0), δ = −z_j) and rubs on it with the 2D Stribeck law of eq. 4
(μ_s, μ_d, v_s, v_d) against the disc surface velocity V_j = Ω ẑ × r_j.

DOF order: (x_j, y_j, z_j) for j = 0 … N−1, then z_plate.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fem_squeal.reduced.laws.contact import UnilateralLaw
from fem_squeal.reduced.laws.friction import StribeckFriction
from fem_squeal.reduced.transient import DynamicModel, FrictionContact, NewmarkHHT, run_transient
from fem_squeal.util.blas import single_threaded
from fem_squeal.util.errors import ModelError


@dataclass(frozen=True)
class SegmentedPad:
    """Parameters (SI units).  Seed 004 gives μ_s, μ_d, k and F; the rest are chosen for a
    sintered puck (≈ 50 g, 30 mm pitch) on a 0.25 m-radius disc and stated here once."""

    n_side: int = 3                 # elements per side of the square grid (N = n_side²)
    pitch: float = 0.03             # element spacing [m]
    radius: float = 0.25            # mean friction radius [m]
    m_element: float = 0.05         # [kg]
    m_plate: float = 1.0            # [kg]
    k: float = 4.0e5                # in-plane link stiffness (seed: 400 N/mm) [N/m]
    k_z: float = 4.0e5              # element–plate normal stiffness [N/m]
    k_contact: float = 1.0e7        # element–disc contact stiffness k_c [N/m]
    c_max: float = 200.0            # contact damping at full penetration depth (eq. 3) [N s/m]
    depth: float = 1.0e-5           # penetration l at which c reaches c_max [m]
    force: float = 300.0            # plate load F (seed) [N]
    mu_s: float = 0.6
    mu_d: float = 0.3
    v_s: float = 1.0e-3             # stiction transition velocity [m/s]
    v_d: float = 3.3e-2             # dynamic transition velocity [m/s]

    def __post_init__(self):
        for name in ("pitch", "radius", "m_element", "m_plate", "k", "k_z", "k_contact", "depth", "force",
                     "v_s", "v_d"):
            if not getattr(self, name) > 0:
                raise ModelError(f"segmented_pad.{name}: must be > 0 (got {getattr(self, name)})")
        if self.n_side < 1:
            raise ModelError(f"segmented_pad.n_side: must be >= 1 (got {self.n_side})")
        if not self.v_d > self.v_s:
            raise ModelError(f"segmented_pad.v_d: must be > v_s = {self.v_s} (got {self.v_d})")

    @property
    def n_elements(self) -> int:
        return self.n_side ** 2

    def positions(self) -> np.ndarray:
        """(N, 2) element centres; the grid is centred at (R, 0), x radial, y along the rotation."""
        g = (np.arange(self.n_side) - (self.n_side - 1) / 2) * self.pitch
        X, Y = np.meshgrid(g, g, indexing="ij")
        return np.column_stack([self.radius + X.ravel(), Y.ravel()])

    def links(self) -> tuple[list[tuple[int, int]], list[int]]:
        """Neighbour pairs of the grid and the outer elements (linked to the plate)."""
        n = self.n_side
        idx = np.arange(n * n).reshape(n, n)
        pairs = [(int(idx[i, j]), int(idx[i + 1, j])) for i in range(n - 1) for j in range(n)]
        pairs += [(int(idx[i, j]), int(idx[i, j + 1])) for i in range(n) for j in range(n - 1)]
        outer = [int(idx[i, j]) for i in range(n) for j in range(n) if i in (0, n - 1) or j in (0, n - 1)]
        return pairs, outer


def build(pad: SegmentedPad, omega: float) -> DynamicModel:
    """The dynamic model at disc speed ``omega`` [rad/s] (module docstring)."""
    N = pad.n_elements
    m = 3 * N + 1
    zp = 3 * N
    M = np.diag(np.r_[np.full(3 * N, pad.m_element), pad.m_plate])
    K = np.zeros((m, m))

    def spring(a: int, b: int | None, k: float) -> None:
        K[a, a] += k
        if b is not None:
            K[b, b] += k
            K[a, b] -= k
            K[b, a] -= k

    pairs, outer = pad.links()
    for i, j in pairs:
        for d in (0, 1):
            spring(3 * i + d, 3 * j + d, pad.k)
    for i in outer:
        for d in (0, 1):
            spring(3 * i + d, None, pad.k)          # the plate does not move in-plane
    for i in range(N):
        spring(3 * i + 2, zp, pad.k_z)
    f = np.zeros(m)
    f[zp] = -pad.force
    D = np.zeros((N, m))
    T = np.zeros((2, N, m))
    for i in range(N):
        D[i, 3 * i + 2] = -1.0                     # closure δ = −z
        T[0, i, 3 * i] = 1.0
        T[1, i, 3 * i + 1] = 1.0
    r = pad.positions()
    V = omega * np.column_stack([-r[:, 1], r[:, 0]])   # Ω ẑ × r
    law = UnilateralLaw(k_l=np.full(N, pad.k_contact), c_max=np.full(N, pad.c_max), depth=np.full(N, pad.depth))
    friction = StribeckFriction(pad.mu_s, pad.mu_d, pad.v_s, pad.v_d)
    contact = FrictionContact(D=D, T=T, d0=np.zeros(N), normal=law, friction=friction, V=V,
                              radius=np.linalg.norm(r, axis=1), x=np.column_stack([r, np.zeros(N)]), name="pad")
    return DynamicModel(K=K, contacts=[contact], M=M, f=f)


@dataclass
class PadRun:
    speed: float              # disc surface speed at the mean radius [m/s]
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    w: np.ndarray             # (n_t, N, 2) velocity of each element relative to the disc
    normal: np.ndarray        # (n_t, N) contact forces
    regime: list[str]         # per element
    fractions: np.ndarray     # (N, 3): time shares with |w| < v_s, v_s..v_d (falling branch), ≥ v_d
    stats: dict


def classify(w: np.ndarray, speed: float, v_s: float, v_d: float, eps: float = 0.1
             ) -> tuple[list[str], np.ndarray]:
    """Regime of each element from its sliding speed s = |w| over the analysed window.

    The smooth law of eq. 4 has no true stick, only creep below v_s; a real stick phase drives
    s to ~1e-4–5e-3 v_s, a creep cycle keeps it at 0.15–0.95 v_s (the element never catches
    up with the disc: the straight segments of the seed's Fig. 5).  With an oscillation
    (ptp s > 1 % of the disc speed):

    - "stick-slip": min s < ``eps``·v_s;
    - "creep": eps·v_s ≤ min s < v_d (the cycle lives on the falling branch);
    - "periodic": min s ≥ v_d (always sliding on the flat μ_d branch).

    Without one: "steady creep" (mean s < v_d) or "steady".  Also returned: the time shares
    (N, 3) of s < v_s, v_s ≤ s < v_d and s ≥ v_d."""
    s = np.linalg.norm(w, axis=-1)                       # (n_t, N)
    low = (s < v_s).mean(axis=0)
    band = ((s >= v_s) & (s < v_d)).mean(axis=0)
    high = (s >= v_d).mean(axis=0)
    regimes = []
    for j in range(s.shape[1]):
        sj = s[:, j]
        if np.ptp(sj) > 0.01 * speed:
            regimes.append("stick-slip" if sj.min() < eps * v_s else "creep" if sj.min() < v_d else "periodic")
        else:
            regimes.append("steady creep" if sj.mean() < v_d else "steady")
    return regimes, np.column_stack([low, band, high])


def simulate(pad: SegmentedPad, speed: float, *, t_end: float = 0.3, dt: float = 4e-5, alpha: float = -0.3,
             analyse_from: float = 0.5, kick: float = 1e-3, record_every: int = 2,
             tangent: str = "full") -> PadRun:
    """Run the pad at disc surface speed ``speed`` [m/s] (at the mean radius) from steady
    sliding, with the elements kicked by ``kick`` [m/s] radially (alternating signs), and
    classify the regime over t ≥ ``analyse_from``·t_end.  HHT α = −0.3 damps the stiff
    sub-v_s branch of the law (its time constant m/(μ'(0)F) is a few µs)."""
    if not speed > 0:
        raise ModelError(f"segmented_pad speed: must be > 0 (got {speed})")
    with single_threaded():
        return _simulate(pad, speed, t_end, dt, alpha, analyse_from, kick, record_every, tangent)


def _simulate(pad, speed, t_end, dt, alpha, analyse_from, kick, record_every, tangent) -> PadRun:
    model = build(pad, speed / pad.radius)
    integ = NewmarkHHT(model, dt, alpha=alpha)
    N = pad.n_elements
    q_guess = np.zeros(model.size)
    per = pad.force / N
    q_guess[2:3 * N:3] = -per / pad.k_contact
    q_guess[3 * N] = q_guess[2] - per / pad.k_z
    q0 = integ.steady_sliding(q_guess)
    v0 = np.zeros(model.size)
    v0[0:3 * N:3] = kick * (-1.0) ** np.arange(N)
    res = run_transient(model, q0, v0, t_end, dt, alpha=alpha, record_every=record_every, tangent=tangent)
    w = res.contact["pad.w"]
    late = res.t >= analyse_from * t_end
    regimes, fractions = classify(w[late], speed, pad.v_s, pad.v_d)
    return PadRun(speed, res.t, res.q, res.v, w, res.contact["pad.F"], regimes, fractions, res.stats)
