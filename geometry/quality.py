"""Element quality of tetrahedral meshes: inverted, degenerate and poorly shaped elements.

- **Inverted**: the Jacobian determinant det J(ξ) of the element map is ≤ 0 somewhere.  It is
  sampled at the corners, mid-edges and centroid (11 points) and scaled by 6 V of the straight tetrahedron
  on the corners; a linear tetrahedron has one value, 6 V with V the signed volume (positive for
  the Abaqus/Nastran/VTK node order: 1-2-3 counter-clockwise seen from 4).
- **Aspect ratio** γ = h_max / (2√6 r_in) with r_in = 3V / A (inradius), 1 for the regular
  tetrahedron.  The element stiffness condition number grows like γ², so γ > ``DEGENERATE`` (10⁴:
  κ amplified 10⁸, half the digits of a double gone on that element) is treated as degenerate;
  γ above the scene's ``max_aspect_ratio`` is a warning.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

DEGENERATE = 1e4

# reference points: corners, mid-edges (VTK order), centroid
_XI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1],
                [.5, 0, 0], [.5, .5, 0], [0, .5, 0], [0, 0, .5], [.5, 0, .5], [0, .5, .5], [.25, .25, .25]])


class Quality(NamedTuple):
    """Per-element measures, and the indices of the bad and poor elements."""

    jacobian_ratio: np.ndarray      # min over samples of det J / (6 V_corners); 1 for straight elements
    aspect_ratio: np.ndarray        # γ (1 = regular)
    inverted: np.ndarray            # indices with det J <= 0 somewhere
    degenerate: np.ndarray          # indices with zero volume or γ > DEGENERATE
    poor: np.ndarray                # indices with γ > the warning threshold


def _tet10_gradients(xi: np.ndarray) -> np.ndarray:
    """∇N_a(ξ) of the VTK tetra10 shape functions at one point: (10, 3)."""
    r, s, t = xi
    u = 1.0 - r - s - t
    L = np.array([u, r, s, t])
    dL = np.array([[-1, -1, -1], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    g = np.zeros((10, 3))
    for a in range(4):
        g[a] = (4 * L[a] - 1) * dL[a]
    for k, (a, b) in enumerate(((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))):
        g[4 + k] = 4 * (L[a] * dL[b] + L[b] * dL[a])
    return g


#: ∇N at every sample point side by side: (10, 3·len(_XI)), column 3p + b = ∂N/∂ξ_b at point p.
_GRADIENTS = np.concatenate([_tet10_gradients(xi) for xi in _XI], axis=1)


def _tet10_jacobians(x: np.ndarray) -> np.ndarray:
    """det J(ξ_p) of each tetra10 (coordinates ``x``: (m, 10, 3)) at every sample point: (m, len(_XI)).
    J_nb = Σ_a x_an ∂N_a/∂ξ_b for all points in one matrix product, the determinants by the triple
    product (the same numbers as ``np.linalg.det`` to round-off, a fraction of its time)."""
    m = len(x)
    J = (x.transpose(0, 2, 1).reshape(3 * m, 10) @ _GRADIENTS).reshape(m, 3, len(_XI), 3)
    a, b, c = J[:, :, :, 0], J[:, :, :, 1], J[:, :, :, 2]          # the columns ∂x/∂ξ_b, each (m, 3, p)
    return (a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1]) - a[:, 1] * (b[:, 0] * c[:, 2] - b[:, 2] * c[:, 0])
            + a[:, 2] * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0]))


_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))


def longest_edge(corners: np.ndarray) -> np.ndarray:
    """h_max of each tetrahedron from its corner coordinates ``corners`` (m, 4, 3)."""
    edges = np.stack([corners[:, b] - corners[:, a] for a, b in _EDGES], axis=1)
    return np.linalg.norm(edges, axis=2).max(axis=1)


def tet_quality(points: np.ndarray, cells: np.ndarray, max_aspect_ratio: float = 10.0) -> Quality:
    """Quality of tetrahedra (4 or 10 nodes, VTK order) with coordinates ``points``."""
    x = points[cells]                                   # (m, n, 3)
    c = x[:, :4]
    e1, e2, e3 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0], c[:, 3] - c[:, 0]
    six_v = np.einsum("ij,ij->i", np.cross(e1, e2), e3)
    h_max = longest_edge(c)
    area = sum(0.5 * np.linalg.norm(np.cross(c[:, j] - c[:, i], c[:, k] - c[:, i]), axis=1)
               for i, j, k in ((0, 1, 2), (0, 3, 1), (1, 3, 2), (2, 3, 0)))
    vol = np.abs(six_v) / 6.0
    with np.errstate(divide="ignore", invalid="ignore"):
        gamma = np.where(vol > 0, h_max * area / (6.0 * np.sqrt(6.0) * vol), np.inf)
        if cells.shape[1] == 10:
            dets = _tet10_jacobians(x)
            ratio = dets.min(axis=1) / six_v
            ratio = np.where(six_v > 0, ratio, np.minimum(dets.min(axis=1), 0.0) / np.abs(six_v))
        else:
            ratio = np.sign(six_v)
    scale = np.maximum(h_max, 1e-300) ** 3
    inverted = np.flatnonzero((ratio <= 0) & (np.abs(six_v) > 1e-12 * scale))
    degenerate = np.flatnonzero((np.abs(six_v) <= 1e-12 * scale) | (gamma > DEGENERATE))
    poor = np.flatnonzero((gamma > max_aspect_ratio) & (gamma <= DEGENERATE))
    return Quality(ratio, gamma, inverted, degenerate, poor)
