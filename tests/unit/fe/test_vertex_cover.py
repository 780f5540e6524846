"""The interface of the substructured factorisation: a minimum vertex cover of a bipartite graph
(fem_squeal.fe.substructured.min_vertex_cover, König's construction) against brute force."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from fem_squeal.fe.substructured import min_vertex_cover


def _brute_force(G: np.ndarray) -> int:
    """The size of a smallest vertex cover, by trying every subset of the left side (the right side
    then needs every neighbour of an uncovered left vertex)."""
    nl = G.shape[0]
    best = nl + G.shape[1]
    for k in range(nl + 1):
        for left in itertools.combinations(range(nl), k):
            rest = [i for i in range(nl) if i not in left]
            need = np.flatnonzero(G[rest].any(axis=0)) if rest else []
            best = min(best, k + len(need))
    return best


@pytest.mark.parametrize("seed", range(12))
def test_cover_is_minimum_and_covers_every_edge(seed):
    rng = np.random.default_rng(seed)
    nl, nr = rng.integers(1, 8), rng.integers(1, 8)
    G = rng.random((nl, nr)) < rng.uniform(0.15, 0.6)
    left, right = min_vertex_cover(sp.csr_matrix(G.astype(np.int8)))
    rows, cols = np.nonzero(G)
    assert np.all(left[rows] | right[cols]), "an edge with neither end in the cover"
    assert left.sum() + right.sum() == _brute_force(G)


def test_a_band_graph_is_covered_by_one_side():
    """Two layers of nodes across a cut, each coupled to its neighbour and the next (a 1D picture of
    the rows on either side of a partition): a cover of the smaller side's size."""
    n = 40
    G = sp.diags([1, 1], [0, 1], shape=(n, n + 1), dtype=np.int8).tocsr()
    left, right = min_vertex_cover(G)
    assert left.sum() + right.sum() == n
