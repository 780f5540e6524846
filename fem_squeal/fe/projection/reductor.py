"""The reduced model of a basis: the basis built (modes, sampled modes, static corrections, contact
attachments) and the operators projected onto it."""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.assembly import OperatingTerms, Operators
from fem_squeal.fe.dense import apply
from fem_squeal.fe.eigen import (
    TWO_PI,
    drop_zeros,
)
from fem_squeal.fe.pressure_terms import REFERENCE
from fem_squeal.fe.projection.basis import (
    Basis,
    _gather_rows,
    _new_block,
    _orthonormality,
    _stack,
    canonical_order,
    project,
)
from fem_squeal.fe.projection.parametric import ParametricOperators, project_plates
from fem_squeal.fe.projection.shifted import ShiftedSolver, modes_below, static_correction
from fem_squeal.reduced.contact_rows import ContactRows, from_gap_rows
from fem_squeal.reduced.masa import polar_patches
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.util.errors import ModelError, ReductionError


def restrict_contacts(ops: Operators, Phi: np.ndarray, preload=None) -> dict[str, ContactRows]:
    """G_n Φ and G_t Φ of every contact interface (all points on every rank, canonical order)."""
    out = {}
    for it, op in ops.contacts:
        comm = op.Gn.getComm().tompi4py()
        x = _gather_rows(comm, op.x)
        o = canonical_order(x)
        g0 = _gather_rows(comm, op.gap0)[o]
        g = _gather_rows(comm, preload.gap[it.name])[o] if preload is not None else g0
        act = _gather_rows(comm, preload.active[it.name])[o] if preload is not None else np.ones(op.n_global, bool)
        pres = _gather_rows(comm, preload.pressure[it.name])[o] if preload is not None else None
        out[it.name] = from_gap_rows(
            Gn=_gather_rows(comm, apply(op.Gn, Phi))[o], Gt=_gather_rows(comm, apply(op.Gt1, Phi))[o],
            weight=_gather_rows(comm, op.weight)[o], kn=it.kn, mu=it.mu, sliding=float(it.sliding),
            gap=g, active=act.astype(bool), gap0=g0, x=x[o], pressure=pres,
            Gt2=_gather_rows(comm, apply(op.Gt2, Phi))[o], kt=float(it.kt), name=it.name)
    return out


def contact_states(ops: Operators, preload, states) -> dict[float, dict[str, np.ndarray]]:
    """The closed rows of every contact (all points, canonical order: :func:`restrict_contacts`' rows) at
    each pressure scale of ``states`` (scale -> its preload result), for the reduced model's
    ``contact_states``; {} when the contact set of every state is ``preload``'s (the model is then affine in
    the pressure).  Collective."""
    out: dict[float, dict[str, np.ndarray]] = {}
    changed = False
    for scale, st in sorted(states.items()):
        out[float(scale)] = {}
        for it, op in ops.contacts:
            comm = op.Gn.getComm().tompi4py()
            o = canonical_order(_gather_rows(comm, op.x))
            a = _gather_rows(comm, np.asarray(st.active[it.name], bool))[o]
            changed |= bool(np.any(a != _gather_rows(comm, np.asarray(preload.active[it.name], bool))[o]))
            out[float(scale)][it.name] = a
    return out if changed else {}


