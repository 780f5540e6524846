"""Fill-reducing ordering of a serial sparse factorisation: METIS nested dissection of the node graph.

A vector P2 stiffness couples whole b×b blocks (b = 3 displacement components per node), so the
graph of its nodes has b² fewer edges than the graph of its rows.  METIS_NodeND on that node graph,
expanded to the rows node by node, orders K as well as CHOLMOD's own METIS on the full graph
(measured on the clamped P2 disc, 255k DOFs: 130.8M against 128.8M factor entries) at a fraction of
the analysis cost: CHOLMOD's default analysis tries AMD and then METIS on the row graph (2.0 s there),
this one takes 0.04 s for the graph and 0.7 s for METIS, plus 0.55 s to permute K and M; ordering,
permutation and factorisation took 7.5 s against 8.0 s for CHOLMOD's default path
(``benchmarks/modal_peers.py --speed``, 2026-11-27).

METIS is the ``libmetis.so.5`` that SuiteSparse's CHOLMOD itself links (Debian ``libmetis5``), called
through ctypes.  Any failure (no library, another index width, a result that is not a permutation)
gives None, and the caller keeps the factorisation's own ordering: an ordering only changes the fill,
never the solution.
"""
from __future__ import annotations

import ctypes
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from fem_squeal.util.native import first_library

_METIS_OK = 1
_METIS_NOPTIONS = 40


@lru_cache(maxsize=1)
def _metis() -> ctypes.CDLL | None:
    return first_library(("libmetis.so.5",), "METIS_NodeND", search=("metis",))


def metis_available() -> bool:
    return _metis() is not None


def _node_nd(indptr: np.ndarray, indices: np.ndarray) -> np.ndarray | None:
    """METIS_NodeND of the symmetric graph (CSR without self-loops): ``perm`` with new vertex i =
    old vertex perm[i]; None if METIS is missing or its answer is not a permutation (Debian's METIS
    has 32-bit indices: a 64-bit build would not give one)."""
    lib = _metis()
    n = len(indptr) - 1
    if lib is None or n < 2 or indptr[-1] >= 2**31:
        return None
    opts = (ctypes.c_int32 * _METIS_NOPTIONS)()
    lib.METIS_SetDefaultOptions(opts)
    xadj = np.ascontiguousarray(indptr, dtype=np.int32)
    adjncy = np.ascontiguousarray(indices, dtype=np.int32)
    perm, iperm = np.full(n, -1, np.int32), np.full(n, -1, np.int32)

    def ptr(a):
        return a.ctypes.data_as(ctypes.c_void_p)
    rc = lib.METIS_NodeND(ctypes.byref(ctypes.c_int32(n)), ptr(xadj), ptr(adjncy), None, opts,
                          ptr(perm), ptr(iperm))
    if rc != _METIS_OK or perm.min() < 0 or perm.max() >= n or np.bincount(perm, minlength=n).max() != 1:
        return None
    return perm.astype(np.int64)


def node_graph(A: PETSc.Mat, bs: int, pattern: tuple[np.ndarray, np.ndarray] | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """The symmetric graph of the nodes of the serial matrix ``A`` (rows b·i … b·i + b − 1 are node
    i), from the first row of each node, without self-loops, as CSR (indptr, indices).
    ``pattern``: A's CSR (indptr, indices) where the caller has it already (else MatGetRowIJ)."""
    ia, ja = pattern if pattern is not None else A.getRowIJ(symmetric=False, compressed=False)
    n = len(ia) - 1
    first = sp.csr_matrix((np.ones(len(ja), dtype=np.int8), ja, ia), shape=(n, n))[::bs]
    nn = first.shape[0]
    G = sp.csr_matrix((first.data, first.indices // bs, first.indptr), shape=(nn, nn))
    G = (G + G.T).tocsr()      # symmetric (K's pattern already is; METIS must see both directions)
    G.setdiag(0)
    G.eliminate_zeros()
    G.sort_indices()
    return G.indptr, G.indices


def nested_dissection(A: PETSc.Mat, pattern: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray | None:
    """A fill-reducing row permutation p of the serial matrix ``A`` (new row i = old row p[i]): METIS
    nested dissection of its node graph (blocks of ``A.getBlockSize()`` rows), each node's rows kept
    together.  ``pattern``: the CSR (indptr, indices) of the matrix to factorise where the caller has
    it (A's, or one with more entries, such as A − σM); else A's own.  None where it cannot be had
    (parallel matrix, no METIS): keep the solver's own."""
    if A.getComm().getSize() > 1 or not metis_available():
        return None
    n = A.getSize()[0]
    bs = A.getBlockSize() if A.getBlockSize() > 0 and n % A.getBlockSize() == 0 else 1
    perm = _node_nd(*node_graph(A, bs, pattern))
    if perm is None:
        return None
    return (bs * perm[:, None] + np.arange(bs)).ravel()


def permuted(A: PETSc.Mat, p: np.ndarray) -> PETSc.Mat:
    """P A Pᵀ: the matrix with entry (i, j) = A(p[i], p[j]); its symmetry flag kept."""
    isp = PETSc.IS().createGeneral(p.astype(PETSc.IntType), comm=A.getComm())
    try:
        B = A.permute(isp, isp)
    finally:
        isp.destroy()
    known, symmetric = A.isSymmetricKnown()
    if known:
        B.setOption(PETSc.Mat.Option.SYMMETRIC, symmetric)
    return B
