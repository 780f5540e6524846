"""The operating matrix on the reduced model: brake conditions (pressure, disc temperature, disc speed,
direction) as a full-factorial design or a table, each solved on the parametric reduced model, and the
noise-matrix summary a dynamometer squeal test (SAE J2521) reports.

A condition c = (p, T, Ω, d) sets the reduced model's parameters (:mod:`fem_squeal.reduced.model`):

    mu      = d·μ(p, T, Ω)       the law of every frictional interface without its own (default: the scene's μ)
    mu.<i>  = d·μ_i(p, T, Ω)     interface i with its own law
                                 (:func:`~fem_squeal.reduced.laws.friction.operating_mu`)
    speed   = |Ω|                where Ω is a parameter of the model (gyroscopic, friction damping)
    pressure = p                 where p is a parameter of the model (the stress stiffening K_σ(u(p)))

and the reverse direction (d = −1) turns the disc the other way: the friction stiffness changes sign
(signed μ, as sign(v)μ in seed 001 Fig. 8) and so does the gyroscopic term, C(−Ω) = C(|Ω|) − 2|Ω| G₁;
the Ω² terms (centrifugal stiffening, convective) and the friction damping (|μ|/|V|) do not.  Kept from
the nominal point: the contact state and the preload's stress stiffening (with a frictional static
step its friction traction is that of the scene's direction).  The pressure p is the scale of the
scene's ``loads.pressure``; it enters here through the friction laws μ(p, T, Ω) and, where the model
has the parameter ``pressure``, through the stress stiffening K_σ(u(p)) = K_σ(u(1)) + (p − 1) K_σ,s
(affine in p: :mod:`fem_squeal.reduced.model`): the reduced model is built about one contact state, so
another pressure is evaluated on it only where the contact set and a linear penalty keep its other
linearised operators the scene's (no friction damping: the app checks this with the preload continuation,
:mod:`fem_squeal.app.analyses.pressure_continuation`).

A part's loss factor η(f, T) (a shim's table, :class:`LossFactors`) enters at the condition's temperature:
as the parameter ``eta.<part>`` where the table does not vary with f (then exactly the constant-η model),
else as i·η(f, T)·K_part at each band mode's own frequency, by the fixed point in frequency of
:mod:`fem_squeal.reduced.loss_fixed_point` (:func:`condition_fixed_point`; its iterations and the modes
that did not converge are in :attr:`MatrixResult.fixed_point`).

Each condition is solved alone (one eigenproblem per condition, the same arithmetic on any rank), the
conditions dealt round-robin over the ranks and gathered: results do not depend on the rank count.
"""
from __future__ import annotations

import itertools
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fem_squeal.reduced.affine import MU, PRESSURE, SPEED, eta_param
from fem_squeal.reduced.eigensolve import TWO_PI, in_band, quadratic_eigs, unstable
from fem_squeal.reduced.laws.friction import operating_mu
from fem_squeal.reduced.laws.loss_factor import LossTable
from fem_squeal.reduced.loss_fixed_point import FixedPointResult, fixed_point
from fem_squeal.reduced.mode_coupling import basis_modes, coupling_of
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.squeal_index import third_octave_bands
from fem_squeal.util.errors import ModelError

VARIABLES = ("pressure", "temperature", "speed", "direction")
DIRECTIONS = {"forward": 1, "reverse": -1}
UNITS = {"pressure": "× loads.pressure", "temperature": "°C", "speed": "rad/s", "direction": ""}


