"""Modal projection of the full operators (the PETSc/SLEPc side of the reduced layer).

Basis (issue 4; seed 001 §2.2 eq. 5 generalised):

* the real modes of the frictionless system K φ = ω² M φ (K with the closed contact springs,
  symmetric) below ``f_cut``;
* modes at sampled parameter values (a part's Young's modulus at the ends of its range), so that
  the basis stays accurate across a design of experiments;
* static correction vectors (K + σM)⁻¹ K_f Φ: the quasi-static response to the friction forces of
  each mode, which the truncated modes cannot represent (measured on the ring with k_n 1e11,
  μ 1: the modal error stalls at 1.5e-3 with 160 modes, 40 modes + 40 corrections give 3e-7);
* all of it M-orthonormalised with deflation: a vector whose part outside the span of the others
  is below ``rtol`` of its M-norm adds nothing and is dropped.

The reduced matrices Φᵀ A Φ are formed with PETSc sparse × dense products and summed over the
ranks, so every rank holds the same :class:`~fem_squeal.reduced.model.ReducedModel`.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc
from scipy.linalg import blas
from scipy.sparse import csr_matrix

from fem_squeal.fe import interface as itf
from fem_squeal.fe.assembly import OperatingTerms, Operators, _owned_global_rows, combination
from fem_squeal.fe.csr import csr_view, sum_norms_inf
from fem_squeal.fe.dense import apply, block_solve, gram, matmul_f, project_out
from fem_squeal.fe.eigen import (
    DIRECT_SOLVER_OPTIONS,
    TWO_PI,
    drop_zeros,
    modes_on_factor,
    set_options,
    solve_complex_modes,
    solve_left_vectors,
    solve_real_modes,
)
from fem_squeal.fe.model import ModelSpec, common_mu  # noqa: F401  (common_mu: re-exported)
from fem_squeal.reduced.masa import polar_patches
from fem_squeal.reduced.model import (
    MU,
    SPEED,
    ContactRestriction,
    PlateProjection,
    ReducedModel,
    e_param,
    eta_param,
    friction_damping_scale,
    split_param,
)
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.errors import EigenSolveError, ModelError, ReductionError, UnknownNameError


@dataclass
class Basis:
    """Mass-orthonormal basis Φ (rank-local owned rows) and where its vectors come from."""

    Phi: np.ndarray               # (n_local, m)
    n_global: int
    modal_hz: np.ndarray          # frequencies of the nominal frictionless modes included
    counts: dict = field(default_factory=dict)  # modes, sampled modes, static corrections, dropped
    orthonormality: float | None = None   # max |ΦᵀMΦ − I| as measured when built (None: not measured)

    @property
    def size(self) -> int:
        return self.Phi.shape[1]


def project(A: PETSc.Mat, Phi: np.ndarray) -> np.ndarray:
    """Φᵀ A Φ (m × m, the same on every rank), summed over the rows where A has entries only when
    they are fewer than half (a contact operator's, a small part's stiffness: the m × m sum over
    all rows cost 80 ms at 50k DOFs × 232 vectors, whatever the rows held)."""
    comm = A.getComm().tompi4py()
    AP = apply(A, Phi)
    if comm.size == 1 and A.getType() == "seqaij":
        with csr_view(A) as (indptr, _, _):
            rows = np.flatnonzero(np.diff(indptr))
    else:     # the local rows of A Φ that are not zero (a scan costs a quarter of the sum)
        rows = np.flatnonzero(np.any(AP != 0.0, axis=1))
    if len(rows) >= 0.5 * Phi.shape[0]:
        return gram(comm, Phi, AP)
    return gram(comm, Phi[rows], AP[rows])


def m_orthonormalise(M: PETSc.Mat, V: np.ndarray, rtol: float = 1e-8, Phi: np.ndarray | None = None
                     ) -> tuple[np.ndarray, int]:
    """Extend the M-orthonormal ``Phi`` (or start afresh) by span(V), with deflation; returns
    (basis, number of dropped directions).  See :func:`m_extend`."""
    Phi, _, dropped = m_extend(M, V, rtol, Phi)
    return Phi, dropped


def m_extend(M: PETSc.Mat, V: np.ndarray, rtol: float = 1e-8, Phi: np.ndarray | None = None,
             MPhi: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Extend the M-orthonormal ``Phi`` (``MPhi`` = M Φ if at hand) by span(V), with deflation;
    returns (basis Φ', M Φ', number of dropped directions).  See :func:`_new_block`."""
    blocks = []
    if Phi is not None and Phi.shape[1] > 0:
        blocks = [(Phi, apply(M, Phi) if MPhi is None else MPhi)]
    W, MW, dropped = _new_block(M, V, rtol, blocks)
    blocks.append((W, MW))
    return _stack([b[0] for b in blocks], V.shape[0]), _stack([b[1] for b in blocks], V.shape[0]), dropped


