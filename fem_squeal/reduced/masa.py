"""Modal Amplitude Stability Analysis (seed 000) on a reduced model.

Coordinates q on a mass-orthonormal basis (M = I).  Each contact element j has the closure
δ_j = δ₀_j + D_j q (D = −G_nΦ: closure per unit q) and the slip row T_j = G_tΦ along the sliding
direction; its normal force F_j(δ, δ̇) (:mod:`.contact_law`) acts on the structure through
B_j = D_j − μT_j (normal push plus the friction drag μF_j of the sliding counter-face), so

    F_nl(q) = Σ_j B_jᵀ F_j(δ_j)                                   (seed 000 eq. 1)
    K q + F_nl(q) = f                                              (eq. 4, static equilibrium)
    J_nl = Σ_j B_jᵀ ∂_δF_j(δ_s) D_j,   C_nl = Σ_j B_jᵀ ∂_δ̇F_j(δ_s) D_j    (tangents at q_s)
    (λ²I + λ(C + C_nl) + K + J_nl) y = 0                          (eq. 6, the CEA)

MASA, for an unstable CEA pair (λ_i = a_i + jω_i, y_i) and modal amplitudes p:
X = p y_i / |(y_i; jω_i y_i)| (eqs. 23–25; ψ and ω stay at their p = 0 values unless
``update_shape``), the element motions Δδ_j(t) = 2 Re(D_j X e^{jωt}) are linearised to first
harmonic by AFT (:mod:`.aft`, eq. 18) giving k_j, c_j, and

    K₁ = Σ_j B_jᵀ k_j D_j,   C₁ = Σ_j B_jᵀ c_j D_j                  (eq. 14)
    A = [[0, I], [−(K + J_nl + K₁), −(C + C_nl + C₁)]]               (eq. 20)

whose eigenvalues in the band are recorded for every p.  The static state and J_nl use the
contact *points*; the AFT remainder may use coarser *elements* (area-weighted patches of points,
:func:`aggregate`), which keeps the CEA at p = 0 exact and costs O(n_elements·m²) per step.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fem_squeal.reduced.aft import NO_CONTACT, contact_status, first_harmonic
from fem_squeal.reduced.contact_rows import ContactRows, check_columns, checked_rows
from fem_squeal.reduced.eigensolve import TWO_PI, quadratic_eigs, unstable
from fem_squeal.reduced.laws.contact import UnilateralLaw, tune_cubic
from fem_squeal.reduced.model import MU, ReducedModel
from fem_squeal.util.errors import MasaError
from fem_squeal.util.progress import ProgressBar


def _check_masa_rows(cs: ContactRows) -> None:
    """MASA's needs of a contact set: the closure at q = 0 and a normal law its AFT can take."""
    n = cs.size
    if cs.d0 is None:
        raise MasaError(f"{cs.name}.d0: MASA needs the closure at q = 0")
    law = cs.normal
    if not getattr(law, "aft", False):     # the law declares it (fem_squeal.reduced.laws.contact)
        raise MasaError(f"{cs.name}.law: MASA's AFT needs the cubic UnilateralLaw (its remainder and "
                        f"k_l, k_nl, c_max; a law with aft = True); got {type(law).__name__}")
    for a in ("k_l", "k_nl", "c_max"):
        v = np.asarray(getattr(law, a))
        if v.ndim and v.shape != (n,):
            raise MasaError(f"{cs.name}.law.{a}: {v.shape[0]} values for {n} contact points")


def ContactSet(D: np.ndarray, T: np.ndarray, d0: np.ndarray, law: UnilateralLaw, mu: float = 0.0,
               weight: np.ndarray | None = None, x: np.ndarray | None = None, name: str = "contact"
               ) -> ContactRows:
    """Contact points (or elements) of one frictional interface, on the basis (module docstring; the
    old name): :class:`~fem_squeal.reduced.contact_rows.ContactRows` with closure rows D (= −G_nΦ),
    slip rows T (= G_tΦ), closure d0 at q = 0, the normal ``law`` and the signed μ along T."""
    cs = checked_rows(MasaError, D=D, T=T, d0=np.asarray(d0, float), normal=law, mu=mu, weight=weight, x=x,
                      name=name)
    _check_masa_rows(cs)
    return cs


