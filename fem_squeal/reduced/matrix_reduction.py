"""The reduced model of a model given as matrices (:class:`fem_squeal.reduced.matrix_model.MatrixModel`):
a basis V (n × m) and every affine term projected once, A_k,r = Vᵀ A_k V, so that at any point p

    (λ² M_r(p) + λ C_r(p) + K_r(p)) y = 0,   A_r(p) = Σ_k c_k(p) A_k,r,   x ≈ V y.

Two bases:

- ``modes`` (where the problem has a symmetric part): the real modes Φ of the symmetric parts at the
  nominal point, K_s φ = ω² M_s φ (K_s = (K + Kᵀ)/2, M_s = (M + Mᵀ)/2, M_s positive definite), plus the
  static corrections (K_s − σM_s)⁻¹ A_k Φ of every term A_k of K and C that is non-symmetric or whose
  coefficient depends on a parameter (what the modes of K_s alone miss: the circulatory and gyroscopic
  couplings and the parameter directions); the whole M_s-orthonormalised column by column
  (:func:`orthonormal_columns`: Gram–Schmidt twice, a column dropped where less than 1e-5 of its
  M_s-norm is new).
- ``snapshots`` (none: M_s not positive definite, or asked for): the eigenvectors x of the
  non-symmetric problem itself at sampled parameter values (real and imaginary parts), from a sparse
  shift-invert solve of its linearisation, orthonormalised column by column (under MPI the same basis
  built on the ranks' rows: :mod:`fem_squeal.fe.matrix_snapshots`).

:class:`ReducedMatrixModel` answers ``matrices(points, n)`` as :class:`fem_squeal.reduced.model.ReducedModel`
does (K, C of λ²I + λC + K: the terms are pre-multiplied by M_r⁻¹ once when M does not depend on the
parameters, per point otherwise), so the sweep, tracking and grid code
(:mod:`fem_squeal.reduced.sweep`, :mod:`fem_squeal.reduced.tracking`) run on it unchanged."""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fem_squeal.reduced.affine import check_names
from fem_squeal.reduced.matrix_model import OPERATORS, MatrixModel
from fem_squeal.util.errors import ModelError

#: relative size (of the largest) under which a direction of the basis is dropped as dependent
DROP_RTOL = 1e-10


def _sym(A: sp.spmatrix) -> sp.csr_matrix:
    return (0.5 * (A + A.T)).tocsr()


def orthonormal(V: np.ndarray, gram: Callable[[np.ndarray], np.ndarray],
                norms: Callable[[np.ndarray], np.ndarray] | None = None, rtol: float = DROP_RTOL) -> np.ndarray:
    """An orthonormal basis of the columns of V in the inner product of ``gram`` (``gram(V) = VᵀWV``),
    from the eigen-decomposition G = U diag(d) Uᵀ of the Gram matrix, V ← V U_k d_k^(−1/2), directions of
    relative weight d < rtol·max d dropped.  V may be the rows of one rank of a distributed basis: then
    ``gram`` and ``norms`` (the columns' Euclidean norms; default: of V itself) sum over the ranks and
    return the same numbers on each."""
    V = V / np.maximum(np.linalg.norm(V, axis=0) if norms is None else norms(V), 1e-300)
    for _ in range(2):                  # twice: the Gram matrix squares the condition number
        G = gram(V)
        d, U = np.linalg.eigh(0.5 * (G + G.T))
        keep = d > rtol * d.max()
        V = V @ (U[:, keep] / np.sqrt(d[keep]))
    return V


def orthonormal_columns(V: np.ndarray, mass: Callable[[np.ndarray], np.ndarray] | None = None,
                        total: Callable[[np.ndarray], np.ndarray] | None = None, rtol: float = DROP_RTOL
                        ) -> np.ndarray:
    """A W-orthonormal basis Q (QᵀWQ = I) of the columns of V, W applied by ``mass`` (the identity where
    None), by classical Gram–Schmidt twice, column by column in their order (the columns already kept
    are not changed): a = v/‖v‖_W, a ← a − Q(QᵀWa) twice, kept as a/‖a‖_W where ‖a‖_W > √rtol (what is
    new in the column), else dropped as dependent.  V may be the rows of one rank of a distributed
    basis: ``total`` sums over the ranks (the same numbers on each).

    Unlike :func:`orthonormal` (the eigen-decomposition of the Gram matrix VᵀWV, whose rounding of
    ε‖G‖ moves a direction of relative weight d by ε/d), a kept direction is determined to ε/‖a‖_W ≥
    ε/√rtol: the rounding of a different summation order (another number of ranks) moves the exported
    brake's reduced eigenvalues by 1e-8 with :func:`orthonormal` (its Gram eigenvalues run without a gap
    from 1e-13 to 1), by 1e-10 here."""
    total = total or (lambda x: x)
    mass = mass or (lambda x: x)
    V = np.asarray(V, float)
    WV = mass(V)
    norms = np.sqrt(np.maximum(total(np.einsum("ij,ij->j", V, WV)), 0.0))
    Q, WQ = np.empty_like(V), np.empty_like(V)
    k, tol = 0, np.sqrt(rtol)
    for j in range(V.shape[1]):
        if not norms[j] > 0:
            continue
        a = V[:, j] / norms[j]
        for _ in range(2):
            a = a - Q[:, :k] @ total(WQ[:, :k].T @ a)
        Wa = mass(a[:, None])[:, 0]
        r = np.sqrt(max(float(total(np.array([a @ Wa]))[0]), 0.0))
        if r > tol:
            Q[:, k], WQ[:, k] = a / r, Wa / r
            k += 1
    return Q[:, :k]