@dataclass(frozen=True)
class Conditions:
    """Operating conditions as flat arrays of equal length: ``pressure`` (scale of loads.pressure),
    ``temperature`` [°C], ``speed`` |Ω| [rad/s] and ``direction`` (+1 forward, −1 reverse)."""

    pressure: np.ndarray
    temperature: np.ndarray
    speed: np.ndarray
    direction: np.ndarray

    def __post_init__(self):
        arrays = [np.atleast_1d(np.asarray(getattr(self, k), float)) for k in VARIABLES]
        n = arrays[0].size
        for k, a in zip(VARIABLES, arrays):
            if a.ndim != 1 or a.size != n or n == 0:
                raise ModelError(f"conditions.{k}: one value per condition ({n}; got shape {a.shape})")
            if not np.all(np.isfinite(a)):
                raise ModelError(f"conditions.{k}: must be finite numbers")
            object.__setattr__(self, k, a)
        if np.any(self.pressure <= 0):
            raise ModelError(f"conditions.pressure: must be > 0 (got {self.pressure.min():g})")
        if np.any(self.speed < 0):
            raise ModelError(f"conditions.speed: must be >= 0 (the disc speed |Ω|; the direction is separate; "
                             f"got {self.speed.min():g})")
        if not np.all(np.isin(self.direction, (-1.0, 1.0))):
            raise ModelError("conditions.direction: must be +1 (forward) or -1 (reverse)")

    @property
    def size(self) -> int:
        return int(self.pressure.size)

    def row(self, k: int) -> dict:
        """Condition k as a record (direction by name)."""
        return {"pressure": float(self.pressure[k]), "temperature": float(self.temperature[k]),
                "speed": float(self.speed[k]), "direction": "forward" if self.direction[k] > 0 else "reverse"}

    def corners(self) -> list[int]:
        """The conditions at the corners of the matrix: every variable at its smallest or largest value
        (the first condition of each distinct corner)."""
        seen, out = set(), []
        for k in range(self.size):
            key = []
            for v in VARIABLES:
                a = getattr(self, v)
                x = a[k]
                if x not in (a.min(), a.max()):
                    break
                key.append(x)
            else:
                if tuple(key) not in seen:
                    seen.add(tuple(key))
                    out.append(k)
        return out


def direction_sign(name: str) -> int:
    """+1 for 'forward', −1 for 'reverse'."""
    if name not in DIRECTIONS:
        raise ModelError(f"direction: must be one of {list(DIRECTIONS)} (got {name!r})")
    return DIRECTIONS[name]


def factorial(pressure: Sequence[float], temperature: Sequence[float], speed: Sequence[float],
              direction: Sequence[str]) -> Conditions:
    """Every combination, in C order (pressure slowest, direction fastest)."""
    rows = list(itertools.product(pressure, temperature, speed, [direction_sign(d) for d in direction]))
    if not rows:
        raise ModelError("conditions: every variable needs at least one value")
    return Conditions(*(np.array(c, float) for c in zip(*rows)))


def from_table(rows: Sequence[Mapping]) -> Conditions:
    """Conditions given one by one: each row has pressure, temperature, speed and direction."""
    if not rows:
        raise ModelError("conditions: the table is empty")
    cols = {k: [] for k in VARIABLES}
    for i, r in enumerate(rows):
        missing = [k for k in VARIABLES if k not in r]
        if missing:
            raise ModelError(f"conditions[{i}]: missing {missing}")
        for k in VARIABLES:
            cols[k].append(direction_sign(r[k]) if k == "direction" else float(r[k]))
    return Conditions(*(np.array(cols[k], float) for k in VARIABLES))


@dataclass(frozen=True)
class InterfaceLaw:
    """The friction law of one interface at the operating conditions (``law``: constant, Stribeck or
    table μ(p, T, Ω); ``radius``: the sliding radius r of a Stribeck law, V = |Ω| r)."""

    law: object
    radius: float = 0.0

    def mu(self, temperature, speed, pressure=None) -> np.ndarray:
        """|μ| at the conditions (``pressure``: the scale of loads.pressure, for a table over it)."""
        return operating_mu(self.law, temperature, speed, self.radius, pressure)