@dataclass
class MasaModel:
    """K (without the nonlinear contacts, eq. 2's K_nl), C, load f and the contact sets."""

    K: np.ndarray
    contacts: list[ContactRows]
    C: np.ndarray | None = None
    f: np.ndarray | None = None
    elements: list[ContactRows] | None = None   # AFT elements (default: the points themselves)

    def __post_init__(self):
        m = self.K.shape[0]
        if self.K.shape != (m, m):
            raise MasaError(f"K: must be square (got {self.K.shape})")
        if self.C is not None and self.C.shape != (m, m):
            raise MasaError(f"C: must be {m}×{m} (got {self.C.shape})")
        if self.f is not None and self.f.shape != (m,):
            raise MasaError(f"f: must have {m} entries (got {self.f.shape})")
        if not self.contacts:
            raise MasaError("contacts: MASA needs at least one nonlinear contact interface")
        check_columns(self.contacts + (self.elements or []), m, MasaError)
        for cs in self.contacts + (self.elements or []):
            _check_masa_rows(cs)

    @property
    def size(self) -> int:
        return self.K.shape[0]

    @property
    def aft_sets(self) -> list[ContactRows]:
        return self.elements if self.elements is not None else self.contacts


# ---------------------------------------------------------------- static equilibrium (eq. 4)
@dataclass
class Equilibrium:
    q: np.ndarray
    closure: list[np.ndarray]      # δ_s per contact set (points)
    iterations: int
    residual: float                # ‖K q + F_nl − f‖ / ‖f‖
    history: list[float]           # relative residual per iteration

    def as_dict(self) -> dict:
        return {"iterations": self.iterations, "residual": self.residual, "history": self.history,
                "closed_points": int(sum(int((d > 0).sum()) for d in self.closure)),
                "points": int(sum(d.size for d in self.closure))}


def _residual(model: MasaModel, q: np.ndarray, f: np.ndarray) -> np.ndarray:
    r = model.K @ q - f
    for cs in model.contacts:
        r += cs.B.T @ cs.normal.force(cs.closure(q))
    return r


def _jacobian(model: MasaModel, closures: Sequence[np.ndarray], sets: Sequence[ContactRows] | None = None,
              base: np.ndarray | None = None, what: str = "stiffness") -> np.ndarray:
    """base + Σ Bᵀ diag(∂F) D with ∂F the law's ``stiffness`` or ``viscosity`` at the closures."""
    sets = model.contacts if sets is None else sets
    J = np.zeros((model.size,) * 2) if base is None else base.copy()
    for cs, d in zip(sets, closures):
        k = getattr(cs.normal, what)(d)
        if np.any(k):
            J += cs.B.T @ (k[:, None] * cs.D)
    return J


def static_equilibrium(model: MasaModel, q0: np.ndarray | None = None, *, tol: float = 1e-10,
                       max_iterations: int = 50) -> Equilibrium:
    """Newton's method with a backtracking (Armijo) line search on ‖R‖ for eq. 4.

    Semi-smooth at contact loss (∂F = 0 where open).  Converged when ‖R‖ ≤ tol·‖f‖; raises
    :class:`MasaError` with the residual history otherwise (or when the tangent is singular,
    e.g. a body held only by contacts that are all open)."""
    f = model.f if model.f is not None else np.zeros(model.size)
    scale = np.linalg.norm(f)
    q = np.zeros(model.size) if q0 is None else np.array(q0, float)
    if scale == 0:
        scale = 1.0
    R = _residual(model, q, f)
    history = [float(np.linalg.norm(R) / scale)]
    for it in range(1, max_iterations + 1):
        if history[-1] <= tol:
            break
        J = _jacobian(model, [cs.closure(q) for cs in model.contacts], base=model.K)
        try:
            dq = np.linalg.solve(J, -R)
        except np.linalg.LinAlgError as e:
            raise MasaError(f"static equilibrium: singular tangent at iteration {it} ({e}); "
                            f"residual history {history}") from e
        alpha, r0 = 1.0, np.linalg.norm(R)
        while True:
            Rn = _residual(model, q + alpha * dq, f)
            if np.linalg.norm(Rn) <= (1 - 1e-4 * alpha) * r0 or alpha < 2 ** -20:
                break
            alpha *= 0.5
        q = q + alpha * dq
        R = Rn
        history.append(float(np.linalg.norm(R) / scale))
    else:
        if history[-1] > tol:
            raise MasaError(f"static equilibrium: ‖R‖/‖f‖ = {history[-1]:.2e} > tol {tol:.0e} after "
                            f"{max_iterations} Newton iterations; history {[f'{h:.2e}' for h in history]}")
    return Equilibrium(q, [cs.closure(q) for cs in model.contacts], len(history) - 1, history[-1], history)