def build_basis(ops: Operators, par: ParametricOperators | None, f_cut_hz: float, *,
                samples: list[dict[str, float]] = (), static: bool = True, sigma_hz: float | None = None,
                options=None, prefix: str = "basis_", rtol: float = 1e-8, enrich_rtol: float = 1e-3,
                n_start: int = 20, extra: np.ndarray | None = None, modes: tuple | None = None,
                directions: np.ndarray | None = None, solver: ShiftedSolver | None = None,
                operating: OperatingTerms | None = None) -> Basis:
    """Frictionless modes ≤ ``f_cut_hz`` at the nominal point and at each of ``samples``, plus the
    static corrections (K + σM)⁻¹ K_f Φ (of all the modes kept; and of C_d Φ with friction damping,
    ``ops.Cd``), M-orthonormalised (see the module
    docstring); sampled modes add only their directions beyond ``enrich_rtol`` (the corrections
    are kept whole: truncating them at 1e-3 raised the ring's error at μ = 1 from 1.5e-6 to 5e-5).
    ``n_start``: first guess of the number of modes below the cut; ``extra``: more vectors (local
    rows), kept whole, e.g. the preload displacement and contact attachments for MASA.
    Given by :func:`adaptive_reduce`, which shares them between its rounds: ``modes`` (ω², local
    vectors) already solved up to at least the cut (the subset ≤ ``f_cut_hz`` is used),
    ``directions`` (local rows) enriching like the sampled modes (e.g. their derivatives),
    and ``solver``, the factorisation of K + σM for the corrections (then ``sigma_hz`` is its).
    ``par`` None (no ``samples``): the corrections take the disc's rotation from ``operating``
    (the projected CEA, :mod:`.projected_cea`, which has no parametric operators)."""
    if not f_cut_hz > 0:
        raise ModelError(f"f_cut_hz: must be > 0 (got {f_cut_hz})")
    if modes is None:
        w2, V = modes_below(ops.K, ops.M, f_cut_hz, n_start=n_start, options=options, prefix=prefix)
    else:
        keep = np.sqrt(np.abs(modes[0])) / TWO_PI <= f_cut_hz
        w2, V = modes[0][keep], modes[1][:, keep]
    # M Φ carried along: M is applied to the new columns only, without its stored zeros (a third of
    # the work: the vector mass is assembled on the stiffness pattern's 3×3 blocks); the basis is
    # kept as blocks [(Φ_b, MΦ_b)] and stacked once at the end
    Mz = drop_zeros(ops.M)
    blocks: list[tuple[np.ndarray, np.ndarray]] = []

    def extend(X: np.ndarray, tol: float, owned: bool = False) -> tuple[int, int]:
        """(columns added, directions dropped); ``owned``: X made here, to be overwritten."""
        W, MW, d = _new_block(Mz, X, tol, blocks, owned)
        if W.shape[1]:
            blocks.append((W, MW))
        return W.shape[1], d

    dropped = extend(V, rtol, owned=True)[1]        # V: modes_below's or a column subset (copies)
    n_sample = n_static = n_extra = 0
    if directions is not None and directions.shape[1]:
        added, d = extend(directions, enrich_rtol)
        n_sample, dropped = n_sample + added, dropped + d
    for s in samples:
        K = par.frictionless(s)
        _, Vs = modes_below(K, ops.M, f_cut_hz, n_start=int(1.15 * V.shape[1]) + 4, options=options,
                            prefix=prefix)
        K.destroy()
        # only what the sampled modes add beyond ``enrich_rtol`` of their norm: eigenvalue errors
        # are quadratic in the subspace error for well-separated modes, but near a coalescence
        # (non-normal) they are not: 1e-2 gave 1.0e-3 on the brake at a map corner, 1e-3 is the default
        added, d = extend(Vs, enrich_rtol, owned=True)
        n_sample, dropped = n_sample + added, dropped + d
    if par is None and samples:
        raise ModelError("samples: modes at other parameter values need the parametric operators (par)")
    loads = _loads(correction_operators(ops, par.operating if par is not None else operating,
                                        loss_operators(par), _slope_corrections(par)), blocks) if static else []
    if loads:
        sigma = (TWO_PI * (sigma_hz if sigma_hz is not None else 0.1 * f_cut_hz)) ** 2
        F = np.column_stack(loads)
        S = solver.solve(F) if solver is not None else \
            static_correction(ops.K, ops.M, F, sigma, options, prefix + "static_")
        n_static, d = extend(S, rtol, owned=True)  # corrections: all of their new content
        dropped += d
    if extra is not None and extra.shape[1]:
        n_extra, d = extend(extra, rtol)
        dropped += d
    Phi = _stack([b[0] for b in blocks], V.shape[0])
    basis = Basis(Phi, ops.K.getSize()[0], np.sqrt(np.abs(w2)) / TWO_PI,
                 {"modes": int(V.shape[1]), "sampled_modes": n_sample, "static": n_static, "extra": n_extra,
                  "dropped": dropped, "size": int(Phi.shape[1])}, _orthonormality(Mz.getComm().tompi4py(), blocks))
    if Mz is not ops.M:
        Mz.destroy()
    return basis