def parameter_points(model: ReducedModel, cond: Conditions, laws: Mapping[str, InterfaceLaw],
                     default: InterfaceLaw | None = None) -> dict[str, np.ndarray]:
    """The reduced model's parameters at every condition (module docstring): ``mu`` from ``default``
    (None: the model's μ⁰, constant), ``mu.<i>`` from ``laws``, ``speed`` where Ω is a parameter,
    ``pressure`` where the pressure is.
    Raises a ModelError when a law names an interface without a friction parameter, or when the speed
    changes terms the model cannot follow (Ω not a parameter but present in it)."""
    d = cond.direction
    mu = (default.mu(cond.temperature, cond.speed, cond.pressure) if default is not None
          else np.full(cond.size, abs(model.mu0)))
    pts = {MU: d * mu}
    for name, law in laws.items():
        key = f"mu.{name}"
        if key not in model.parameters:
            raise ModelError(f"friction.{name}: not a sliding interface with its own μ in this reduced model; "
                             f"its friction parameters: {[p for p in model.parameters if p.startswith('mu')]}")
        pts[key] = d * law.mu(cond.temperature, cond.speed, cond.pressure)
    if PRESSURE in model.parameters:
        pts[PRESSURE] = cond.pressure.copy()
    if SPEED in model.parameters:
        pts[SPEED] = cond.speed.copy()
    elif np.any(cond.speed != model.speed0) and any(
            getattr(model, a) is not None for a in ("G1", "K2", "Cd0")):
        raise ModelError(f"speed: the disc speed is not a parameter of this reduced model (a μ(V) law in the "
                         f"scene), but it has speed terms at Ω₀ = {model.speed0:g} rad/s; conditions ask for "
                         f"{sorted(set(cond.speed.tolist()))}")
    return pts