def linearise(model: MasaModel, eq: Equilibrium) -> tuple[np.ndarray, np.ndarray | None]:
    """K + J_nl and C + C_nl at the equilibrium (eq. 6); C is None when both are zero."""
    K = _jacobian(model, eq.closure, base=model.K)
    damped = any(cs.normal.damped for cs in model.contacts)
    if model.C is None and not damped:
        return K, None
    C = model.C.copy() if model.C is not None else np.zeros_like(K)
    if damped:
        C = _jacobian(model, eq.closure, base=C, what="viscosity")
    return K, C


def element_closures(model: MasaModel, eq: Equilibrium) -> list[np.ndarray]:
    """Static closure of every AFT element."""
    return [cs.closure(eq.q) for cs in model.aft_sets]


# ---------------------------------------------------------------- elements
def aggregate(cs: ContactRows, labels: np.ndarray, name: str | None = None) -> ContactRows:
    """Contact elements from groups of points (``labels``: group of each point, −1 = left out).

    Element rows are the area-weighted means of its points' rows; k_l, k_nl, c_max add up (a
    patch closing uniformly carries the sum of its points' forces), the depth l is the mean."""
    labels = np.asarray(labels)
    if labels.shape != (cs.size,):
        raise MasaError(f"{cs.name}: {labels.shape} labels for {cs.size} points")
    w = cs.weight if cs.weight is not None else np.ones(cs.size)
    groups = np.unique(labels[labels >= 0])
    P = np.zeros((len(groups), cs.size))
    P[np.searchsorted(groups, labels[labels >= 0]), np.flatnonzero(labels >= 0)] = w[labels >= 0]
    area = P.sum(axis=1)
    S = P / area[:, None]

    def total(v):
        return (P > 0) @ np.broadcast_to(np.asarray(v, float), (cs.size,))

    depth = np.broadcast_to(np.asarray(cs.normal.depth, float), (cs.size,))
    depth = S @ depth if np.all(np.isfinite(depth)) else np.full(len(groups), np.inf)
    law = UnilateralLaw(k_l=total(cs.normal.k_l), k_nl=total(cs.normal.k_nl), c_max=total(cs.normal.c_max),
                        depth=depth)
    return ContactRows(D=S @ cs.D, T=np.stack([S @ t for t in cs.T]), d0=S @ cs.d0, normal=law, mu=cs.mu,
                       weight=area, x=S @ cs.x if cs.x is not None else None, name=name or cs.name)


