"""The full operators as affine functions of the parameters (μ, E of a part, speed, loss factors, brake
pressure):
K(p), C(p) term by term, their derivatives, the residuals of reduced pairs lifted into the full
model."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc
from scipy.sparse import csr_matrix

from fem_squeal.fe import interface as itf
from fem_squeal.fe.assembly import OperatingTerms, Operators, _owned_global_rows, combination
from fem_squeal.fe.csr import sum_norms_inf
from fem_squeal.fe.dense import apply, matmul_f
from fem_squeal.fe.model import ModelSpec
from fem_squeal.fe.pressure_terms import REFERENCE, PressureTerms
from fem_squeal.fe.projection.basis import project
from fem_squeal.reduced import affine
from fem_squeal.reduced.affine import (
    MU,
    PRESSURE,
    SPEED,
    e_param,
    eta_param,
    friction_damping_scale,
    split_param,
)
from fem_squeal.reduced.model import PlateProjection
from fem_squeal.util.errors import ModelError, UnknownNameError


class ParametricOperators:
    """Full-order K(p), C(p) of the affine form (:mod:`fem_squeal.reduced.affine`), term by term:
    used to verify the reduced model and to sample modes at parameter values.

    The parameters are those of :class:`~fem_squeal.reduced.model.ReducedModel`: ``mu``, ``E.<part>``
    and ``eta.<part>`` (``parts``), and ``mu.<c>``, ``kn.<c>``, ``kt.<c>`` of every contact interface c
    and of every named rigid plate (``ops.plate_parts``: assembled with ``parts=True``).
    The interface matrices are assembled at the closed points of ``preload`` (all points without
    one), as the reduced model's: the contact state of the preload is kept when k_n changes.
    A loss factor η makes K complex, which the real PETSc build cannot hold: :meth:`matrices`
    returns the real part and :meth:`loss_stiffness` the imaginary part Σ η_i θ_i K_i, from which
    :meth:`real_equivalent` builds the real problem of twice the size.
    With ``pressure`` (:class:`~fem_squeal.fe.pressure_terms.PressureTerms`, owned from then on:
    :meth:`destroy` destroys it) the brake pressure scale ``pressure`` is a parameter: at s ≠ 1 the
    stress stiffening K_σ0 = K_σ(u(1)) of ``operating`` is replaced by K_σ(u(s)) and the friction damping
    C_d by C_d(p(s)), both assembled from the preload state continued to s (not the reduced model's affine
    terms K_σ0 + (s − 1) K_σ,s, C_d + (s − 1) C_d,s, which this checks)."""

    def __init__(self, ops: Operators, spec: ModelSpec, mu0: float, parts: list[str] | None = None,
                 preload=None, operating: OperatingTerms | None = None, speed0: float = 0.0,
                 pressure: PressureTerms | None = None):
        self.ops, self.mu0 = ops, mu0
        if pressure is not None:
            _check_pressure_terms(pressure, operating, ops.Cd)
        self.pressure = pressure
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
        # the parts with a structural loss factor (η or a table η(f, T)): their i η K_p is a term the modes
        # do not span, whose static corrections join the basis (reductor.correction_operators)
        self.loss_parts = [p for p in self.parts if self.eta0[p] != 0
                           or getattr(spec.materials[p], "eta_table", None) is not None]
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
        # μ = 0 is accepted by a frictionless model
        return affine.parameter_names(self.parts, self.interfaces, speed=self.speed_varies,
                                      pressure=self.pressure is not None)

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
        return affine.mu_share(it.mu, self.mu0, it.has_friction and self.ops.Kf is not None)

    def _check(self, params: Mapping[str, float]) -> None:
        affine.check_names(params, self.parameters)
        for name, v in params.items():
            affine.check_range(name, v)

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
                E = params.get(e_param(p), self.E0[p])
                out.append((self.K_parts[p], affine.loss_coefficient(eta, E, self.E0[p])))
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
        self._operating(K, C, mu, params.get(SPEED, self.speed0), params.get(PRESSURE, REFERENCE))
        for p in self.parts:
            d = affine.modulus_coefficient(params.get(e_param(p), self.E0[p]), self.E0[p])
            if d != 0:
                K.append((self.K_parts[p], d))
                if self.beta[p] > 0:
                    C.append((self.K_parts[p], self.beta[p] * d))
        for name, it in self.interfaces.items():
            coefs = affine.interface_coefficients(params, name, it.kn, it.kt, mu, self._mu_share(it))
            if coefs:
                mats = self.interface_matrices(name)
                K += [(mats[j], c) for j, c in coefs if mats[j] is not None]
        return K, C

    def _operating(self, K: list, C: list, mu: float, speed: float, pressure: float = REFERENCE) -> None:
        """The terms K_σ0 + Ω²(K_σc − S) of K and Ω G + ((|μ|/|μ⁰|)(Ω₀/Ω) − 1) C_d of C (which holds C_d
        at the nominal point), appended to the term lists; at a pressure scale s ≠ 1, K_σ(u(s)) and
        C_d(p(s)) of the state at s in place of K_σ0 and C_d."""
        op, Cd = self.operating, self.ops.Cd
        at_s = self.pressure is not None and pressure != REFERENCE
        if op is not None and op.Ks0 is not None:
            K.append((self.pressure.stiffness_at(pressure) if at_s else op.Ks0, 1.0))
        if op is not None and op.G is not None:
            K.append((self.K2, speed ** 2))
            C.append((op.G, speed))
        if Cd is not None and self.mu0 != 0:
            if self.speed0:
                affine.check_damping_speed(speed)
            scale = friction_damping_scale(mu, self.mu0, speed, self.speed0)
            if at_s:    # C₀ holds C_d(p(1)): replaced by that of the state at s
                C += [(Cd, -1.0), (self.pressure.damping_at(pressure), scale)]
            else:
                C.append((Cd, scale - 1.0))

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
        if self.pressure is not None:
            self.pressure.destroy()
        for mats in self._interface.values():
            for A in mats:
                if A is not None:
                    A.destroy()


def parameter_derivative(par: ParametricOperators, name: str) -> tuple[PETSc.Mat, PETSc.Mat | None, complex]:
    """(∂K/∂p, ∂C/∂p or None, factor) of the full operators at the nominal point: the derivative is
    factor·∂K/∂p (factor i for a loss factor η, whose term is iθK_i; 1 otherwise).  The same terms
    as :meth:`fem_squeal.reduced.model.ReducedModel.derivative`: ∂K/∂μ = K_f/μ⁰; ∂K/∂E_i = K_i/E_i⁰,
    ∂C/∂E_i = β_i K_i/E_i⁰; ∂K/∂η_i = iK_i; ∂K/∂μ_c = K_f,c¹; ∂K/∂k_n,c = (K_c,c + μ_c⁰K_f,c¹)/k_n,c⁰;
    ∂K/∂k_t,c = K_t,c¹; with friction damping ∂C/∂μ = C_d/μ⁰; ∂K/∂Ω = 2Ω₀(K_σc − S), ∂C/∂Ω = G − C_d/Ω₀;
    ∂K/∂s = K_σ,s, ∂C/∂s = C_d,s (the pressure's slopes).  New matrices (the caller destroys them)."""
    par._check({name: 1.0})
    prefix, target = split_param(name)
    if name == PRESSURE:
        pt = par.pressure
        dK = combination([(pt.stiffness_slope, 1.0)]) if pt.stiffness_slope is not None else par.ops.K.duplicate()
        if pt.stiffness_slope is None:
            dK.zeroEntries()
        dC = combination([(pt.damping_slope, 1.0)]) if pt.damping_slope is not None else None
        return dK, dC, 1.0
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


def _check_pressure_terms(pressure: PressureTerms, operating: OperatingTerms | None, Cd: PETSc.Mat | None) -> None:
    """The pressure terms match the operators: a stress stiffening K_σ0 and a friction damping C_d of the
    operators each need theirs across the pressures, and a term across the pressures needs its operator."""
    Ks0 = operating.Ks0 if operating is not None else None
    for what, nominal, across in (("the stress stiffening K_σ (preload.geometric_stiffness)", Ks0,
                                   pressure.stiffness),
                                  ("the friction damping C_d (friction_damping)", Cd, pressure.damping)):
        if (nominal is None) != (across is None):
            raise ModelError(f"pressure: {what} " + ("is not in these operators" if nominal is None else
                                                     "grows with the pressure, but the pressure terms lack it"))


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