def matrices_at(model: ReducedModel, point: Mapping[str, np.ndarray], direction: float
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """K and C (m × m) of one condition: :meth:`ReducedModel.matrices` at |Ω|, with the gyroscopic
    term turned for the reverse direction, C(−Ω) = C(|Ω|) − 2|Ω| G₁."""
    K, C = model.matrices({k: np.asarray(v, float).reshape(1) for k, v in point.items()}, 1)
    K, C = K[0], (C[0] if C is not None else None)
    if direction < 0 and model.G1 is not None:
        w = float(np.asarray(point.get(SPEED, model.speed0)).reshape(-1)[0])
        C = C - 2.0 * w * model.G1
    return K, C


@dataclass
class MatrixResult:
    """Eigenvalues (n_conditions, m) of every condition and the wall time [s] (slowest rank); with
    frequency-dependent loss factors the fixed point's summary of every condition (else None)."""

    conditions: Conditions
    eigenvalues: np.ndarray
    seconds: float
    ranks: int
    fixed_point: list[dict] | None = None


@dataclass(frozen=True)
class LossFactors:
    """The loss-factor tables η_p(f, T) of parts the reduced model carries (``eta.<part>`` parameters),
    the band [Hz] whose modes the fixed point follows, its tolerance and iteration limit
    (:mod:`fem_squeal.reduced.loss_fixed_point`)."""

    tables: Mapping[str, LossTable]
    band_hz: tuple[float, float]
    tol: float = 1e-10
    max_iterations: int = 50

    def check(self, model: ReducedModel, temperature: np.ndarray) -> None:
        """Named errors before any computation: a part the model has no ``eta.<part>`` for, a temperature
        outside a table, a band outside the frequency range of a table that varies with f."""
        for part, table in self.tables.items():
            if eta_param(part) not in model.parameters:
                raise ModelError(f"{table.name}: the reduced model has no loss-factor parameter of part "
                                 f"{part!r} (its stiffness is not carried)")
            table.check_range(temperature=temperature)
            if table.varies_with_frequency:
                table.check_range(frequency=np.asarray(self.band_hz))

    def constant_in_frequency(self, temperature: np.ndarray) -> dict[str, np.ndarray]:
        """``eta.<part>`` at every condition for the tables that do not vary with f (plain parameters)."""
        return {eta_param(p): t.value(t.frequency[0], temperature) for p, t in self.tables.items()
                if not t.varies_with_frequency}

    def in_frequency(self) -> dict[str, LossTable]:
        return {p: t for p, t in self.tables.items() if t.varies_with_frequency}


def condition_fixed_point(model: ReducedModel, point: Mapping[str, float], direction: float,
                          loss: LossFactors, temperature: float) -> tuple[np.ndarray, FixedPointResult]:
    """One condition with frequency-dependent loss factors (the tables that do not vary with f: η_p(T),
    plain parameters): the start solve with every other table at its reference frequency (η_p(f_ref, T)),
    then the fixed point in frequency of the modes in the band (rigid-body modes, f < 10⁻³ × its top, aside)
    (:func:`~fem_squeal.reduced.loss_fixed_point.fixed_point`).  Returns the m eigenvalues (those of the
    band at their fixed point, the others from the start solve) and the fixed point's result."""
    varying = loss.in_frequency()
    point = {**point, **{k: float(v) for k, v in loss.constant_in_frequency(np.asarray(temperature)).items()}}

    def matrices(eta: Mapping[str, float]):
        return matrices_at(model, {**point, **{eta_param(p): v for p, v in eta.items()}}, direction)

    laws = {p: t.at_temperature(temperature) for p, t in varying.items()}
    ref = {p: float(t.value(t.frequency[0] if t.reference_frequency is None else t.reference_frequency,
                            temperature)) for p, t in varying.items()}
    K, C = matrices(ref)
    lam, Y = quadratic_eigs(K[None], None if C is None else C[None], vectors=True)
    lam, Y = lam[0], Y[0]
    # rigid-body modes of free parts (λ ≈ 0, below 1e-3 of the band's top) keep the start value: a
    # frequency of round-off has no loss factor to follow (the ring's three took 50 iterations each)
    modes = np.flatnonzero(in_band(lam, loss.band_hz))
    res = fixed_point(matrices, laws, lam, Y, modes, tol=loss.tol, max_iterations=loss.max_iterations,
                      start_eta=ref)
    out = lam.copy()
    out[modes] = res.eigenvalues
    order = np.lexsort((out.real, np.round(out.imag, 9)))
    return out[order], res


def evaluate(model: ReducedModel, cond: Conditions, points: Mapping[str, np.ndarray], comm=None,
             loss: LossFactors | None = None) -> MatrixResult:
    """The eigenvalues of every condition (one eigenproblem each), conditions dealt round-robin over the
    ranks of ``comm`` (None: serial) and gathered on every rank.  ``loss``: parts' loss factors η(f, T)
    at each condition's temperature, a plain parameter where a table does not vary with f, else the
    fixed point in frequency per mode (:func:`condition_fixed_point`)."""
    t = time.perf_counter()
    size, rank = (1, 0) if comm is None else (comm.size, comm.rank)
    mine = np.arange(rank, cond.size, size)
    lam = np.empty((mine.size, model.size), complex)
    fps: list = []
    if loss is not None:
        loss.check(model, cond.temperature)
        points = {**points, **loss.constant_in_frequency(cond.temperature)}
    for j, k in enumerate(mine):
        point = {n: v[k] for n, v in points.items()}
        if loss is not None and loss.in_frequency():
            lam[j], res = condition_fixed_point(model, point, cond.direction[k], loss, cond.temperature[k])
            fps.append(res.summary())
            continue
        K, C = matrices_at(model, point, cond.direction[k])
        lam[j] = quadratic_eigs(K[None], None if C is None else C[None])[0]
    if comm is not None and size > 1:
        full = np.empty((cond.size, model.size), complex)
        fp_all: list = [None] * cond.size
        for idx, val, fp in comm.allgather((mine, lam, fps)):
            full[idx] = val
            for i, r in zip(idx, fp):
                fp_all[i] = r
        lam, fps = full, (fp_all if fps or any(fp_all) else [])
    seconds = time.perf_counter() - t
    if comm is not None and size > 1:
        seconds = comm.allreduce(seconds, op=_max_op())
    return MatrixResult(cond, lam, seconds, size, fps or None)


def _max_op():
    from mpi4py import MPI  # heavy: MPI initialisation

    return MPI.MAX


def unstable_modes(res: MatrixResult, band_hz: tuple[float, float], growth_tol: float) -> list[dict]:
    """Every unstable mode (Re λ > growth_tol |λ|) in ``band_hz`` (rigid-body modes aside,
    :func:`~fem_squeal.reduced.eigensolve.in_band`) of every condition: condition index,
    frequency f = Im λ/2π [Hz], growth rate σ = Re λ [1/s] and damping ratio ζ = −Re λ/|λ|."""
    out = []
    for k, lam in enumerate(res.eigenvalues):
        f = lam.imag / TWO_PI
        keep = unstable(lam, growth_tol) & in_band(lam, band_hz)
        for j in np.flatnonzero(keep)[np.argsort(f[keep])]:
            out.append({"condition": k, "frequency_hz": float(f[j]), "growth_rate": float(lam[j].real),
                        "damping_ratio": float(-lam[j].real / abs(lam[j]))})
    return out


def mode_couplings(model: ReducedModel, res: MatrixResult, points: Mapping[str, np.ndarray], modes: list[dict],
                   loss: LossFactors | None = None, comm=None) -> None:
    """Adds to each unstable mode of :func:`unstable_modes` its ``coupling``: the participation of the
    basis's real modes (the nominal frictionless modes, as the μ sweep's, :func:`fem_squeal.reduced.
    mode_coupling.basis_modes`) in its eigenvector at its condition (η at its own frequency where a table
    varies with f), by inverse iteration at its eigenvalue (:func:`~fem_squeal.reduced.mode_coupling.
    coupling_of`: one m × m LU a mode; the modes dealt round-robin over the ranks of ``comm``, each computed
    alone, so the same bits on any number).  Nothing where the model carries no real modes (info['modes'])."""
    n_modes = int(model.info.get("modes", 0))
    if not n_modes or not modes:
        return
    real = basis_modes(model.K0, n_modes)
    cond = res.conditions
    varying = loss.in_frequency() if loss is not None else {}
    if loss is not None:
        points = {**points, **loss.constant_in_frequency(cond.temperature)}
    key, K, C = None, None, None          # the matrices of the last (condition, η): the rows come by condition
    size, rank = (1, 0) if comm is None else (comm.size, comm.rank)
    mine = {}
    for i in range(rank, len(modes), size):
        row = modes[i]
        k = row["condition"]
        eta = {eta_param(p): float(t.value(row["frequency_hz"], cond.temperature[k])) for p, t in varying.items()}
        if (k, *eta.values()) != key:
            key = (k, *eta.values())
            K, C = matrices_at(model, {**{n: float(v[k]) for n, v in points.items()}, **eta}, cond.direction[k])
        mine[i] = coupling_of(K, C, complex(row["growth_rate"], TWO_PI * row["frequency_hz"]), real)
    if size > 1:
        mine = {i: c for part in comm.allgather(mine) for i, c in part.items()}
    for i, c in mine.items():
        modes[i]["coupling"] = c


def noise_matrix(res: MatrixResult, band_hz: tuple[float, float], growth_tol: float) -> dict:
    """The dynamometer summary: per condition the number of unstable modes and the largest growth rate;
    per 1/3-octave band (1–16 kHz) the conditions with an unstable mode in it (count and share); per
    value of each variable the share of its conditions with any unstable mode; the unstable modes."""
    modes = unstable_modes(res, band_hz, growth_tol)
    cond, n = res.conditions, res.conditions.size
    count = np.zeros(n, int)
    growth = np.full(n, np.nan)
    for m in modes:
        count[m["condition"]] += 1
        growth[m["condition"]] = np.nanmax([growth[m["condition"]], m["growth_rate"]])
    bands = []
    for nominal, lo, hi in third_octave_bands():
        hit = {m["condition"] for m in modes if lo <= m["frequency_hz"] < hi}
        bands.append({"band_hz": nominal, "lower_hz": lo, "upper_hz": hi, "conditions": len(hit),
                      "occurrence": len(hit) / n, "in_model_band": bool(lo < band_hz[1] and hi > band_hz[0])})
    noisy = count > 0
    by_variable = {}
    for v in VARIABLES:
        a = getattr(cond, v)
        rows = []
        for x in np.unique(a):
            sel = a == x
            rows.append({"value": (("forward" if x > 0 else "reverse") if v == "direction" else float(x)),
                         "conditions": int(sel.sum()), "unstable": int(noisy[sel].sum()),
                         "occurrence": float(noisy[sel].mean())})
        by_variable[v] = rows
    return {"n_conditions": n, "unstable_conditions": int(noisy.sum()), "occurrence": float(noisy.mean()),
            "n_unstable": count.tolist(), "max_growth_rate": [None if np.isnan(g) else float(g) for g in growth],
            "third_octave": bands, "by_variable": by_variable, "modes": modes}