def polar_patches(x: np.ndarray, n_radial: int, n_angular: int, axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Labels of an n_radial × n_angular polar grid (about ``axis``) over the points' extent."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    e1 = np.cross(a, [1.0, 0, 0]) if abs(a[0]) < 0.9 else np.cross(a, [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    r = np.linalg.norm(x - np.outer(x @ a, a), axis=1)
    phi = np.arctan2(x @ e2, x @ e1)
    mid = np.angle(np.mean(np.exp(1j * phi)))        # a pad spans < 2π: angles about its centre
    t = np.angle(np.exp(1j * (phi - mid)))

    def bins(v, n):
        lo, hi = v.min(), v.max()
        return np.minimum(((v - lo) / max(hi - lo, 1e-300) * n).astype(int), n - 1)

    return bins(r, n_radial) * n_angular + bins(t, n_angular)


# ---------------------------------------------------------------- the sweep (eqs. 14–25)
@dataclass
class Instability:
    """An unstable pair of the CEA at equilibrium: λ = a + jω and its reduced shape y."""

    index: int          # position in the CEA's in-band list (ascending frequency)
    lam: complex
    y: np.ndarray

    @property
    def freq_hz(self) -> float:
        return float(self.lam.imag / TWO_PI)


@dataclass
class MasaResult:
    """One instability's amplitude sweep (the seed's Figs. 4–10 and Table 1 row)."""

    index: int
    freq_hz: float                    # of the instability at p = 0
    real_part: float                  # its Re λ at p = 0 [1/s]
    amplitudes: np.ndarray            # (n,) the p evaluated (fewer than asked after a sweep break)
    eigenvalues: np.ndarray           # (n, n_max) every eigenvalue in the band, NaN-padded
    tracked: np.ndarray               # (n,) the instability's own eigenvalue
    status: np.ndarray                # (n, n_elements) contact status (aft.NO_CONTACT/PERMANENT/IMPACTS)
    interface_amplitude: np.ndarray   # (n,) largest normal vibration amplitude of an element [m]
    stationary: list[float] = field(default_factory=list)   # p where Re(tracked) crosses 0
    broke_at: float | None = None     # p of the sweep break
    update_shape: bool = False
    steps: int = 0                    # state matrices solved (sweep + refinement)

    def unstable_counts(self, growth_tol: float = 1e-6) -> np.ndarray:
        lam = np.nan_to_num(self.eigenvalues, nan=0.0)
        return np.sum(unstable(lam, growth_tol), axis=1)

    def as_dict(self) -> dict:
        lam = self.eigenvalues
        ok = ~np.isnan(lam)
        return {"index": self.index, "freq_hz": self.freq_hz, "real_part": self.real_part,
                "amplitudes": self.amplitudes.tolist(), "tracked_real": self.tracked.real.tolist(),
                "tracked_freq_hz": (self.tracked.imag / TWO_PI).tolist(),
                "stationary_amplitudes": self.stationary, "broke_at": self.broke_at,
                "update_shape": self.update_shape, "steps": self.steps,
                "interface_amplitude_m": self.interface_amplitude.tolist(),
                "unstable_counts": self.unstable_counts().tolist(),
                "eigenvalues": [{"real": lam[i, ok[i]].real.tolist(),
                                 "freq_hz": (lam[i, ok[i]].imag / TWO_PI).tolist()} for i in range(len(lam))],
                "impacting_elements": (self.status == 2).sum(axis=1).tolist(),
                "open_elements": (self.status == NO_CONTACT).sum(axis=1).tolist()}


def _in_band(lam: np.ndarray, band_hz) -> np.ndarray:
    f = lam.imag / TWO_PI
    return (f > max(band_hz[0], 0.0)) & (f <= band_hz[1])


def instabilities(K: np.ndarray, C: np.ndarray | None, band_hz, growth_tol: float = 1e-6) -> list[Instability]:
    """The unstable pairs in the band of (λ²I + λC + K)y = 0 (the CEA of eq. 6)."""
    lam, Y = quadratic_eigs(K, C, vectors=True)
    sel = np.flatnonzero(_in_band(lam, band_hz))
    return [Instability(int(n), complex(lam[j]), Y[:, j]) for n, j in enumerate(sel)
            if unstable(lam[j], growth_tol)]


def modal_displacement(y: np.ndarray, omega: float, p: float) -> np.ndarray:
    """X = p y / |(y; jωy)| (eqs. 23–25)."""
    return p * y / (np.linalg.norm(y) * np.sqrt(1.0 + omega * omega))


class MasaProblem:
    """MASA about one static equilibrium: owns the CEA matrices and the element closures and
    evaluates the state matrix of eq. 20 for a given mode shape, frequency and amplitude."""

    def __init__(self, model: MasaModel, eq: Equilibrium, band_hz, *, n_samples: int = 64,
                 growth_tol: float = 1e-6):
        if not (len(band_hz) == 2 and 0 <= band_hz[0] < band_hz[1]):
            raise MasaError(f"band_hz: need 0 <= low < high (got {band_hz})")
        if n_samples < 8:
            raise MasaError(f"n_samples: must be >= 8 (got {n_samples})")
        self.model, self.eq, self.band = model, eq, tuple(band_hz)
        self.n_samples, self.growth_tol = int(n_samples), float(growth_tol)
        self.K, self.C = linearise(model, eq)
        self.d_el = element_closures(model, eq)
        self.damped_law = any(cs.normal.damped for cs in model.aft_sets)
        self.n_elements = sum(cs.size for cs in model.aft_sets)

    def instabilities(self) -> list[Instability]:
        return instabilities(self.K, self.C, self.band, self.growth_tol)

    def loss_amplitude(self, inst: Instability) -> float:
        """The smallest p at which an element closed at equilibrium starts losing contact
        (δ_s = 2|D X(p)|); inf if none ever does."""
        X = modal_displacement(inst.y, inst.lam.imag, 1.0)
        best = np.inf
        for cs, d in zip(self.model.aft_sets, self.d_el):
            a = 2 * np.abs(cs.D @ X)
            ok = (d > 0) & (a > 0)
            if ok.any():
                best = min(best, float(np.min(d[ok] / a[ok])))
        return best

    def state(self, y: np.ndarray, omega: float, p: float, vectors: bool = False):
        """Eigenvalues in the band of eq. 20 at amplitude p (and their vectors), the element
        contact status and the largest element vibration amplitude."""
        X = modal_displacement(y, omega, p)
        K = self.K.copy()
        C = None if self.C is None and not self.damped_law else \
            (self.C.copy() if self.C is not None else np.zeros_like(K))
        status, amp = [], 0.0
        for cs, d in zip(self.model.aft_sets, self.d_el):
            z = cs.D @ X
            a = 2.0 * np.abs(z)
            status.append(contact_status(d, a))
            amp = max(amp, float(a.max(initial=0.0)))
            if p == 0:
                continue
            h = first_harmonic(cs.normal, d, 2.0 * z.real, -2.0 * z.imag, omega, self.n_samples)
            B = cs.B
            K += B.T @ (h.k[:, None] * cs.D)
            if cs.normal.damped:  # an elastic law has c = 0 exactly (the remainder is even in time)
                C += B.T @ (h.c[:, None] * cs.D)
        out = quadratic_eigs(K, C, vectors=vectors)
        lam, Y = out if vectors else (out, None)
        sel = _in_band(lam, self.band)
        return lam[sel], (Y[:, sel] if vectors else None), np.concatenate(status), amp


def _nearest(lam: np.ndarray, target: complex) -> int:
    return int(np.argmin(np.abs(lam - target)))


def _pad(rows: list[np.ndarray]) -> np.ndarray:
    n = max((len(r) for r in rows), default=0)
    out = np.full((len(rows), n), np.nan + 1j * np.nan)
    for i, r in enumerate(rows):
        out[i, :len(r)] = r
    return out


def _follow(lam: np.ndarray, prev: complex, prev2: complex | None) -> int | None:
    """Index in ``lam`` of the continued eigenvalue: nearest to the linear prediction from the two
    previous steps (to the previous one at the first step); None when ``lam`` is empty."""
    return _nearest(lam, prev if prev2 is None else 2 * prev - prev2) if len(lam) else None


def _track(steps: list[np.ndarray], start: complex) -> np.ndarray:
    """Nearest-eigenvalue continuation from ``start`` with a linear prediction."""
    out, prev, prev2 = [], start, None
    for lam in steps:
        j = _follow(lam, prev, prev2)
        cur = lam[j] if j is not None else np.nan + 0j
        out.append(cur)
        prev2, prev = prev, cur
    return np.array(out, complex)


def _sweep(prob: MasaProblem, inst: Instability, amplitudes: np.ndarray, sweep_break: bool,
           update_shape: bool, refine: int) -> MasaResult:
    """One instability, sequentially (needed for a sweep break or a shape update)."""
    y, w = inst.y, inst.lam.imag
    lams, stats, amps, tracked, shapes = [], [], [], [], []
    prev, prev2, broke = inst.lam, None, None
    for p in amplitudes:
        lam, Y, st, a = prob.state(y, w, p, vectors=update_shape)
        j = _follow(lam, prev, prev2)
        shapes.append((y, w))
        if update_shape:
            y, w = Y[:, j], lam[j].imag
        lams.append(lam)
        stats.append(st)
        amps.append(a)
        tracked.append(lam[j])
        prev2, prev = prev, lam[j]
        if sweep_break and p > 0 and not unstable(lam[j], prob.growth_tol):
            broke = float(p)
            break
    n = len(lams)
    res = MasaResult(inst.index, inst.freq_hz, float(inst.lam.real), np.asarray(amplitudes[:n], float),
                     _pad(lams), np.array(tracked), np.array(stats), np.array(amps), broke_at=broke,
                     update_shape=update_shape, steps=n)
    _stationary(prob, res, shapes, refine)
    return res


def _stationary(prob: MasaProblem, res: MasaResult, shapes, refine: int) -> None:
    """Amplitudes where the tracked real part changes sign, refined by ``refine`` bisections."""
    tol = prob.growth_tol
    unst = unstable(res.tracked, tol)
    for i in np.flatnonzero(unst[1:] != unst[:-1]):
        lo, hi = float(res.amplitudes[i]), float(res.amplitudes[i + 1])
        lam_lo, lam_hi = res.tracked[i], res.tracked[i + 1]
        y, w = shapes[i]
        for _ in range(refine):
            mid = 0.5 * (lo + hi)
            lam, _, _, _ = prob.state(y, w, mid)
            lm = lam[_nearest(lam, 0.5 * (lam_lo + lam_hi))]
            res.steps += 1
            if unstable(lm, tol) == unst[i]:
                lo, lam_lo = mid, lm
            else:
                hi, lam_hi = mid, lm
        # linear interpolation of the real part in the final bracket
        rl, rh = lam_lo.real, lam_hi.real
        res.stationary.append(float(lo + (hi - lo) * rl / (rl - rh)) if rl != rh else 0.5 * (lo + hi))


def run_masa(prob: MasaProblem, targets: Sequence[Instability], amplitudes, *, sweep_break: bool = True,
             update_shape: bool = False, refine: int = 10, comm=None, progress: bool = False
             ) -> list[MasaResult]:
    """MASA of every instability in ``targets`` over ``amplitudes`` (ascending, from 0 or above).

    With MPI ``comm``: instabilities are dealt round-robin to the ranks when a sweep is sequential
    (sweep break or shape update); otherwise every (instability, amplitude) pair is dealt out, so
    two ranks help even for one instability.  Every rank returns all results, identical to a
    serial run (the same arithmetic runs for each pair whatever the rank count).  ``progress``
    draws rank 0's share of the work."""

    amplitudes = np.asarray(amplitudes, float)
    grids = np.broadcast_to(amplitudes, (len(targets), amplitudes.shape[-1])) \
        if amplitudes.ndim in (1, 2) else None
    if grids is None or grids.shape[1] < 2 or np.any(np.diff(grids, axis=1) <= 0) or np.any(grids[:, 0] < 0):
        raise MasaError("amplitudes: need >= 2 increasing values >= 0 (one row, or one row per instability)")
    rank, size = (comm.rank, comm.size) if comm is not None else (0, 1)
    if sweep_break or update_shape:
        own = [n for n in range(len(targets)) if n % size == rank]
        mine = []
        with ProgressBar(len(own), "MASA", enabled=progress and rank == 0, unit=" instabilities") as bar:
            for k, n in enumerate(own):
                mine.append(_sweep(prob, targets[n], grids[n], sweep_break, update_shape, refine))
                bar.update(k + 1)
        parts = comm.allgather(mine) if comm is not None else [mine]
        out = [None] * len(targets)
        for r, chunk in enumerate(parts):
            for k, res in enumerate(chunk):
                out[r + k * size] = res
        return out
    n_p = grids.shape[1]
    pairs = [(n, i) for n in range(len(targets)) for i in range(n_p)]
    mine = {}
    with ProgressBar(len(pairs), "MASA", enabled=progress and rank == 0, unit=" states") as bar:
        for k, (n, i) in enumerate(pairs):
            if k % size == rank:
                t = targets[n]
                lam, _, st, a = prob.state(t.y, t.lam.imag, grids[n, i])
                mine[(n, i)] = (lam, st, a)
                bar.update(k + 1)
    if comm is not None:
        for d in comm.allgather(mine):
            mine.update(d)
    results = []
    for n, t in enumerate(targets):
        lams = [mine[(n, i)][0] for i in range(n_p)]
        results.append(MasaResult(t.index, t.freq_hz, float(t.lam.real), grids[n].copy(), _pad(lams),
                                  _track(lams, t.lam), np.array([mine[(n, i)][1] for i in range(n_p)]),
                                  np.array([mine[(n, i)][2] for i in range(n_p)]), steps=n_p))
    # refine the stationary amplitudes: instabilities dealt round-robin, then shared
    mine_st = {}
    for n, t in enumerate(targets):
        if n % size == rank:
            _stationary(prob, results[n], [(t.y, t.lam.imag)] * n_p, refine)
            mine_st[n] = (results[n].stationary, results[n].steps)
    if comm is not None:
        for d in comm.allgather(mine_st):
            mine_st.update(d)
    for n, (st, steps) in mine_st.items():
        results[n].stationary, results[n].steps = st, steps
    return results


def from_reduced(model: ReducedModel, params: dict | None = None, *, cubic_share: float = 0.0,
                 c_max: float = 0.0, depth: float = np.inf, patches: tuple[int, int] | None = None,
                 axis=(0.0, 0.0, 1.0)) -> MasaModel:
    """The MASA model of a reduced brake model at the parameter point ``params``.

    The reduction linearised every contact interface about the full-order preload (penalty k_n
    on the closed points); that contribution is taken out of K(p) again (exactly: the same
    restricted rows), and each quadrature point becomes a contact point with the law
    :func:`~fem_squeal.reduced.laws.contact.tune_cubic` makes per unit area from the penalty k_n
    and the interface's mean preload pressure (one law per interface, scaled by each point's
    area w: the tangent is k_n at the mean pressure, stiffer above it, softer below).
    ``cubic_share`` = 0 is the linear unilateral penalty, which reproduces the full-order
    preload and CEA exactly when the preload displacement is in the basis.
    ``c_max`` [N s/m³ per area] and ``depth`` add seed 004's contact damping; ``patches`` =
    (n_radial, n_angular) groups the points of each interface into AFT elements.
    The tangential penalty k_t of a contact (``interfaces.<name>.kt``, across the sliding direction)
    is not taken out: it stays in K as the linear spring G_t₂ᵀ diag(k_t w) G_t₂ on the points closed
    at the preload, so the CEA at p = 0 is the full-order one with k_t; the AFT switches only the
    normal law (a point that opens in the cycle keeps its k_t spring, as in a perturbation step)."""
    params = dict(params or {})
    if model.f is None or model.q_static is None:
        raise MasaError("reduced model: no static load or preload displacement (reduce with a preload)")
    if not model.contacts:
        raise MasaError("reduced model: no contact interface (MASA needs interfaces of type 'contact')")
    K, C = model.matrices({k: np.array([v]) for k, v in params.items()})
    K, C = K[0].copy(), (C[0].copy() if C is not None else None)
    mu = float(params.get(MU, model.mu0))
    points, elements = [], []
    for name, cr in model.contacts.items():
        if cr.gap0 is None or cr.pressure is None:
            raise MasaError(f"contacts.{name}: no initial gap or preload pressure stored")
        kt = cr.kn * cr.weight
        m_i = mu if cr.mu != 0 and cr.sliding != 0 else 0.0
        K -= (cr.Gn + m_i * cr.Gt).T @ ((kt * cr.active)[:, None] * cr.Gn)
        closed = cr.active & (cr.pressure > 0)
        p_mean = float(cr.pressure[closed] @ cr.weight[closed] / cr.weight[closed].sum()) if closed.any() else 0.0
        k_l, k_nl, _ = tune_cubic(cr.kn, p_mean, cubic_share)   # per area, one law per interface
        law = UnilateralLaw(k_l=float(k_l) * cr.weight, k_nl=float(k_nl) * cr.weight, c_max=c_max * cr.weight,
                            depth=np.full(len(kt), depth))
        cs = ContactSet(D=cr.D, T=cr.Gt, d0=cr.d0, law=law, mu=m_i, weight=cr.weight, x=cr.x, name=name)
        points.append(cs)
        if patches is not None:
            elements.append(aggregate(cs, polar_patches(cr.x, patches[0], patches[1], axis)))
    return MasaModel(K=K, contacts=points, C=C, f=model.f.copy(), elements=elements if patches else None)
