"""The curved tetrahedra's Jacobian determinants of geometry.quality (one matrix product for all sample
points, determinants by the triple product) against numpy's determinant of each J(ξ) formed point by point."""
from __future__ import annotations

import numpy as np

from geometry import quality


def _reference(x: np.ndarray) -> np.ndarray:
    return np.stack([np.linalg.det(np.einsum("man,ab->mnb", x, quality._tet10_gradients(xi)))
                     for xi in quality._XI], axis=1)


def test_tet10_jacobians_equal_the_determinants_point_by_point():
    rng = np.random.default_rng(7)
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    mids = np.array([(corners[a] + corners[b]) / 2 for a, b in quality._EDGES])
    straight = np.vstack([corners, mids])
    # scaled, turned and curved copies (mid-edge nodes moved by up to 30 % of the edge), one inverted
    x = np.stack([s * straight @ np.linalg.qr(rng.normal(size=(3, 3)))[0].T
                  + 0.3 * s * np.vstack([np.zeros((4, 3)), rng.uniform(-1, 1, (6, 3))])
                  for s in rng.uniform(1e-3, 1.0, 200)])
    x[0, 4] = x[0, 0] - 2.0 * (x[0, 1] - x[0, 0])
    got, ref = quality._tet10_jacobians(x), _reference(x)
    scale = np.abs(ref).max(axis=1, keepdims=True)
    # both are the determinant to round-off: a few ε times the products of J's entries, which the largest
    # |det J| of the element bounds for these shapes (2e-14 measured on the 255k-DOF disc): 1e-13
    assert np.max(np.abs(got - ref) / scale) < 1e-13
    assert (got[0] <= 0).any() and np.array_equal(np.sign(got) <= 0, np.sign(ref) <= 0)