def static_loads(ops: Operators, par: ParametricOperators, Phi: np.ndarray | list[tuple[np.ndarray, ...]]
                 ) -> list[np.ndarray]:
    """The loads A Φ whose static corrections (K + σM)⁻¹ A Φ join the basis: A = K_f (friction), C_d (friction
    damping), the gyroscopic G of a turning disc, the stiffness of the parts with a loss factor and, where the
    brake pressure is a parameter, the slope C_d,s of the friction damping (issue 39): the terms that the
    modes at rest do not span.  The symmetric K_σ0, K_σc − S (prestress, spin softening: ~1e-4 of K) and the
    slope K_σ,s of the stress stiffening are left to the modes.  Measured on the coarse brake (50k DOFs,
    corners μ = ±0.6 × Ω = 2, 100 rad/s, worst relative error of the unstable eigenvalues): K_f, C_d: 239
    vectors, 2.6e-4; + G: 324, 7.3e-5; + G, K_σc − S, K_σ0: 496, 1.7e-4; + their sum at Ω₀: 325, 1.0e-4.
    K_σ,s (pressures 0.5 and 2, two corners): without its corrections 251 vectors, 2.9e-5; with them 337,
    3.6e-5."""
    return _loads(correction_operators(ops, par.operating, loss_operators(par), _slope_corrections(par)), Phi)


def loss_operators(par: ParametricOperators | None) -> list[PETSc.Mat]:
    """The stiffness K_p of each part with a loss factor (η or a table η(f, T)): the structural damping
    i η K_p spans stiff directions (a contact's, a penalty's) that the modes do not.  Measured on the
    Ryzhik ring between its plates (η = 0.03 on the ring, modes ≤ 16 kHz): the unstable eigenvalues near
    9.5 kHz 1.2–2.3e-6 from the full model's without these corrections, whatever the cut (30 kHz: the
    same), 3e-10 with them (the basis 129 → 192 vectors)."""
    return [par.K_parts[p] for p in getattr(par, "loss_parts", ())] if par is not None else []


def correction_operators(ops: Operators, operating: OperatingTerms | None = None,
                         loss: list[PETSc.Mat] = (), slopes: list[PETSc.Mat] = ()) -> list[PETSc.Mat]:
    """The operators A of :func:`static_loads` (K_f, C_d, the gyroscopic G of ``operating``, the parts'
    stiffness of ``loss`` (:func:`loss_operators`), the pressure slopes of ``slopes``) that the model has."""
    mats = [ops.Kf, getattr(ops, "Cd", None), operating.G if operating is not None else None, *loss, *slopes]
    return [A for A in mats if A is not None]


def _pressure_slopes(par: ParametricOperators | None) -> tuple[PETSc.Mat | None, PETSc.Mat | None]:
    """(K_σ,s, C_d,s) of ``par`` where the pressure is its parameter (None where it has no such term)."""
    if par is None or par.pressure is None:
        return None, None
    return par.pressure.stiffness_slope, par.pressure.damping_slope


def _slope_corrections(par: ParametricOperators | None) -> list[PETSc.Mat]:
    """The pressure slopes whose static corrections join the basis: C_d,s only (the stress stiffening's
    K_σ,s is left to the modes as K_σ0 is: :func:`static_loads`)."""
    return [A for A in _pressure_slopes(par)[1:] if A is not None]


def _loads(mats: list[PETSc.Mat], Phi: np.ndarray | list[tuple[np.ndarray, ...]]) -> list[np.ndarray]:
    """A Φ for each A of ``mats`` (Φ given as blocks [(Φ_b, …)]: A Φ_b side by side)."""
    if isinstance(Phi, list):
        return [np.hstack([apply(A, b[0]) for b in Phi]) for A in mats]
    return [apply(A, Phi) for A in mats]


