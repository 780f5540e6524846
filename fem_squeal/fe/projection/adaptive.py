"""The basis enriched round by round until the reduced eigenvalues stop changing and their lifted
residuals meet the tolerance."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from mpi4py import MPI

from fem_squeal.fe.assembly import Operators, contact_change, destroy_relinearised, relinearise
from fem_squeal.fe.dense import apply
from fem_squeal.fe.eigen import (
    TWO_PI,
)
from fem_squeal.fe.preload import changed_points
from fem_squeal.fe.projection.basis import Basis, m_extend
from fem_squeal.fe.projection.parametric import ParametricOperators, lifted_residuals_at
from fem_squeal.fe.projection.reductor import build_basis, contact_states, pressure_tables, reduce
from fem_squeal.fe.projection.sensitivity import full_modes
from fem_squeal.fe.projection.shifted import ShiftedSolver, modes_below
from fem_squeal.reduced.affine import PRESSURE
from fem_squeal.reduced.eigensolve import band_centre_hz, in_band
from fem_squeal.reduced.model import (
    ReducedModel,
)
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.errors import ModelError, ReductionError, UnknownNameError


@dataclass
class ReductionReport:
    """How the basis was grown: one row per round, and whether the change met ``tol``."""

    rounds: list[dict]
    converged: bool
    tol: float
    estimate: float               # max relative change of the watched eigenvalues in the last round
    residuals: list[dict]         # lifted backward errors of the unstable pairs at the check points
    states: list[dict] = field(default_factory=list)   # how each changed contact state entered the basis
    snapshots: list[dict] = field(default_factory=list)  # the greedy step's training points and vectors

    def as_dict(self) -> dict:
        out = {"rounds": self.rounds, "converged": self.converged, "tol": self.tol,
               "estimated_error": self.estimate, "lifted_residuals": self.residuals}
        if self.states:
            out["contact_states"] = self.states
        if self.snapshots:
            out["snapshots"] = self.snapshots
        return out


def _in_band(lam: np.ndarray, band_hz) -> np.ndarray:
    """Eigenvalues with frequency in the band, above 1e-3 of its top (rigid-body modes of free
    parts sit at λ ≈ 0, where a relative change means nothing)."""
    return lam[in_band(lam, band_hz)]


def _watched(lam: np.ndarray, growth_tol: float) -> np.ndarray:
    bad = lam.real > growth_tol * np.abs(lam)
    return lam[bad] if bad.any() else lam


def relative_change(new: np.ndarray, old: np.ndarray) -> float:
    """max over ``new`` of the distance to the nearest of ``old``, relative to |λ|."""
    if new.size == 0:
        return 0.0
    if old.size == 0:
        return np.inf
    return float(np.max(np.min(np.abs(new[:, None] - old[None, :]), axis=1) / np.abs(new)))


#: share of the preload's closed contact points that must open or close at a pressure for its state's
#: modes to be solved (below it they enter as static derivatives in the contact change).  Measured on
#: the coarse tapered brake (2 ranks, benchmarks/README.md): where 3.5 % and 5 % changed (p = 2, 4) the
#: derivatives matched the full CEAs to 1.7e-5 and 2.0e-5 (the re-solved modes: 3.1e-5 at p = 4); where
#: 19 % changed (p = 0.25), 2.2e-4 against 8.5e-5 with the re-solved modes
RESOLVE_SHARE = 0.1

#: orders of the static modal derivatives that stand in for the modes sampled at other E (1: the
#: tangent (K + σM)⁻¹K_iφ alone; 2: and (K + σM)⁻¹K_i of it; measured on the brake, see adaptive_reduce)
DERIVATIVE_ORDER = 2


def _modal_derivatives(par: ParametricOperators, solver: ShiftedSolver, V: np.ndarray,
                       parts: list[str], order: int | None = None) -> list[np.ndarray]:
    """[(K + σM)⁻¹K_i V, ((K + σM)⁻¹K_i)² V, …] for each part i, ``order`` terms each: the
    static modal derivatives of the modes V with respect to θ_i = E_i/E_i⁰, and their powers."""
    return _modal_derivatives_of([par.K_parts[q] for q in parts], solver, V, order)


def _modal_derivatives_of(changes, solver: ShiftedSolver, V: np.ndarray, order: int | None = None
                          ) -> list[np.ndarray]:
    """[(K + σM)⁻¹ΔK V, ((K + σM)⁻¹ΔK)² V, …] for each stiffness change ΔK of ``changes`` (None: none),
    ``order`` terms each: the modes of K + ΔK to that order in ΔK, φ + Δφ with
    Δφ = −(K − ω²M)⁺ΔK φ + …, the resolvent taken at the shift σ."""
    out = []
    for dK in changes:
        if dK is None:
            continue
        D = V
        for _ in range(order or DERIVATIVE_ORDER):
            D = solver.solve(apply(dK, D))
            out.append(D)
    return out


def adaptive_reduce(ops: Operators, par: ParametricOperators, band_hz: tuple[float, float],
                    check_points: list[dict[str, float]], *, tol: float = 1e-3,
                    cut_factors: tuple[float, ...] = (1.25, 1.6, 2.0, 2.5), samples=(), static: bool = True,
                    sigma_hz: float | None = None, growth_tol: float = 1e-6, enrich_rtol: float = 1e-3,
                    preload=None, options=None, log=None, extra: np.ndarray | None = None,
                    states: dict | None = None, snapshots: Sequence[dict] = ()
                    ) -> tuple[ReducedModel, Basis, ReductionReport]:
    """Grow the basis (modes up to factor × the band's top, for each factor in turn) until the
    unstable eigenvalues in the band (all of them where none is unstable) at ``check_points``
    move by less than ``tol`` (relative) between two rounds.  The model of the last round is
    returned, with the change as its error estimate and the lifted residuals of its unstable
    pairs.  Raises :class:`ReductionError` with the history if ``tol`` is never met.

    Work shared between the rounds (issue 23; the basis used to cost 35 full CEAs on the 50k-DOF
    brake, re-solving every round's modes at the nominal point and at each E sample):

    * the nominal modes are solved once up to the second cut (two rounds are the least that give
      a change), the first round takes the subset below its cut; a later round extends them;
    * one factorisation of K + σM serves every round (σ = sign(``sigma_hz``)(2π·``sigma_hz``)²;
      default ``sigma_hz`` = −(band centre): K − ω_c²M, the shift inside the band): the
      corrections (K + σM)⁻¹ K_f Φ and, for a sample of E of a part, the modal derivatives
      (K + σM)⁻¹ K_i φ (the first-order change ∂φ/∂θ_i = −(K − ω²M)⁺(K_i − ∂ω²/∂θ_i M)φ with the
      resolvent taken at σ; its part along φ is in the basis already) and their second order
      (K + σM)⁻¹ K_i (K + σM)⁻¹ K_i φ, in place of the modes re-solved at each sample.  Samples of
      other parameters keep their own eigensolves.  The resolvent at the band centre approximates
      the truncated modes' flexibility Σ φ_kφ_kᵀ/(ω_k² − ω²) for ω in the band better than a
      positive shift: on the 50k-DOF brake (band 0–10 kHz, modes ≤ 16 kHz) the worst error of the
      unstable eigenvalues at the design corners is 2.4e-4 with 234 vectors, against 1.1e-3 with
      K + (2π·1.6 kHz)²M and 1.2e-3 (one unstable mode missed) with the re-solved samples (255);
      on more than one rank the modes too come from this factorisation (:func:`modes_below`);
    * the modes are asked for by their cut, not their number (no inertia count first).

    ``states`` (pressure scale -> continued preload result: the operating matrix's other pressures):
    the model's ``contact_states``; the check points are also checked at each pressure whose contact set
    is not ``preload``'s, so the rounds converge at every contact state.  The modes of each such state's
    stiffness K + ΔK_s (ΔK_s: the contact matrices of the points that closed minus those of the points
    that opened, :func:`~fem_squeal.fe.assembly.contact_change`) join the basis (beyond ``enrich_rtol``,
    as the sampled modes do): where more than :data:`RESOLVE_SHARE` of the preload's closed points
    changed, solved (frictionless, about that state, :func:`~fem_squeal.fe.assembly.relinearise`) to the
    same cut as the nominal ones; else as their static derivatives in ΔK_s to second order,
    (K + σM)⁻¹ΔK_s V and ((K + σM)⁻¹ΔK_s)² V, on the one factorisation (as the E samples'), in place of an
    eigensolve per state.

    ``snapshots`` (training points): once the rounds have converged, one greedy reduced-basis step: the
    full CEA at each point (of twice the size where a part has a loss factor,
    :func:`~fem_squeal.fe.projection.full_modes`) gives its band's eigenvectors, whose real and imaginary
    parts join the basis (M-orthonormalised, deflated only at round-off), and the model is projected
    again.  For a loss factor η(f): the nominal point at the tables' η, which takes the two-block shim's
    reduced fixed point from 2.2e-6 to 1.1e-7 of the full nonlinear eigenproblem (benchmarks/README.md).
    Each round's row gives the seconds of its parts (``factor_seconds``, ``modes_seconds``,
    ``directions_seconds``, ``basis_seconds``: corrections and orthonormalisation,
    ``project_seconds``, ``checks_seconds``)."""

    if len(cut_factors) < 2 or any(b <= a for a, b in zip(cut_factors, cut_factors[1:])):
        raise ModelError(f"cut_factors: need at least 2 increasing factors (got {list(cut_factors)})")
    rounds, prev, change, n_start = [], None, np.inf, 20
    comm = ops.K.getComm().tompi4py()
    top = band_hz[1]
    e_parts = sorted({k[2:] for s in samples for k in s if k.startswith("E.")})
    missing = [q for q in e_parts if q not in par.K_parts]
    if missing:
        raise UnknownNameError(f"samples: no stiffness of part(s) {missing} in the parametric operators")
    other_samples = [s for s in samples if any(not k.startswith("E.") for k in s)]
    # default: the band centre, K − ω_c²M (above)
    sigma_hz = sigma_hz if sigma_hz is not None else -0.5 * (band_hz[0] + band_hz[1])
    gyroscopic = par.operating is not None and par.operating.G is not None
    need_solver = (static and (ops.Kf is not None or gyroscopic or par.pressure is not None)) or e_parts \
        or bool(states)
    wall = lambda t0: comm.allreduce(MPI.Wtime() - t0, op=MPI.MAX)  # noqa: E731
    t = MPI.Wtime()
    solver = ShiftedSolver(ops.K, ops.M, np.sign(sigma_hz) * (TWO_PI * sigma_hz) ** 2, options, "basis_static_") \
        if need_solver else None
    factor_s = wall(t)
    modes, solved_cut, dirs = None, 0.0, None
    cstates = contact_states(ops, preload, states) if states else {}
    share = {}
    if cstates:       # the share of the preload's closed points that opened or closed at each pressure
        closed = comm.allreduce(int(sum(np.count_nonzero(a) for a in preload.active.values())), op=MPI.SUM)
        share = {s: changed_points(states[s], preload, comm) / max(closed, 1) for s in cstates}
    resolved = [s for s in cstates if share[s] > RESOLVE_SHARE]
    state_ops = {s: relinearise(ops, preload.active, states[s].active) for s in resolved}
    changes = [contact_change(ops, preload.active, states[s].active, friction=False)[0]
               for s in cstates if 0 < share[s] <= RESOLVE_SHARE]
    moved = [s for s in cstates if share[s] > 0]
    state_modes: dict[float, tuple] = {}
    state_dirs: list[np.ndarray] | None = None
    checks = [*check_points, *({**p, PRESSURE: s} for s in moved for p in check_points)]

    def project_model(basis: Basis) -> ReducedModel:
        model = reduce(ops, par, basis, preload)
        if cstates:
            model = replace(model, contact_states=cstates,
                            pressure_tables=pressure_tables(par, basis.Phi, cstates))
        return model

    try:
        for i, factor in enumerate(cut_factors):
            t = MPI.Wtime()
            cut = factor * top
            row = {"cut_hz": cut, "factor_seconds": factor_s if i == 0 else 0.0, "modes_seconds": 0.0,
                   "directions_seconds": 0.0}
            if solved_cut < cut:
                t0 = MPI.Wtime()
                want = cut_factors[min(i + 1, len(cut_factors) - 1)] * top
                # block Lanczos to the cut (no count of the modes below it first: an inertia count
                # cost one more factorisation, 0.5 s of the 50k-DOF brake's basis); the guess of
                # their number sets its block size, 16 columns from 121 modes
                w2, V = modes_below(ops.K, ops.M, want, n_start=max(n_start, 128), options=options,
                                    prefix="basis_", solver=solver)
                n_start = V.shape[1] + 2
                modes, solved_cut, dirs, state_dirs = (w2, V), want, None, None
                for s, o in state_ops.items():      # the frictionless modes about each state changed most
                    state_modes[s] = modes_below(o.K, ops.M, want, n_start=n_start, options=options,
                                                 prefix="basis_state_")
                row["modes_seconds"] = wall(t0)
            keep = np.sqrt(np.abs(modes[0])) / TWO_PI <= cut
            if e_parts and dirs is None:
                t0 = MPI.Wtime()
                dirs = _modal_derivatives(par, solver, modes[1], e_parts)
                row["directions_seconds"] += wall(t0)
            if changes and state_dirs is None:
                t0 = MPI.Wtime()
                state_dirs = _modal_derivatives_of(changes, solver, modes[1])
                row["directions_seconds"] += wall(t0)
            # this round's: the derivatives of the modes in E (every order), the modes about the states
            # changed most (to its cut), the static derivatives of the modes about the other states
            parts = [d[:, keep] for d in dirs or ()]
            parts += [V_s[:, np.sqrt(np.abs(w2_s)) / TWO_PI <= cut] for w2_s, V_s in state_modes.values()]
            parts += [d[:, keep] for d in state_dirs or ()]
            directions = np.hstack(parts) if parts else None
            t0 = MPI.Wtime()
            basis = build_basis(ops, par, cut, samples=other_samples, static=static, sigma_hz=sigma_hz,
                                options=options, n_start=n_start, enrich_rtol=enrich_rtol, extra=extra,
                                modes=(modes[0][keep], modes[1][:, keep]), directions=directions,
                                solver=solver)
            row["basis_seconds"] = wall(t0)
            t0 = MPI.Wtime()
            model = project_model(basis)
            row["project_seconds"] = wall(t0)
            t0 = MPI.Wtime()
            lams = [_in_band(solve_points(model, {k: np.array([v]) for k, v in p.items()})[0], band_hz)
                    for p in checks]
            row["checks_seconds"] = wall(t0)
            if prev is not None:
                change = max(relative_change(_watched(a, growth_tol), b) for a, b in zip(lams, prev))
            rounds.append({**row, **basis.counts, "change": change, "seconds": wall(t) + row["factor_seconds"]})
            if log:
                log(f"[fem_squeal] reduced basis: modes <= {cut:.0f} Hz, size {basis.size}, "
                    f"change {change:.1e} ({rounds[-1]['seconds']:.1f} s)")
            prev = lams
            if change <= tol:
                break
    finally:
        if solver is not None:
            solver.destroy()
        for dK in changes:
            if dK is not None:
                dK.destroy()
        for o in state_ops.values():
            destroy_relinearised(o)
    converged = change <= tol
    if not converged:
        raise ReductionError(
            f"reduced basis: eigenvalues still moved by {change:.1e} > tol {tol:.0e} with modes up to "
            f"{cut_factors[-1]:g} × {band_hz[1]:g} Hz; rounds: " +
            "; ".join(f"{r['size']} vectors: {r['change']:.1e}" for r in rounds) +
            " (raise analyses.reduced.cut_factors or tol)")
    taken = []
    if snapshots:
        model, basis, taken = snapshot_step(ops, par, model, basis, snapshots, band_hz, options, project_model)
        if log:
            log(f"[fem_squeal] reduced basis: the full eigenvectors at {len(snapshots)} training point(s), "
                f"size {basis.size} ({sum(r['seconds'] for r in taken):.1f} s)")
    residuals, pairs = [], []
    for p in check_points:
        lam, Y = solve_points(model, {k: np.array([v]) for k, v in p.items()}, vectors=True)
        lam, Y = lam[0], Y[0]
        f = lam.imag / TWO_PI
        sel = (f >= band_hz[0]) & (f <= band_hz[1]) & (lam.real > growth_tol * np.abs(lam))
        residuals.append({"point": p, "freq_hz": f[sel], "real_part": lam[sel].real,
                          "backward_error": np.zeros(0)})
        pairs.append((p, lam[sel], Y[:, sel]))
    with_pairs = [i for i, (_, lam, _) in enumerate(pairs) if lam.size]
    for i, eta in zip(with_pairs, lifted_residuals_at(par, basis.Phi, [pairs[i] for i in with_pairs])):
        residuals[i]["backward_error"] = eta
    model.info.update(cut_hz=rounds[-1]["cut_hz"], estimated_error=change)
    entered = [{"pressure": s, "changed_share": share[s],
                "entered_as": "modes" if s in state_modes else "static derivatives"} for s in moved]
    return model, basis, ReductionReport(rounds, converged, tol, change, residuals, entered, taken)


def snapshot_step(ops: Operators, par: ParametricOperators, model: ReducedModel, basis: Basis,
                  points: Sequence[dict], band_hz, options, project_model) -> tuple[ReducedModel, Basis, list]:
    """The greedy step of :func:`adaptive_reduce` (``snapshots``): the full CEA's band eigenvectors at each
    of ``points`` (as many modes as the reduced model has there, + 2) join the basis, and
    ``project_model(basis)`` projects the model on it.  Returns (model, basis, a row per point: the point,
    the vectors taken, the seconds)."""
    comm = ops.K.getComm().tompi4py()
    cols, rows = [], []
    for p in points:
        t = MPI.Wtime()
        n_ask = _in_band(solve_points(model, {k: np.array([v]) for k, v in p.items()})[0], band_hz).size + 2
        lam, X = full_modes(par, p, n_ask, band_centre_hz(band_hz), band_hz=tuple(band_hz), options=options,
                            prefix="basis_snapshot_", vectors=True)
        sel = in_band(lam, band_hz)
        cols += [X[:, sel].real, X[:, sel].imag]
        rows.append({"point": dict(p), "vectors": 2 * int(sel.sum()),
                     "seconds": comm.allreduce(MPI.Wtime() - t, op=MPI.MAX)})
    Phi, _, dropped = m_extend(ops.M, np.hstack(cols), Phi=basis.Phi)
    basis = replace(basis, Phi=Phi, counts={**basis.counts, "snapshots": Phi.shape[1] - basis.size,
                                            "dropped": basis.counts.get("dropped", 0) + dropped,
                                            "size": Phi.shape[1]})
    return project_model(basis), basis, rows