def _orthonormality(comm, blocks: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """max |ΦᵀMΦ − I| of the basis held as blocks [(Φ_b, MΦ_b)], block by block (the M Φ of the
    whole basis is never stacked: it served this check alone)."""
    err = 0.0
    for i, (Pi, _) in enumerate(blocks):
        for j, (_, MPj) in enumerate(blocks[i:], start=i):
            G = gram(comm, Pi, MPj)
            err = max(err, float(np.max(np.abs(G - np.eye(G.shape[0]) if i == j else G), initial=0.0)))
    return err


def _stack(blocks: list[np.ndarray], n_local: int) -> np.ndarray:
    """The blocks side by side, column-major (as :func:`fem_squeal.fe.dense.apply` takes them)."""
    out = np.empty((n_local, sum(b.shape[1] for b in blocks)), order="F")
    j = 0
    for b in blocks:
        out[:, j:j + b.shape[1]] = b
        j += b.shape[1]
    return out


def _new_block(M: PETSc.Mat, V: np.ndarray, rtol: float, blocks: list[tuple[np.ndarray, np.ndarray]],
               owned: bool = False) -> tuple[np.ndarray, np.ndarray, int]:
    """The block (W, M W, number of dropped directions) that extends the M-orthonormal basis held as
    ``blocks`` [(Φ_b, M Φ_b), …] by span(V): [Φ_1 … W] is M-orthonormal to round-off.

    Each column of V is scaled by its M-norm and M-orthogonalised against the basis (block
    Gram–Schmidt, ΦᵀMW = (MΦ)ᵀW); then G = WᵀMW = Q diag(s) Qᵀ and directions with s < rtol² (new
    content below ``rtol`` of the vector) are dropped, W Q s^(-1/2) is kept.  A second pass against
    the basis on the kept directions only (one pass leaves a part ~ε/√s along the basis, which the
    scaling brings to ~ε/√s ≤ ε/rtol and the second pass back to ε: "twice is enough"; the dropped
    directions do not need it, and the brake's enrichment drops 5 of every 6) and the Cholesky
    factor of the new block's Gram matrix make it M-orthonormal.  The basis is kept as blocks and
    never re-multiplied nor re-stacked (the whole basis was once re-multiplied by the Cholesky
    factor of its whole Gram matrix: 2·2·n·m² flops per call, 1.3 s of the 50k-DOF brake's 11 s
    basis, to move Φ by round-off; then stacked at each call, 0.6 s).
    M is applied to V and to the kept directions before their Cholesky factor (afresh: s^(-1/2)
    amplifies the round-off of a tracked product by up to 1/rtol); M W after the first pass and
    through the Cholesky factor (close to I) is carried, never applied to the basis (issue 23: the
    basis of the 50k-DOF brake spent 5.5 s re-applying M to it)."""
    comm = M.getComm().tompi4py()

    def against_basis(W: np.ndarray, MW: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """W − Σ Φ_b C_b, C_b = (MΦ_b)ᵀW, in place; and M W − Σ (MΦ_b) C_b where ``MW`` is given."""
        # collective calls depend on column counts only: a rank may own no rows of V
        for Phi, MPhi in blocks:
            C, W = project_out(comm, Phi, MPhi, W)
            if MW is not None and MW.size:
                MW = blas.dgemm(-1.0, MPhi, C, beta=1.0, c=MW, overwrite_c=1)
        return W, MW

    MV = apply(M, V)
    norms = np.sqrt(np.maximum(comm.allreduce(np.einsum("ij,ij->j", V, MV), op=MPI.SUM), 0.0))
    ok = norms > 0
    # scaled in place: in V itself where the caller made it for this (``owned``), else in one copy
    W = V if owned and ok.all() and V.flags.f_contiguous and V.flags.writeable else \
        np.array(V if ok.all() else V[:, ok], order="F")
    W /= norms[ok]
    dropped = int(np.sum(~ok))
    if blocks:
        # W = V/‖V‖ − Σ Φ_b C_b and M W = M V/‖V‖ − Σ (MΦ_b) C_b, the latter carried in place of a
        # sparse product (the same cost in flops, and no new array): an absolute round-off ε either
        # way, as the subtraction that makes W itself
        MW = MV if ok.all() else np.asfortranarray(MV[:, ok])
        MW /= norms[ok]
        W, MW = against_basis(W, MW)
        G = gram(comm, W, MW)
    else:                 # W scaled (V itself where owned), MV not: its columns divided here
        G = gram(comm, W, MV if ok.all() else MV[:, ok]) / norms[ok]
    s, Q = np.linalg.eigh(0.5 * (G + G.T))
    keep = s > rtol ** 2
    dropped += int(np.sum(~keep))
    W = against_basis(matmul_f(W, Q[:, keep] / np.sqrt(s[keep])))[0]
    MW = apply(M, W)
    if W.shape[1]:
        # the new block's Cholesky QR, in place (BLAS dtrsm; L well conditioned, G ≈ I), M W
        # following W through it (M W L⁻ᵀ = M(W L⁻ᵀ) to round-off times κ(L) ≈ 1)
        G = gram(comm, W, MW)
        L = np.linalg.cholesky(0.5 * (G + G.T))
        if W.shape[0]:     # a rank may own no rows
            W = blas.dtrsm(1.0, L, W, side=1, lower=1, trans_a=1, overwrite_b=1)
            MW = blas.dtrsm(1.0, L, MW, side=1, lower=1, trans_a=1, overwrite_b=1)
    return W, MW, dropped


def _local_array(vecs: list[PETSc.Vec]) -> np.ndarray:
    """The vectors' rank-local rows as the columns of a column-major array."""
    return np.array([v.array_r for v in vecs]).T if vecs else np.zeros((0, 0), order="F")


#: convergence of the basis modes (shift-inverted residual, SLEPc's criterion; the real-mode analysis
#: takes 1e-7): they only span the basis, to which their derivatives and the static corrections are
#: added and on which the model is a Galerkin projection.  Measured on the 50k-DOF brake (91 modes
#: ≤ 16 kHz): 1e-7 / 1e-6 / 1e-5: 1.60 / 1.52 / 1.42 s, frequencies within 2.8e-11 of 1e-7's, pair
#: residuals ‖Kx − λMx‖/(‖K‖‖x‖) ≤ 2.4e-9 / 2.0e-8 / 1.3e-7; the reduced model's error at the
#: design corners unchanged (docs/validation.md, "Fifth pass").
BASIS_MODE_TOL = 1e-5
BASIS_MODE_RESIDUAL = 1e-6   # the pairs' residual bound beyond which Krylov–Schur takes over (8× the measured)


def modes_below(K: PETSc.Mat, M: PETSc.Mat, f_cut_hz: float, *, n_start: int = 20, options=None,
                prefix: str = "basis_", max_modes: int = 2000, solver: ShiftedSolver | None = None):
    """Every real mode with f ≤ ``f_cut_hz`` (shift-invert near 0): block Lanczos converges the modes
    below the cut and two above it (``f_max_hz`` of :func:`solve_real_modes`; ``n_start``, a guess
    of their number, sets its block size); where Krylov–Schur takes over, the count grows until the
    highest converged mode lies above the cut.  ``solver``: a factorisation of K + σM at hand, used
    instead of a new one where MUMPS would factorise anyway (more than one rank;
    :func:`fem_squeal.fe.eigen.modes_on_factor`; on one rank CHOLMOD's factorisation near 0 and its
    solves cost less than MUMPS's solves).  Returns (ω² array, local (n_local, n) array)."""
    def local(rm) -> tuple[np.ndarray, np.ndarray]:
        keep = rm.freqs_hz <= f_cut_hz
        Phi = _local_array([v for v, k in zip(rm.vectors, keep) if k])
        for v in rm.vectors:
            v.destroy()
        return rm.omega2[keep], Phi

    if solver is not None and solver.factor is not None and K.getComm().getSize() > 1:
        rm = modes_on_factor(solver.solve, K, M, -solver.sigma, f_cut_hz, n_start, tol=BASIS_MODE_TOL,
                             max_residual=BASIS_MODE_RESIDUAL)
        if rm is not None and rm.freqs_hz[-1] > f_cut_hz:
            return local(rm)
        for v in rm.vectors if rm is not None else ():
            v.destroy()
    nev = n_start
    target = 1e-3 * f_cut_hz  # a small positive shift: K may be singular (free bodies)
    while True:
        rm = solve_real_modes(K, M, nev, target, options=options, prefix=prefix, progress=True, f_max_hz=f_cut_hz,
                              tol=BASIS_MODE_TOL, max_residual=BASIS_MODE_RESIDUAL)
        f = rm.freqs_hz
        if f[-1] > f_cut_hz or nev >= max_modes:
            return local(rm)
        for v in rm.vectors:
            v.destroy()
        # extrapolate the count to the cut (N ∝ f^1.5, between plates ∝ f² and beams ∝ f), with a
        # margin, but at most ×2.5 per try: a large overshoot costs more than one more solve
        grow = (f_cut_hz / max(f[-1], 1e-9)) ** 1.5 * 1.1
        nev = int(min(max_modes, nev * min(max(grow, 1.3), 2.5) + 4))


def count_below(K: PETSc.Mat, M: PETSc.Mat, f_hz: float, options=None, prefix: str = "basis_count_") -> int:
    """The number of modes with f < ``f_hz``: the negative inertia of K − (2πf)²M (Sylvester's law;
    one MUMPS LDLᵀ factorisation, ICNTL(13) = 1 and ICNTL(24) = 1 as its inertia needs).  A check of
    the modes a solve returns (tests); :func:`adaptive_reduce` no longer counts before solving."""
    set_options(prefix, options, {"pc_type": "cholesky", "mat_mumps_icntl_13": 1, "mat_mumps_icntl_24": 1})
    A = K.copy()
    A.axpy(-(TWO_PI * f_hz) ** 2, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    ksp = _solver(A, options, prefix)
    try:
        ksp.setUp()
        return int(ksp.getPC().getFactorMatrix().getInertia()[0])
    finally:
        ksp.destroy()
        A.destroy()


def _solver(A: PETSc.Mat, options, prefix: str) -> PETSc.KSP:
    set_options(prefix, options, {k.removeprefix("st_"): v for k, v in DIRECT_SOLVER_OPTIONS.items()})
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    return ksp


class ShiftedSolver:
    """(K + σM)⁻¹ applied to blocks of columns with one sparse factorisation (K symmetric, as the
    frictionless stiffness is: MUMPS Cholesky by default, ``<prefix>pc_type`` overrides).  The
    columns go to the factor's multiple-right-hand-side solve (MatMatSolve) in blocks of
    ``block``: measured on the 50k-DOF brake, 13–26 ms per column against 52–83 ms one at a time."""

    def __init__(self, K: PETSc.Mat, M: PETSc.Mat, sigma: float, options=None,
                 prefix: str = "basis_static_", block: int = 64):
        self.sigma, self.block = sigma, block
        self.A = K.copy()
        self.A.axpy(sigma, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        # MUMPS's solve takes its right-hand sides 64 at a time (ICNTL(27); its default of 32 for
        # MatMatSolve): the 50k-DOF brake's 172 columns 0.43 → 0.38 s, the factorisation the same
        set_options(prefix, options, {"pc_type": "cholesky", "mat_mumps_icntl_27": 64})
        self.ksp = _solver(self.A, options, prefix)
        self.ksp.setUp()
        pc = self.ksp.getPC()
        self.factor = pc.getFactorMatrix() if self.ksp.getType() == "preonly" and \
            pc.getType() in ("lu", "cholesky") else None

    def solve(self, F: np.ndarray) -> np.ndarray:
        """(K + σM)⁻¹ F for the rank-local columns F (n_local, k)."""
        out = np.empty_like(F)
        if self.factor is None:  # an iterative or non-factor solver: one column at a time
            b, x = self.A.createVecs()
            for j in range(F.shape[1]):
                b.array[:] = F[:, j]
                self.ksp.solve(b, x)
                out[:, j] = x.array_r
            b.destroy()
            x.destroy()
            return out
        solve = block_solve(self.factor)
        for s in range(0, F.shape[1], self.block):
            out[:, s:s + self.block] = solve(F[:, s:s + self.block])
        return out

    def destroy(self):
        self.ksp.destroy()
        self.A.destroy()


def static_correction(K: PETSc.Mat, M: PETSc.Mat, F: np.ndarray, sigma: float, options=None,
                      prefix: str = "basis_static_") -> np.ndarray:
    """(K + σM)⁻¹ F for the rank-local columns F (one factorisation, all right-hand sides)."""
    solver = ShiftedSolver(K, M, sigma, options, prefix)
    try:
        return solver.solve(F)
    finally:
        solver.destroy()


class ParametricOperators:
    """Full-order K(p), C(p) of the affine form (module docstring of :mod:`fem_squeal.reduced.model`):
    used to verify the reduced model and to sample modes at parameter values.

    The parameters are those of :class:`~fem_squeal.reduced.model.ReducedModel`: ``mu``, ``E.<part>``
    and ``eta.<part>`` (``parts``), and ``mu.<c>``, ``kn.<c>``, ``kt.<c>`` of every contact interface c
    and of every named rigid plate (``ops.plate_parts``: assembled with ``parts=True``).
    The interface matrices are assembled at the closed points of ``preload`` (all points without
    one), as the reduced model's: the contact state of the preload is kept when k_n changes.
    A loss factor η makes K complex, which the real PETSc build cannot hold: :meth:`matrices`
    returns the real part and :meth:`loss_stiffness` the imaginary part Σ η_i θ_i K_i, from which
    :meth:`real_equivalent` builds the real problem of twice the size."""

    def __init__(self, ops: Operators, spec: ModelSpec, mu0: float, parts: list[str] | None = None,
                 preload=None, operating: OperatingTerms | None = None, speed0: float = 0.0):
        self.ops, self.mu0 = ops, mu0
        # the disc's rotation and stress stiffening (fe.assembly.OperatingTerms) at the scene's speed Ω₀;
        # friction damping ops.Cd (in ops.C) scales as (|μ|/|μ⁰|)(Ω₀/Ω): p |μ|/V with V = Ω r
        self.operating, self.speed0 = operating, float(speed0)
        self.K2 = operating.stiffness_per_speed2() if operating is not None else None
        has_law = any(p.law is not None for p in spec.plates) or any(i.law is not None for i in spec.interfaces)
        self.speed_varies = self.speed0 > 0 and not has_law and (
            ops.Cd is not None or (operating is not None and operating.G is not None))
        self.parts = list(parts) if parts is not None else list(ops.K_parts or {})
        missing = [p for p in self.parts if not ops.K_parts or p not in ops.K_parts]
        if missing:
            raise UnknownNameError(f"parameters: no stiffness of part(s) {missing} (assemble with parts=True)")
        bc_rows = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
        self.K_parts = {}
        for p in self.parts:
            A = ops.K_parts[p].copy()
            A.zeroRowsColumns(bc_rows, diag=0.0)  # the clamped rows of K keep their unit diagonal
            self.K_parts[p] = A
        self.E0 = {p: spec.materials[p].E for p in self.parts}
        self.beta = {p: spec.materials[p].rayleigh_beta for p in self.parts}
        self.eta0 = {p: float(getattr(spec.materials[p], "eta", 0.0)) for p in self.parts}
        self.contacts = {it.name: (it, op) for it, op in ops.contacts}
        self.active = {name: (None if preload is None else np.asarray(preload.active[name], bool))
                       for name in self.contacts}
        self.plates = dict(ops.plate_parts or {})
        # every interface with per-interface parameters: contacts and named rigid plates
        self.interfaces = {**{n: it for n, (it, _) in self.contacts.items()},
                           **{n: pm.plate for n, pm in self.plates.items()}}
        self._bc_rows = bc_rows
        self._interface: dict[str, tuple] = {}

    @property
    def parameters(self) -> list[str]:
        """Every parameter name these operators accept (the reduced model's names)."""
        out = [MU] + [e_param(p) for p in self.parts]   # μ = 0 is accepted by a frictionless model
        out += [f"mu.{c}" for c, it in self.interfaces.items() if it.sliding != 0]
        out += [f"{k}.{c}" for k in ("kn", "kt") for c in self.interfaces]
        return out + [eta_param(p) for p in self.parts] + ([SPEED] if self.speed_varies else [])

    def interface_matrices(self, name: str) -> tuple[PETSc.Mat, PETSc.Mat | None, PETSc.Mat]:
        """(K_c at the nominal k_n, K_f for μ = 1 at the nominal k_n or None without sliding, K_t for
        k_t = 1) of contact ``name`` on its closed points (of rigid plate ``name``: on its face), zero
        on the clamped DOFs."""
        if name in self.plates and name not in self._interface:
            pm = self.plates[name]
            mats = [None if A is None else A.copy() for A in (pm.Kc, pm.Kf, pm.Kt)]
            for A in mats:
                if A is not None:
                    A.zeroRowsColumns(self._bc_rows, diag=0.0)
            self._interface[name] = tuple(mats)
        if name not in self._interface:
            it, op = self.contacts[name]
            a = self.active[name]
            closed = np.ones(len(op.weight)) if a is None else a.astype(float)
            mats = [itf.contact_stiffness(op, it.kn * closed),
                    itf.friction_stiffness(op, it.kn * closed, 1.0) if it.sliding != 0 else None,
                    itf.tangential_stiffness(op, closed, it.sliding != 0)]
            for A in mats:
                if A is not None:
                    A.zeroRowsColumns(self._bc_rows, diag=0.0)
            self._interface[name] = tuple(mats)
        return self._interface[name]

    def _mu_share(self, it) -> float:
        return it.mu / self.mu0 if self.mu0 != 0 and it.has_friction and self.ops.Kf is not None else 0.0

    def _check(self, params: Mapping[str, float]) -> None:
        known = self.parameters
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise UnknownNameError(f"{unknown[0]}: not a parameter; parameters: {known}")
        for name, v in params.items():
            prefix = split_param(name)[0]
            if (prefix in ("E", "kn") and not v > 0) or (prefix in ("eta", "kt", SPEED) and not v >= 0):
                raise ModelError(f"{name}: must be {'>' if prefix in ('E', 'kn') else '>='} 0 (got {v})")

    def loss_stiffness(self, params: Mapping[str, float]) -> PETSc.Mat | None:
        """Σ_i η_i θ_i K_i: the imaginary part of K(p) (None when no part has a loss factor)."""
        terms = self.loss_terms(params)
        return combination(terms) if terms else None

    def loss_terms(self, params: Mapping[str, float]) -> list[tuple[PETSc.Mat, float]]:
        """:meth:`loss_stiffness` as terms [(K_i, η_i θ_i)] (empty without a loss factor)."""
        self._check(params)
        out = []
        for p in self.parts:
            eta = params.get(eta_param(p), self.eta0[p])
            if eta != 0:
                out.append((self.K_parts[p], eta * params.get(e_param(p), self.E0[p]) / self.E0[p]))
        return out

    def matrices(self, params: Mapping[str, float]) -> tuple[PETSc.Mat, PETSc.Mat | None]:
        """New K(p) (with friction) and C(p) (None if undamped) for parameter values ``params``;
        with a loss factor K(p) is the real part of the stiffness (:meth:`loss_stiffness`)."""
        K, C = self.terms(params)
        return combination(K), (combination(C) if C else None)

    def terms(self, params: Mapping[str, float]) -> tuple[list[tuple[PETSc.Mat, float]], list]:
        """K(p) = Σ c_i A_i and C(p) = Σ d_j B_j as lists [(A_i, c_i)] (C: empty if undamped), in the
        order :meth:`matrices` adds them (the affine form, defined here once)."""
        self._check(params)
        K = [(self.ops.K, 1.0)]
        C = [(self.ops.C, 1.0)] if self.ops.C is not None else []
        mu = params.get(MU, self.mu0)
        if self.ops.Kf is not None and self.mu0 != 0:
            K.append((self.ops.Kf, mu / self.mu0))
        self._operating(K, C, mu, params.get(SPEED, self.speed0))
        for p in self.parts:
            d = params.get(e_param(p), self.E0[p]) / self.E0[p] - 1.0
            if d != 0:
                K.append((self.K_parts[p], d))
                if self.beta[p] > 0:
                    C.append((self.K_parts[p], self.beta[p] * d))
        for name, it in self.interfaces.items():
            keys = (f"mu.{name}", f"kn.{name}", f"kt.{name}")
            if not any(k in params for k in keys):
                continue
            Kc, Kf, Kt = self.interface_matrices(name)
            s = params.get(keys[1], it.kn) / it.kn
            if keys[1] in params:
                K.append((Kc, s - 1.0))
            if Kf is not None and (keys[0] in params or keys[1] in params):
                mu_default = params.get(MU, self.mu0) * self._mu_share(it)
                K.append((Kf, params[keys[0]] * s - mu_default if keys[0] in params else mu_default * (s - 1.0)))
            if keys[2] in params:
                K.append((Kt, params[keys[2]] - it.kt))
        return K, C

    def _operating(self, K: list, C: list, mu: float, speed: float) -> None:
        """The terms K_σ0 + Ω²(K_σc − S) of K and Ω G + ((|μ|/|μ⁰|)(Ω₀/Ω) − 1) C_d of C (which holds C_d
        at the nominal point), appended to the term lists."""
        op, Cd = self.operating, self.ops.Cd
        if op is not None and op.Ks0 is not None:
            K.append((op.Ks0, 1.0))
        if op is not None and op.G is not None:
            K.append((self.K2, speed ** 2))
            C.append((op.G, speed))
        if Cd is not None and self.mu0 != 0:
            if self.speed0 and not speed > 0:
                raise ModelError(f"speed: must be > 0 with friction damping (got {speed})")
            C.append((Cd, friction_damping_scale(mu, self.mu0, speed, self.speed0) - 1.0))

    def real_equivalent(self, params: Mapping[str, float]
                        ) -> tuple[PETSc.Mat, PETSc.Mat | None, PETSc.Mat]:
        """(K₂, C₂, M₂) of twice the size for K(p) = K_r + iK_i (a loss factor):
        K₂ = [[K_r, −K_i], [K_i, K_r]], C₂ = diag(C, C), M₂ = diag(M, M).  With T = [[I, I], [−iI, iI]],
        T⁻¹Q₂(λ)T = diag(Q(λ), Q̄(λ)) for Q(λ) = λ²M + λC + K_r + iK_i (M, C real): the eigenvalues of
        the real problem are those of Q (vectors [x; −ix]) and their conjugates (those of Q̄, vectors
        [x; ix]); :func:`complex_stiffness_branch` tells them apart."""
        K, C = self.matrices(params)
        Ki = self.loss_stiffness(params)
        M = self.ops.M
        out = (_block_matrix([[(K, 1.0), (Ki, -1.0)], [(Ki, 1.0), (K, 1.0)]], K),
               None if C is None else _block_matrix([[(C, 1.0), None], [None, (C, 1.0)]], K),
               _block_matrix([[(M, 1.0), None], [None, (M, 1.0)]], K))
        for A in (K, C, Ki):
            if A is not None:
                A.destroy()
        return out

    def frictionless(self, params: Mapping[str, float]) -> PETSc.Mat:
        return self.matrices({**params, MU: 0.0})[0]

    def destroy(self):
        for A in self.K_parts.values():
            A.destroy()
        if self.K2 is not None:
            self.K2.destroy()
        for mats in self._interface.values():
            for A in mats:
                if A is not None:
                    A.destroy()


def parameter_derivative(par: ParametricOperators, name: str) -> tuple[PETSc.Mat, PETSc.Mat | None, complex]:
    """(∂K/∂p, ∂C/∂p or None, factor) of the full operators at the nominal point: the derivative is
    factor·∂K/∂p (factor i for a loss factor η, whose term is iθK_i; 1 otherwise).  The same terms
    as :meth:`fem_squeal.reduced.model.ReducedModel.derivative`: ∂K/∂μ = K_f/μ⁰; ∂K/∂E_i = K_i/E_i⁰,
    ∂C/∂E_i = β_i K_i/E_i⁰; ∂K/∂η_i = iK_i; ∂K/∂μ_c = K_f,c¹; ∂K/∂k_n,c = (K_c,c + μ_c⁰K_f,c¹)/k_n,c⁰;
    ∂K/∂k_t,c = K_t,c¹; with friction damping ∂C/∂μ = C_d/μ⁰; ∂K/∂Ω = 2Ω₀(K_σc − S), ∂C/∂Ω = G − C_d/Ω₀.
    New matrices (the caller destroys them)."""
    par._check({name: 1.0})
    prefix, target = split_param(name)
    if name == MU:
        if par.ops.Kf is None or par.mu0 == 0:
            raise ModelError("mu: the model has no friction at the nominal point (no K_f to scale)")
        Cd = par.ops.Cd   # C_d ∝ |μ|: ∂/∂μ = sign(μ⁰)/|μ⁰| = 1/μ⁰
        return (combination([(par.ops.Kf, 1.0 / par.mu0)]),
                combination([(Cd, 1.0 / par.mu0)]) if Cd is not None else None, 1.0)
    if name == SPEED:   # ∂K/∂Ω = 2Ω₀(K_σc − S), ∂C/∂Ω = G − C_d/Ω₀
        w, op, Cd = par.speed0, par.operating, par.ops.Cd
        dK = combination([(par.K2, 2.0 * w)]) if par.K2 is not None else par.ops.K.duplicate()
        if par.K2 is None:
            dK.zeroEntries()
        dC = combination([(op.G if op is not None else None, 1.0), (Cd, -1.0 / w)])
        return dK, dC, 1.0
    if prefix == "E":
        Ki = combination([(par.K_parts[target], 1.0 / par.E0[target])])
        C = combination([(par.K_parts[target], par.beta[target] / par.E0[target])]) if par.beta[target] else None
        return Ki, C, 1.0
    if prefix == "eta":
        return combination([(par.K_parts[target], 1.0)]), None, 1j
    it = par.interfaces[target]
    Kc, Kf, Kt = par.interface_matrices(target)
    if prefix == "kt":
        return combination([(Kt, 1.0)]), None, 1.0
    if prefix == "mu":
        return combination([(Kf, 1.0)]), None, 1.0
    mu_c = par.mu0 * par._mu_share(it)
    return combination([(Kc, 1.0 / it.kn), (Kf, mu_c / it.kn)]), None, 1.0


@dataclass
class FullSensitivity:
    """dλ/dp of one eigenvalue of the full model from its right and left eigenvectors."""

    eigenvalue: complex
    d_lambda: dict[str, complex]
    left_mismatch: float          # |λ of the transposed problem − λ| / |λ|
    residual: float               # the CEA's relative residual of the right vector


def full_sensitivities(par: ParametricOperators, eigenvalues: np.ndarray, names: list[str], band_hz,
                       *, options=None, prefix: str = "sens_", progress: bool = False) -> list[FullSensitivity]:
    """dλ/dp = −yᴴ(λ²∂M + λ∂C + ∂K)x / yᴴ(2λM + C)x (∂M = 0 here) of the full model at the nominal
    point, for the eigenvalues of the full CEA nearest ``eigenvalues`` (e.g. the reduced model's
    selected modes): x from the CEA (:func:`~fem_squeal.fe.eigen.solve_complex_modes` in ``band_hz``),
    y from the transposed problem (:func:`~fem_squeal.fe.eigen.solve_left_vectors`), both at the
    same shift.  A nominal loss factor (complex K) is not supported by the real-scalar CEA."""
    if any(v != 0 for v in par.eta0.values()):
        raise ModelError("full-order sensitivities: a part has a loss factor eta > 0 at the nominal point; the "
                         "real-scalar CEA has no complex stiffness (use the reduced sensitivities)")
    K, C = par.matrices({})
    M = par.ops.M
    want = np.asarray(eigenvalues, complex)
    f = want.imag / TWO_PI
    # the shift at the wanted modes (nearest first), 0.5 % off: a shift on an eigenvalue makes K − σM singular
    target = 1.005 * float(np.sqrt(np.mean(f ** 2)))
    nev = len(want) + 4
    for attempt in range(4):   # more pairs until every wanted eigenvalue has its own full one within 1 %
        cm = solve_complex_modes(K, M, C, nev, target, band_hz=tuple(band_hz), options=options, prefix=prefix,
                                 progress=progress)
        pick = [int(np.argmin(np.abs(cm.eigenvalues - x))) for x in want] if cm.eigenvalues.size else []
        ok = len(pick) == len(want) and len(set(pick)) == len(pick) and \
            all(abs(cm.eigenvalues[j] - x) <= 1e-2 * abs(x) for j, x in zip(pick, want))
        if ok or attempt == 3:
            break
        for v in (*cm.vectors_re, *cm.vectors_im):
            v.destroy()
        nev *= 2
    if not ok:
        raise EigenSolveError(f"full-order sensitivities: the full CEA ({nev} pairs near {target:.0f} Hz) has no "
                              "distinct eigenvalue within 1 % of each of " +
                              ", ".join(f"{x.imag / TWO_PI:.1f} Hz" for x in want))
    lam = cm.eigenvalues[pick]
    left = solve_left_vectors(K, M, C, lam, target, band_hz=tuple(band_hz), options=options,
                              prefix=prefix + "left_", progress=progress)
    derivs = {n: parameter_derivative(par, n) for n in names}
    tmp_r, tmp_i = K.createVecLeft(), K.createVecLeft()

    def zt(zr, zi, A, xr, xi) -> complex:
        """zᵀ A x for complex z, x given by their real and imaginary parts."""
        A.mult(xr, tmp_r)
        A.mult(xi, tmp_i)
        return complex(zr.dot(tmp_r) - zi.dot(tmp_i), zr.dot(tmp_i) + zi.dot(tmp_r))

    out = []
    try:
        for j, k in enumerate(pick):
            xr, xi, zr, zi, li = cm.vectors_re[k], cm.vectors_im[k], left.vectors_re[j], left.vectors_im[j], lam[j]
            den = 2 * li * zt(zr, zi, M, xr, xi) + (zt(zr, zi, C, xr, xi) if C is not None else 0.0)
            d = {}
            for n, (dK, dC, factor) in derivs.items():
                num = zt(zr, zi, dK, xr, xi) + (li * zt(zr, zi, dC, xr, xi) if dC is not None else 0.0)
                d[n] = complex(-factor * num / den)
            out.append(FullSensitivity(complex(li), d, float(left.mismatch[j]), float(cm.residuals[k])))
    finally:
        for A in (tmp_r, tmp_i, K, C, *cm.vectors_re, *cm.vectors_im, *left.vectors_re, *left.vectors_im,
                  *(m for dK, dC, _ in derivs.values() for m in (dK, dC))):
            if A is not None:
                A.destroy()
    return out


def _block_matrix(blocks, like: PETSc.Mat) -> PETSc.Mat:
    """The 2×2 block matrix [[α₀₀A₀₀, α₀₁A₀₁], [α₁₀A₁₀, α₁₁A₁₁]] (entries (A, α) or None, blocks laid
    out like ``like``) as one AIJ matrix; each rank owns its rows of the first block row, then its
    rows of the second (the MatNest numbering): global row i of block b, owned by rank k with range
    [lo_k, hi_k), becomes 2lo_k + b(hi_k − lo_k) + i − lo_k."""
    ranges = np.asarray(like.getOwnershipRanges())
    lo, hi = like.getOwnershipRange()
    n_global = like.getSize()[0]

    def renumber(j: np.ndarray, b: int) -> np.ndarray:
        k = np.searchsorted(ranges, j, side="right") - 1
        return 2 * ranges[k] + b * (ranges[k + 1] - ranges[k]) + (j - ranges[k])

    rows, cols, vals = [], [], []
    for bi, line in enumerate(blocks):
        for bj, entry in enumerate(line):
            if entry is None or entry[0] is None:
                continue
            A, alpha = entry
            ia, ja, a = A.getValuesCSR()
            r = np.repeat(np.arange(lo, hi), np.diff(ia))
            rows.append(renumber(r, bi) - 2 * lo)
            cols.append(renumber(np.asarray(ja), bj))
            vals.append(alpha * a)
    n_local = 2 * (hi - lo)
    S = csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                   shape=(n_local, 2 * n_global))
    S.sum_duplicates()
    S.sort_indices()
    B = PETSc.Mat().createAIJ(((n_local, 2 * n_global), (n_local, 2 * n_global)), comm=like.getComm(),
                              csr=(S.indptr.astype(PETSc.IntType), S.indices.astype(PETSc.IntType), S.data))
    B.assemble()
    return B


def full_modes(par: ParametricOperators, point: Mapping[str, float], nev: int, target_hz: float, *,
               band_hz: tuple[float, float] | None = None, options=None, prefix: str = "verify_",
               progress: bool = False) -> np.ndarray:
    """Eigenvalues (Im λ > 0, in ``band_hz``) of the full λ²M + λC + K(p) at ``point``: the CEA of
    :meth:`ParametricOperators.matrices`, or, when a part has a loss factor (K complex), the real
    problem of twice the size (:meth:`ParametricOperators.real_equivalent`) with 2·``nev`` pairs,
    of which those of Q(λ) are kept: their vectors are [x; −ix], i.e. ‖a − ib‖ ≪ ‖a + ib‖ for the
    halves a, b of the vector (those of Q̄, the mirrored spurious roots of K(1 − iη), are [x; ix])."""
    Ki = par.loss_stiffness(point)
    if Ki is None:
        K, C = par.matrices(point)
        M, n_ask = par.ops.M, nev
    else:
        Ki.destroy()
        K, C, M = par.real_equivalent(point)
        n_ask = 2 * nev
    cm = solve_complex_modes(K, M, C, n_ask, target_hz, band_hz=band_hz, options=options, prefix=prefix,
                             progress=progress)
    lam = cm.eigenvalues
    if Ki is not None:
        comm = K.getComm().tompi4py()
        n = K.getLocalSize()[0] // 2
        keep = []
        for xr, xi in zip(cm.vectors_re, cm.vectors_im):
            v = xr.array_r + 1j * xi.array_r
            a, b = v[:n], v[n:]
            q, qbar = comm.allreduce(np.array([np.sum(np.abs(a - 1j * b) ** 2), np.sum(np.abs(a + 1j * b) ** 2)]),
                                     op=MPI.SUM)
            keep.append(q < qbar)
        lam = lam[np.array(keep, bool)]
        M.destroy()
    for A in (K, C, *cm.vectors_re, *cm.vectors_im):
        if A is not None:
            A.destroy()
    return lam


def _gather_rows(comm, a: np.ndarray) -> np.ndarray:
    return np.concatenate(comm.allgather(a), axis=0)


def canonical_order(x: np.ndarray) -> np.ndarray:
    """Permutation sorting points by their coordinates (rounded to 1e-9 of the extent), so that
    gathered point data does not depend on how the mesh was partitioned."""
    if len(x) == 0:
        return np.zeros(0, int)
    scale = max(float(np.max(np.abs(x))), 1e-300)
    r = np.round(x / (1e-9 * scale))
    return np.lexsort((r[:, 2], r[:, 1], r[:, 0]))


def restrict_contacts(ops: Operators, Phi: np.ndarray, preload=None) -> dict[str, ContactRestriction]:
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
        out[it.name] = ContactRestriction(
            Gn=_gather_rows(comm, apply(op.Gn, Phi))[o], Gt=_gather_rows(comm, apply(op.Gt1, Phi))[o],
            weight=_gather_rows(comm, op.weight)[o], kn=it.kn, mu=it.mu, sliding=float(it.sliding),
            gap=g, active=act.astype(bool), gap0=g0, x=x[o], pressure=pres,
            Gt2=_gather_rows(comm, apply(op.Gt2, Phi))[o], kt=float(it.kt))
    return out


def build_basis(ops: Operators, par: ParametricOperators, f_cut_hz: float, *,
                samples: list[dict[str, float]] = (), static: bool = True, sigma_hz: float | None = None,
                options=None, prefix: str = "basis_", rtol: float = 1e-8, enrich_rtol: float = 1e-3,
                n_start: int = 20, extra: np.ndarray | None = None, modes: tuple | None = None,
                directions: np.ndarray | None = None, solver: ShiftedSolver | None = None) -> Basis:
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
    and ``solver``, the factorisation of K + σM for the corrections (then ``sigma_hz`` is its)."""
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
    loads = static_loads(ops, par, blocks) if static else []
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
    """The loads A Φ whose static corrections (K + σM)⁻¹ A Φ join the basis: A = K_f (friction), C_d
    (friction damping) and the gyroscopic G of a turning disc, the terms that the modes at rest do not
    span.  The symmetric K_σ0, K_σc − S (prestress, spin softening: ~1e-4 of K) are left to the modes.
    Measured on the coarse brake (50k DOFs, corners μ = ±0.6 × Ω = 2, 100 rad/s, worst relative error
    of the unstable eigenvalues): K_f, C_d: 239 vectors, 2.6e-4; + G: 324, 7.3e-5; + G, K_σc − S, K_σ0:
    496, 1.7e-4; + their sum at Ω₀: 325, 1.0e-4."""
    op = par.operating
    mats = [ops.Kf, getattr(ops, "Cd", None), op.G if op is not None else None]
    if isinstance(Phi, list):   # a basis held as blocks [(Φ_b, …)]: A Φ_b side by side
        return [np.hstack([apply(A, b[0]) for b in Phi]) for A in mats if A is not None]
    return [apply(A, Phi) for A in mats if A is not None]


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
                        eta0=dict(par.eta0), plates=project_plates(par, Phi), **speed)


def project_plates(par: ParametricOperators, Phi: np.ndarray) -> dict[str, PlateProjection]:
    """Φᵀ K_c,p Φ, Φᵀ K_t,p Φ, Φᵀ K_f,p Φ of every named rigid plate (:class:`PlateProjection`)."""
    out = {}
    for name, pm in par.plates.items():
        plate = pm.plate
        Kc, Kf, Kt = par.interface_matrices(name)
        out[name] = PlateProjection(project(Kc, Phi), project(Kt, Phi), None if Kf is None else project(Kf, Phi),
                                    kn=plate.kn, mu=plate.mu, sliding=float(plate.sliding), kt=plate.kt)
    return out


def lifted_residuals(par: ParametricOperators, Phi: np.ndarray, params: Mapping[str, float],
                     lam: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Backward error of each lifted pair (λ, x = Φy) in the full problem:
    η = ‖(λ²M + λC + K)x‖ / ((|λ|²‖M‖ + |λ|‖C‖ + ‖K‖)‖x‖), ∞-norms of the matrices, 2-norms of
    the vectors (Tisseur's normwise backward error of a polynomial eigenpair); with a loss factor
    K = K_r + iK_i and ‖K_r‖ in the denominator.  :func:`lifted_residuals_at` for one point."""
    return lifted_residuals_at(par, Phi, [(params, lam, Y)])[0]


def lifted_residuals_at(par: ParametricOperators, Phi: np.ndarray,
                        pairs: list[tuple[Mapping[str, float], np.ndarray, np.ndarray]]) -> list[np.ndarray]:
    """:func:`lifted_residuals` at several points [(params, λ, Y)]: K(p), C(p) applied and normed
    term by term (:meth:`ParametricOperators.terms`, :func:`fem_squeal.fe.csr.sum_norms_inf`), never
    formed, each matrix applied once to the vectors of every point (x = Φy: the real and imaginary
    parts side by side, Φ @ Y would copy Φ to complex first) and the norms of all points merged in
    one pass (issue 23: the 7 check points of the 50k-DOF brake cost 0.9 s, 0.43 s of it forming
    K(p) with a merged pattern per point)."""
    if not pairs:
        return []
    comm = par.ops.K.getComm().tompi4py()
    M = par.ops.M
    families = []      # per point: (the factor of the family in λ, its terms) for K, C and i K_i
    for params, lam, _ in pairs:
        Kt, Ct = par.terms(params)
        families.append([(np.ones_like(lam), Kt), (lam, Ct), (1j * np.ones_like(lam), par.loss_terms(params)),
                         (lam ** 2, [(M, 1.0)])])
    mats: dict[int, PETSc.Mat] = {}
    for fam in families:
        for _, terms in fam:
            for A, _ in terms:
                mats.setdefault(id(A), A)
    ks = [Y.shape[1] for _, _, Y in pairs]
    offs = np.concatenate([[0], np.cumsum(2 * np.array(ks))]).astype(int)
    Yall = np.empty((Phi.shape[1], offs[-1]))
    for q, (_, _, Y) in enumerate(pairs):
        Yall[:, offs[q]:offs[q] + ks[q]], Yall[:, offs[q] + ks[q]:offs[q + 1]] = Y.real, Y.imag
    XX = matmul_f(Phi, Yall)

    def point(A: np.ndarray, q: int) -> np.ndarray:
        return A[:, offs[q]:offs[q] + ks[q]] + 1j * A[:, offs[q] + ks[q]:offs[q + 1]]
    R = [np.zeros((Phi.shape[0], k), complex) for k in ks]
    for key, A in mats.items():
        AX = apply(A, XX)
        for q, fam in enumerate(families):
            for factor, terms in fam:
                c = sum(ci for B, ci in terms if id(B) == key)
                if c != 0:
                    R[q] += c * point(AX, q) * factor[None, :]

    def norms(j: int) -> np.ndarray:          # family j's ∞-norm at every point
        used = {id(A): A for fam in families for A, _ in fam[j][1]}
        if not used:
            return np.zeros(len(pairs))
        coefs = np.array([[sum(c for B, c in fam[j][1] if id(B) == key) for fam in families] for key in used])
        return sum_norms_inf(list(used.values()), coefs)
    nK, nC, nM = norms(0), norms(1), M.norm(PETSc.NormType.INFINITY)
    out = []
    for q, (_, lam, _) in enumerate(pairs):
        r = np.sqrt(comm.allreduce(np.sum(np.abs(R[q]) ** 2, axis=0), op=MPI.SUM))
        x = np.sqrt(comm.allreduce(np.sum(np.abs(point(XX, q)) ** 2, axis=0), op=MPI.SUM))
        a = np.abs(lam)
        out.append(r / ((a ** 2 * nM + a * nC[q] + nK[q]) * x))
    return out


@dataclass
class ReductionReport:
    """How the basis was grown: one row per round, and whether the change met ``tol``."""

    rounds: list[dict]
    converged: bool
    tol: float
    estimate: float               # max relative change of the watched eigenvalues in the last round
    residuals: list[dict]         # lifted backward errors of the unstable pairs at the check points

    def as_dict(self) -> dict:
        return {"rounds": self.rounds, "converged": self.converged, "tol": self.tol,
                "estimated_error": self.estimate, "lifted_residuals": self.residuals}


def _in_band(lam: np.ndarray, band_hz) -> np.ndarray:
    """Eigenvalues with frequency in the band, above 1e-3 of its top (rigid-body modes of free
    parts sit at λ ≈ 0, where a relative change means nothing)."""
    f = lam.imag / TWO_PI
    return lam[(f >= max(band_hz[0], 1e-3 * band_hz[1])) & (f <= band_hz[1])]


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


#: orders of the static modal derivatives that stand in for the modes sampled at other E (1: the
#: tangent (K + σM)⁻¹K_iφ alone; 2: and (K + σM)⁻¹K_i of it; measured on the brake, see adaptive_reduce)
DERIVATIVE_ORDER = 2


def _modal_derivatives(par: ParametricOperators, solver: ShiftedSolver, V: np.ndarray,
                       parts: list[str], order: int | None = None) -> list[np.ndarray]:
    """[(K + σM)⁻¹K_i V, ((K + σM)⁻¹K_i)² V, …] for each part i, ``order`` terms each: the
    static modal derivatives of the modes V with respect to θ_i = E_i/E_i⁰, and their powers."""
    out = []
    for q in parts:
        D = V
        for _ in range(order or DERIVATIVE_ORDER):
            D = solver.solve(apply(par.K_parts[q], D))
            out.append(D)
    return out


def adaptive_reduce(ops: Operators, par: ParametricOperators, band_hz: tuple[float, float],
                    check_points: list[dict[str, float]], *, tol: float = 1e-3,
                    cut_factors: tuple[float, ...] = (1.25, 1.6, 2.0, 2.5), samples=(), static: bool = True,
                    sigma_hz: float | None = None, growth_tol: float = 1e-6, enrich_rtol: float = 1e-3,
                    preload=None, options=None, log=None, extra: np.ndarray | None = None
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
    need_solver = (static and (ops.Kf is not None or gyroscopic)) or e_parts
    wall = lambda t0: comm.allreduce(MPI.Wtime() - t0, op=MPI.MAX)  # noqa: E731
    t = MPI.Wtime()
    solver = ShiftedSolver(ops.K, ops.M, np.sign(sigma_hz) * (TWO_PI * sigma_hz) ** 2, options, "basis_static_") \
        if need_solver else None
    factor_s = wall(t)
    modes, solved_cut, dirs = None, 0.0, None
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
                modes, solved_cut, dirs = (w2, V), want, None
                row["modes_seconds"] = wall(t0)
            keep = np.sqrt(np.abs(modes[0])) / TWO_PI <= cut
            if e_parts and dirs is None:
                t0 = MPI.Wtime()
                dirs = _modal_derivatives(par, solver, modes[1], e_parts)
                row["directions_seconds"] = wall(t0)
            directions = None
            if dirs is not None:  # the derivatives of the modes of this round, every order
                directions = np.hstack([d[:, keep] for d in dirs])
            t0 = MPI.Wtime()
            basis = build_basis(ops, par, cut, samples=other_samples, static=static, sigma_hz=sigma_hz,
                                options=options, n_start=n_start, enrich_rtol=enrich_rtol, extra=extra,
                                modes=(modes[0][keep], modes[1][:, keep]), directions=directions,
                                solver=solver)
            row["basis_seconds"] = wall(t0)
            t0 = MPI.Wtime()
            model = reduce(ops, par, basis, preload)
            row["project_seconds"] = wall(t0)
            t0 = MPI.Wtime()
            lams = [_in_band(solve_points(model, {k: np.array([v]) for k, v in p.items()})[0], band_hz)
                    for p in check_points]
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
    converged = change <= tol
    if not converged:
        raise ReductionError(
            f"reduced basis: eigenvalues still moved by {change:.1e} > tol {tol:.0e} with modes up to "
            f"{cut_factors[-1]:g} × {band_hz[1]:g} Hz; rounds: " +
            "; ".join(f"{r['size']} vectors: {r['change']:.1e}" for r in rounds) +
            " (raise analyses.reduced.cut_factors or tol)")
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
    return model, basis, ReductionReport(rounds, converged, tol, change, residuals)
