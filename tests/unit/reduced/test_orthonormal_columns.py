"""fem_squeal.reduced.matrix_reduction.orthonormal_columns: the rank-revealing W-orthonormalisation of the
matrix models' bases (Gram–Schmidt twice), whose kept span does not move with the summation order (the
number of ranks) where the columns are nearly dependent."""
from __future__ import annotations

import numpy as np

from fem_squeal.reduced.matrix_reduction import orthonormal_columns


def _graded(n: int = 2000, m: int = 40):
    """Columns whose singular values run from 1 to 3e-7 without a gap (the Gram eigenvalues 1 … 1e-13, as
    the exported brake's modes and static corrections), a diagonal inner product W, a row permutation."""
    rng = np.random.default_rng(0)
    U, _ = np.linalg.qr(rng.standard_normal((n, m)))
    R, _ = np.linalg.qr(rng.standard_normal((m, m)))
    return U @ np.diag(np.logspace(0, -6.5, m)) @ R.T, 1.0 + rng.random(n), rng.permutation(n)


def test_w_orthonormal_span_and_dependent_columns_dropped():
    V, w, _ = _graded()
    mass = lambda X: w[:, None] * X     # noqa: E731
    extra = V[:, :3] @ np.array([1.0, -2.0, 0.5])           # a dependent column: dropped
    Q = orthonormal_columns(np.column_stack([V[:, :10], extra, V[:, 10:]]), mass)
    assert Q.shape[1] == 40
    assert np.abs(Q.T @ mass(Q) - np.eye(40)).max() <= 1e-13
    assert np.linalg.norm(V - Q @ (Q.T @ mass(V))) <= 1e-12 * np.linalg.norm(V)
    assert np.allclose(Q[:, 0], V[:, 0] / np.sqrt(V[:, 0] @ mass(V[:, :1])[:, 0]))   # the first column kept


def test_the_span_does_not_move_with_the_summation_order():
    """The rows in another order (the sums of another number of ranks): the same span to 1e-9 (the
    eigen-decomposition of the Gram matrix, fem_squeal.reduced.matrix_reduction.orthonormal, moves it by
    1e-7 here)."""
    V, w, p = _graded()
    a = orthonormal_columns(V, lambda X: w[:, None] * X)
    b = orthonormal_columns(V[p], lambda X: w[p][:, None] * X)[np.argsort(p)]
    assert a.shape == b.shape
    assert np.linalg.norm(a - b @ (b.T @ (w[:, None] * a)), 2) <= 1e-9