def modal_basis(model: MatrixModel, matrices: Mapping[str, sp.spmatrix], n_modes: int,
                corrections: bool = True, shift: float = -1.0) -> tuple[np.ndarray, np.ndarray, int]:
    """(V, f [Hz] of the real modes, the number of static corrections kept): the ``n_modes`` lowest
    real modes of the symmetric parts at the nominal point plus, with ``corrections``, the static
    corrections (K_s − σM_s)⁻¹ A_k Φ of the non-symmetric or parameter-dependent terms of K and C
    (σ = ``shift`` [rad²/s²] < 0: a singular K_s is allowed); V is M_s-orthonormal.  Raises a
    ModelError where M_s is not positive definite (then: :func:`snapshot_basis`)."""
    ops = model.assemble(matrices)
    Ms, Ks = _sym(sp.csr_matrix(ops["M"])), _sym(sp.csr_matrix(ops["K"]))
    n = Ks.shape[0]
    if n_modes < 1 or n_modes >= n - 1:
        raise ModelError(f"modes: must be in [1, {n - 2}] for {n} DOFs (got {n_modes})")
    lu = spla.splu((Ks - shift * Ms).tocsc())
    op = spla.LinearOperator((n, n), matvec=lambda x: lu.solve(np.asarray(x, float).ravel()), dtype=float)
    try:
        w2, Phi = spla.eigsh(Ks, n_modes, Ms, sigma=shift, OPinv=op, which="LM", tol=1e-12)
    except (spla.ArpackError, spla.ArpackNoConvergence) as e:
        raise ModelError(f"modes: the real modes of the symmetric part did not converge ({e})") from None
    if np.min(np.diag(Phi.T @ Ms @ Phi)) <= 0:
        raise ModelError("modes: the symmetric part of M is not positive definite")
    order = np.argsort(w2)
    w2, Phi = w2[order], Phi[:, order]
    extra = []
    if corrections:
        for name in ("K", "C"):
            op_ = model.operators.get(name)
            for t in (op_.terms if op_ is not None else ()):
                A = sp.csr_matrix(matrices[t.matrix])
                if t.parameters or abs(A - A.T).sum() > 1e-14 * abs(A).sum():
                    extra.append(np.column_stack([lu.solve(c) for c in (A @ Phi).T]))
    V = orthonormal_columns(np.hstack([Phi, *extra]), Ms.__matmul__)
    f = np.sign(w2) * np.sqrt(np.abs(w2)) / (2 * np.pi)
    return V, f, V.shape[1] - n_modes


