"""The full-order check of frequency-dependent loss factors: the nonlinear eigenproblem

    T(λ) x = (λ²M + λC + K_r + i K_i + i Σ_p η_p(|Im λ|/2π) θ_p K_p) x = 0

on the full mesh (K_r, C, M of :meth:`ParametricOperators.terms` at the point, K_i the loss factors of
the parts without a table, K_p the stiffness of part p with a table η_p(f), θ_p = E_p/E_p⁰), solved
near a start (λ₀, x₀) (the reduced fixed point, lifted) by residual inverse iteration (Neumaier 1985)
with the fixed shift σ = λ₀:

    w = T(σ)⁻ᴴ c                       (c = x₀: the normalisation cᴴx = 1; one transposed solve)
    λ_{k+1}: wᴴ T(λ) x_k = 0           (= cᴴ T(σ)⁻¹ T(λ) x_k: a scalar equation, quadratic in λ for η
                                        frozen, solved by the fixed point in f of the scalar problem)
    x_{k+1} = x_k − T(σ)⁻¹ T(λ_{k+1}) x_k,  scaled to cᴴx_{k+1} = 1

until |λ_{k+1} − λ_k| ≤ tol |λ_{k+1}|.  Without a start vector (a check that takes only the reduced
eigenvalue λ₀, not its lifted vector) x₀ = T(σ)⁻¹T(σ)⁻¹b, two inverse-iteration steps from a
pseudo-random b of fixed seed: with σ within δ of an eigenvalue, the other eigenvectors' parts shrink
by (δ/gap)², and the pair converged to does not depend on b beyond the tolerance.  T's dependence
on |Im λ| is not holomorphic, but the iteration needs only T(λ) at the iterates and one factorisation at σ.
PETSc here has real scalars: T(σ) = A_r + iA_i is factorised as its real equivalent [[A_r, −A_i], [A_i, A_r]] of
twice the size (as :meth:`ParametricOperators.real_equivalent`), whose transpose is the real equivalent of
T(σ)ᴴ. The answer is certified by the backward error ‖T(λ)x‖ / ((|λ|²‖M‖ + |λ|‖C‖ + ‖K_r‖)‖x‖) (∞-norms of the
matrices) with η at the answer's own frequency.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.assembly import combination
from fem_squeal.fe.dense import apply
from fem_squeal.fe.factorisation import LU, factor_solver
from fem_squeal.fe.projection.parametric import ParametricOperators, _block_matrix
from fem_squeal.reduced import affine
from fem_squeal.reduced.affine import e_param, eta_param
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.loss_fixed_point import scalar_root
from fem_squeal.util.errors import ModelError


@dataclass
class NEPResult:
    """The eigenvalue, its vector (rank-local rows), the iterations, whether it converged, the history
    of |Δλ|/|λ| and the backward error of the answer."""

    eigenvalue: complex
    vector: np.ndarray
    iterations: int
    converged: bool
    history: list[float]
    backward_error: float


def _start_vector(comm, n_local: int, seed: int = 39) -> np.ndarray:
    """The rank-local rows of a pseudo-random complex vector of fixed seed (drawn over the global size)."""
    first = comm.exscan(n_local) or 0
    n = comm.allreduce(n_local, op=MPI.SUM)
    rng = np.random.default_rng(seed)
    b = rng.standard_normal(n) + 1j * rng.standard_normal(n)
    return b[first:first + n_local]


def full_loss_nep(par: ParametricOperators, point: Mapping[str, float],
                  laws: Mapping[str, Callable[[float], float]], lam0: complex, x0: np.ndarray | None = None, *,
                  tol: float = 1e-12, max_iterations: int = 60, options=None,
                  prefix: str = "loss_nep_", reverse: bool = False) -> NEPResult:
    """The eigenpair of T(λ) (module docstring) near (``lam0``, ``x0``): ``point`` the parameters (its
    ``eta.<p>`` of the table parts are ignored: their loss is η_p(f) alone, not added to a nominal η),
    ``laws`` part → η_p(f) (the tables at one temperature),
    ``x0`` the start vector's rank-local rows (complex; None: inverse iteration at ``lam0`` from a fixed
    vector).  ``reverse``: the disc turning the other way, C(−Ω) = C(|Ω|) − 2|Ω|G (the gyroscopic term
    turned; the friction's direction is the sign of μ in ``point``)."""
    unknown = sorted(p for p in laws if p not in par.parts)
    if unknown:
        raise ModelError(f"loss-factor NEP: no stiffness of part(s) {unknown} (parts: {par.parts})")
    # the table parts' loss enters through ``laws`` only: η = 0 in the fixed terms (not dropped from the
    # point, where the part's nominal η, a scene material's, would be added a second time)
    point = {**point, **{eta_param(p): 0.0 for p in laws}}
    comm = par.ops.K.getComm().tompi4py()
    Kt, Ct = par.terms(point)
    G = par.operating.G if par.operating is not None else None
    if reverse and G is not None:
        Ct = [(A, -c if A is G else c) for A, c in Ct]
    Kr = combination(Kt)
    C = combination(Ct) if Ct else None
    M = par.ops.M
    fixed = par.loss_terms(point)
    Ki = combination(fixed) if fixed else None
    theta = {p: affine.loss_coefficient(1.0, point.get(e_param(p), par.E0[p]), par.E0[p]) for p in laws}
    mats = {"M": M, "C": C, "K": Kr, "Ki": Ki, **{f"p:{p}": par.K_parts[p] for p in laws}}

    def products(x: np.ndarray) -> dict[str, np.ndarray]:
        X = np.column_stack([x.real, x.imag])
        out = {}
        for name, A in mats.items():
            if A is not None:
                AX = apply(A, X)
                out[name] = AX[:, 0] + 1j * AX[:, 1]
        return out

    def residual(lam: complex, P: dict[str, np.ndarray]) -> np.ndarray:
        f = abs(lam.imag) / TWO_PI
        r = lam ** 2 * P["M"] + P["K"]
        if "C" in P:
            r = r + lam * P["C"]
        if "Ki" in P:
            r = r + 1j * P["Ki"]
        for p in laws:
            r = r + 1j * float(laws[p](f)) * theta[p] * P[f"p:{p}"]
        return r

    def dot(a: np.ndarray, b: np.ndarray) -> complex:
        return complex(comm.allreduce(np.vdot(a, b), op=MPI.SUM))

    # T(σ) = A_r + i A_i as its real equivalent, factorised once
    s = complex(lam0)
    eta_s = {p: float(laws[p](abs(s.imag) / TWO_PI)) for p in laws}
    re = [(M, (s * s).real), (Kr, 1.0)] + ([(C, s.real)] if C is not None else [])
    im = [(M, (s * s).imag)] + ([(C, s.imag)] if C is not None else []) + ([(Ki, 1.0)] if Ki is not None else []) \
        + [(par.K_parts[p], eta_s[p] * theta[p]) for p in laws]
    Ar, Ai = combination(re), combination(im)
    A2 = _block_matrix([[(Ar, 1.0), (Ai, -1.0)], [(Ai, 1.0), (Ar, 1.0)]], Kr)
    ksp = factor_solver(A2, LU, prefix, options)
    b, z = A2.createVecs()
    n = M.getLocalSize()[0]

    def solve(r: np.ndarray, transpose: bool = False) -> np.ndarray:
        b.array[:n], b.array[n:] = r.real, r.imag
        (ksp.solveTranspose if transpose else ksp.solve)(b, z)
        return z.array_r[:n] + 1j * z.array_r[n:]

    if x0 is None:
        x0 = solve(_start_vector(comm, n))
        x0 = solve(x0 / np.sqrt(dot(x0, x0).real))
        x0 = x0 / np.sqrt(dot(x0, x0).real)
    c = np.asarray(x0, complex)
    x = c / dot(c, c)
    w = solve(c, transpose=True)
    lam, history, converged = s, [], False
    for _ in range(max_iterations):
        P = products(x)
        ap = {p: 1j * theta[p] * dot(w, P[f"p:{p}"]) for p in laws}
        a0 = dot(w, P["K"]) + (1j * dot(w, P["Ki"]) if "Ki" in P else 0.0)
        new = scalar_root(dot(w, P["M"]), dot(w, P["C"]) if "C" in P else 0.0, a0,
                          [(laws[p], v) for p, v in ap.items()], lam)
        x = x - solve(residual(new, P))
        x = x / dot(c, x)
        history.append(abs(new - lam) / abs(new))
        lam = new
        if history[-1] <= tol:
            converged = True
            break
    P = products(x)
    r = residual(lam, P)
    norm = lambda A: A.norm(PETSc.NormType.INFINITY) if A is not None else 0.0  # noqa: E731
    nr = np.sqrt(comm.allreduce(np.sum(np.abs(r) ** 2), op=MPI.SUM))
    nx = np.sqrt(comm.allreduce(np.sum(np.abs(x) ** 2), op=MPI.SUM))
    be = nr / ((abs(lam) ** 2 * norm(M) + abs(lam) * norm(C) + norm(Kr)) * nx)
    for A in (ksp, A2, Ar, Ai, b, z, Kr, C, Ki):
        if A is not None:
            A.destroy()
    return NEPResult(lam, x, len(history), converged, history, float(be))