def contact_attachments(ops: Operators, patches: tuple[int, int], sigma_hz: float, options=None,
                        prefix: str = "basis_attach_", axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(K + σM)⁻¹ (G_n + μG_t)ᵀ W 1_j: the static response to a unit pressure (with its friction
    drag) on patch j of every contact interface, the patches being an n_radial × n_angular polar
    grid over each slave surface (:func:`fem_squeal.reduced.masa.polar_patches`).  These carry
    the local contact deformation that the nonlinear contact forces of MASA excite."""

    loads = []
    bc_local = np.asarray(ops.bc_dofs, dtype=int)
    for it, op in ops.contacts:
        comm = op.Gn.getComm().tompi4py()
        sizes = comm.allgather(len(op.weight))
        labels = polar_patches(_gather_rows(comm, op.x), patches[0], patches[1], axis)
        start = sum(sizes[:comm.rank])
        mine = labels[start:start + sizes[comm.rank]]
        row, b, t = op.Gn.createVecLeft(), op.Gn.createVecRight(), op.Gn.createVecRight()
        for j in range(patches[0] * patches[1]):
            if not np.any(labels == j):
                continue
            row.array[:] = op.weight * (mine == j)
            op.Gn.multTranspose(row, b)
            if it.has_friction:
                op.Gt1.multTranspose(row, t)
                b.axpy(it.mu, t)
            col = b.array_r.copy()
            col[bc_local[bc_local < len(col)]] = 0.0
            loads.append(col)
        for v in (row, b, t):
            v.destroy()
    if not loads:
        return np.zeros((ops.K.getLocalSize()[0], 0))
    return static_correction(ops.K, ops.M, np.column_stack(loads), (TWO_PI * sigma_hz) ** 2, options, prefix)


def reduce(ops: Operators, par: ParametricOperators, basis: Basis, preload=None) -> ReducedModel:
    """The affine reduced model on ``basis`` (module docstring of :mod:`fem_squeal.reduced.model`)."""
    Phi = basis.Phi
    K0 = project(ops.K, Phi)
    Kf1 = project(ops.Kf, Phi) / par.mu0 if ops.Kf is not None and par.mu0 != 0 else None
    C0 = project(ops.C, Phi) if ops.C is not None else None
    op = par.operating
    if op is not None and op.Ks0 is not None:
        K0 = K0 + project(op.Ks0, Phi)
    speed = {}
    if op is not None and op.G is not None:
        speed.update(G1=project(op.G, Phi), K2=project(par.K2, Phi))
    if ops.Cd is not None and par.mu0 != 0:   # C_d apart from C₀: it scales with μ and 1/Ω
        speed["Cd0"] = project(ops.Cd, Phi)
        C0 = None if ops.C is ops.Cd else C0 - speed["Cd0"]
    if speed:
        speed.update(speed0=par.speed0, speed_varies=par.speed_varies)
    comm = ops.K.getComm().tompi4py()
    err = basis.orthonormality if basis.orthonormality is not None else \
        float(np.max(np.abs(project(ops.M, Phi) - np.eye(basis.size)), initial=0.0))
    if err > 1e-8:
        raise ReductionError(f"basis: not M-orthonormal (max |ΦᵀMΦ − I| = {err:.1e})")
    f = comm.allreduce(Phi.T @ ops.f.array_r, op=MPI.SUM) if ops.f is not None else None
    q_s = None
    if preload is not None:
        Mu = ops.M.createVecLeft()
        ops.M.mult(preload.u, Mu)
        q_s = comm.allreduce(Phi.T @ Mu.array_r, op=MPI.SUM)
        Mu.destroy()
    return ReducedModel(K0=K0, Kf1=Kf1, C0=C0, K_parts={p: project(A, Phi) for p, A in par.K_parts.items()},
                        E0=dict(par.E0), beta=dict(par.beta), mu0=par.mu0,
                        contacts=restrict_contacts(ops, Phi, preload), info=dict(basis.counts), f=f, q_static=q_s,
                        eta0=dict(par.eta0), plates=project_plates(par, Phi), **speed,
                        **_project_pressure_slopes(par, Phi))


def pressure_tables(par: ParametricOperators, Phi: np.ndarray, scales) -> dict[float, dict[str, np.ndarray]]:
    """The reduced model's ``pressure_tables`` at each continued scale of ``scales``: Φᵀ(K_σ(u(s)) −
    K_σ(u(1)))Φ and Φᵀ(C_d(p(s)) − C_d(p(1)))Φ from each state's own operators (``par.pressure``), for contact
    sets that change with the pressure (where the affine slopes do not hold); {} without pressure terms."""
    pt = par.pressure if par is not None else None
    if pt is None:
        return {}
    out: dict[float, dict[str, np.ndarray]] = {}
    for key, at in (("Ks", pt.stiffness_at if pt.stiffness is not None else None),
                    ("Cd", pt.damping_at if pt.damping is not None else None)):
        if at is None:
            continue
        ref = project(at(REFERENCE), Phi)
        for s in scales:
            out.setdefault(float(s), {})[key] = project(at(float(s)), Phi) - ref
    return out


def _project_pressure_slopes(par: ParametricOperators, Phi: np.ndarray) -> dict[str, np.ndarray]:
    """The brake pressure s: K_σ(u(s)) = K_σ0 + (s − 1) K_σ,s, C_d(p(s)) = C_d + (s − 1) C_d,s projected
    (``Ksp``, ``Cdp`` of the reduced model; none without the pressure parameter)."""
    out = {}
    for key, A in zip(("Ksp", "Cdp"), _pressure_slopes(par)):
        if A is not None:
            out[key] = project(A, Phi)
    return out