def qep_eigs(ops: Mapping[str, sp.spmatrix], k: int, target_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(λ (k,), X (n, k)): the ``k`` eigenpairs of (λ²M + λC + K)x = 0 nearest i·2π·target_hz, from a
    sparse shift-invert solve of the linearisation [[0, I], [−K, −C]] z = λ [[I, 0], [0, M]] z (SciPy)."""
    M, K = sp.csr_matrix(ops["M"]), sp.csr_matrix(ops["K"])
    n = K.shape[0]
    C = sp.csr_matrix(ops["C"]) if "C" in ops else sp.csr_matrix((n, n))
    eye = sp.identity(n, format="csr")
    A = sp.bmat([[None, eye], [-K, -C]], format="csc")
    B = sp.bmat([[eye, None], [None, M]], format="csc")
    lam, Z = spla.eigs(A, k, B, sigma=2j * np.pi * target_hz, which="LM", tol=1e-12)
    return lam, Z[:n]


def nearness(lam: np.ndarray, target_hz: float) -> np.ndarray:
    """|ν| = |λ/(λ² + ω²)|, ω = 2π·target_hz: how near i·ω (and −i·ω) the eigenvalue λ is for the
    shift-invert of the real linearisation at σ = iω that :func:`qep_eigs` runs (SciPy takes the real
    part of (A − σB)⁻¹, whose eigenvalues are ½(1/(λ − σ) + 1/(λ − σ̄)) = ν, and returns the ``k`` of
    largest |ν|: conjugates alike; at ω = 0 the smallest |λ|)."""
    lam = np.asarray(lam, complex)
    return np.abs(lam / (lam ** 2 + (2 * np.pi * target_hz) ** 2))


def nearest(lam: np.ndarray, k: int, target_hz: float) -> np.ndarray:
    """The indices of the ``k`` eigenvalues of ``lam`` of largest :func:`nearness`, nearest first (ties,
    as conjugates: the larger Im λ first)."""
    return np.lexsort((-np.asarray(lam).imag, -nearness(lam, target_hz)))[:k]


def real_columns(X: np.ndarray, total: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """[Re X', Im X'] of the eigenvectors X (columns; this rank's rows with ``total`` the sum over the
    ranks) each turned to the phase where Σ x_i² is real and positive (x' = x e^(−i arg(Σx²)/2): Re x' ⟂
    Im x', ‖Re x'‖ ≥ ‖Im x'‖), the same columns whatever phase a solver returned; the span of the pair is
    that of x and x̄.  An imaginary part under 1e-8 of the real one (a real eigenvalue) is left out."""
    total = total or (lambda x: x)
    X = np.asarray(X, complex)
    s = total(np.sum(X * X, axis=0))
    X = X * np.exp(-0.5j * np.angle(s))[None, :]
    re, im = np.ascontiguousarray(X.real), np.ascontiguousarray(X.imag)
    n_re, n_im = (np.sqrt(total(np.einsum("ij,ij->j", A, A))) for A in (re, im))
    return np.hstack([re, im[:, n_im > 1e-8 * n_re]])


def snapshot_basis(model: MatrixModel, matrices: Mapping[str, sp.spmatrix], points: Sequence[Mapping[str, float]],
                   k: int, target_hz: float) -> np.ndarray:
    """V: the real and imaginary parts (:func:`real_columns`) of ``k`` eigenvectors of the non-symmetric
    problem nearest ±``target_hz`` (:func:`qep_eigs`, nearest first: :func:`nearest`) at each of ``points``,
    orthonormalised (:func:`orthonormal_columns`)."""
    cols = []
    for p in points:
        lam, X = qep_eigs(model.assemble(matrices, p), k, target_hz)
        cols.append(real_columns(X[:, nearest(lam, k, target_hz)]))
    return orthonormal_columns(np.hstack(cols))


@dataclass
class ReducedMatrixModel:
    """The projected terms of a :class:`MatrixModel` (module docstring): ``terms[op][k] = Vᵀ A_k V`` in
    the order of ``model.operators[op].terms``; ``info``: how the basis was built."""

    model: MatrixModel
    terms: dict[str, list[np.ndarray]]
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        self._const_mass = not self.model.operators["M"].parameters
        if self._const_mass:          # M_r⁻¹ applied to the terms of K and C once
            Mr = sum(c * A for c, A in zip(self.model.operators["M"].coefficients({}), self.terms["M"]))
            lu = la.lu_factor(Mr)
            self._scaled = {op: [la.lu_solve(lu, A) for A in self.terms[op]] for op in self.terms if op != "M"}

    @property
    def size(self) -> int:
        return self.terms["K"][0].shape[0]

    @property
    def parameters(self) -> list[str]:
        return self.model.parameters

    def nominal(self) -> dict[str, float]:
        return dict(self.model.nominal)

    @property
    def damped(self) -> bool:
        return self.model.damped

    def _operator(self, op: str, values: Mapping[str, np.ndarray], n: int, scaled: bool) -> np.ndarray:
        coefs = self.model.operators[op].coefficients(values)
        mats = self._scaled[op] if scaled else self.terms[op]
        c = np.stack([np.broadcast_to(np.asarray(x, float), (n,)) for x in coefs], axis=1)
        return np.tensordot(c, np.stack(mats), axes=1)

    def matrices(self, points: Mapping[str, np.ndarray] | None = None, n: int = 1
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        """K(p), C(p) (None: undamped) of λ²I + λC + K as (n, m, m) stacks for ``n`` points (the
        parameters not given at their nominal values)."""
        points = dict(points or {})
        check_names(points, self.parameters, " of this matrix model")
        values = {k: np.broadcast_to(np.asarray(points.get(k, v), float), (n,))
                  for k, v in self.model.nominal.items()}
        if self._const_mass:
            return (self._operator("K", values, n, True),
                    self._operator("C", values, n, True) if self.damped else None)
        Mr = self._operator("M", values, n, False)
        K = np.linalg.solve(Mr, self._operator("K", values, n, False))
        C = np.linalg.solve(Mr, self._operator("C", values, n, False)) if self.damped else None
        return K, C

    def _check(self, names) -> None:
        check_names(names, self.parameters, " of this matrix model")

    def derivative(self, name: str, point: Mapping[str, float] | None = None
                   ) -> tuple[np.ndarray, np.ndarray | None]:
        """(∂K̃/∂p, ∂C̃/∂p or None) of K̃ = M_r⁻¹K_r, C̃ = M_r⁻¹C_r at ``point`` (nominal where not given) for
        the parameter ``name``: ∂K̃ = M_r⁻¹(∂K_r − ∂M_r K̃), ∂C̃ = M_r⁻¹(∂C_r − ∂M_r C̃), ∂A_r = Σ_k ∂c_k/∂p A_k,r
        (the coefficients differentiated exactly: :func:`fem_squeal.reduced.expressions.derivative_scalar`).
        At an eigenpair of λ²I + λC̃ + K̃, λ∂C̃ + ∂K̃ = M_r⁻¹(λ²∂M_r + λ∂C_r + ∂K_r) on x: the sensitivity
        formula (:mod:`fem_squeal.reduced.sensitivity`) is that of the unscaled problem."""
        self._check([name, *(point or {})])
        values = self.model.point(point)

        def part(op: str, d: bool) -> np.ndarray:
            ops = self.model.operators[op]
            c = ops.derivatives(values, name) if d else ops.coefficients(values)
            return sum(float(x) * A for x, A in zip(c, self.terms[op]))

        Mr = part("M", False)
        K, C = self.matrices({k: np.array([v], float) for k, v in (point or {}).items()}, 1)
        dM = part("M", True)
        dK = np.linalg.solve(Mr, part("K", True) - dM @ K[0])
        dC = np.linalg.solve(Mr, part("C", True) - dM @ C[0]) if C is not None else None
        return dK, dC

    def frictionless_frequencies(self) -> np.ndarray:
        """The real-mode frequencies [Hz] of the basis (``info['modes_hz']``; empty for snapshots)."""
        return np.asarray(self.info.get("modes_hz", []), float)


def project(model: MatrixModel, matrices: Mapping[str, sp.spmatrix], V: np.ndarray, rows: np.ndarray | None = None,
            total: Callable[[np.ndarray], np.ndarray] | None = None) -> dict[str, list[np.ndarray]]:
    """Every affine term projected once: {op: [Vᵀ A_k V]}.  Distributed: ``matrices`` the rows of this
    rank, ``rows`` the same rows of the whole basis ``V`` and ``total`` the sum over the ranks, so that
    Vᵀ A V = Σ_ranks V_rᵀ (A_r V)."""
    rows = V if rows is None else rows
    cache: dict[str, np.ndarray] = {}
    out = {}
    for op in OPERATORS:
        if op not in model.operators:
            continue
        out[op] = []
        for t in model.operators[op].terms:
            if t.matrix not in cache:
                local = rows.T @ (sp.csr_matrix(matrices[t.matrix]) @ V)
                cache[t.matrix] = local if total is None else total(local)
            out[op].append(cache[t.matrix])
    return out


def reduce_matrix_model(model: MatrixModel, matrices: Mapping[str, sp.spmatrix], *, basis: str = "auto",
                        modes: int = 20, corrections: bool = True, snapshot_points: Sequence[Mapping] = (),
                        snapshot_modes: int = 10, target_hz: float = 0.0) -> ReducedMatrixModel:
    """The reduced model of ``model`` on its named ``matrices`` (SciPy, whole): ``basis`` "modes",
    "snapshots" or "auto" (modes where M's symmetric part is positive definite, else snapshots at
    ``snapshot_points``, ``snapshot_modes`` eigenvectors each nearest ``target_hz``)."""
    if basis not in ("auto", "modes", "snapshots"):
        raise ModelError(f"basis: must be 'auto', 'modes' or 'snapshots' (got {basis!r})")
    info: dict = {}
    if basis != "snapshots":
        try:
            V, f, n_corr = modal_basis(model, matrices, modes, corrections)
            info = {"basis": "modes", "modes": modes, "corrections": n_corr, "modes_hz": [float(x) for x in f]}
        except ModelError:
            if basis == "modes":
                raise
    if not info:
        if not snapshot_points:
            raise ModelError("snapshots: no parameter points to sample")
        V = snapshot_basis(model, matrices, snapshot_points, snapshot_modes, target_hz)
        info = {"basis": "snapshots", "points": [dict(p) for p in snapshot_points], "per_point": snapshot_modes}
    info["size"] = int(V.shape[1])
    return ReducedMatrixModel(model, project(model, matrices, V), info)
