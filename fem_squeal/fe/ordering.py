"""Fill-reducing ordering of a serial sparse factorisation: METIS nested dissection (or, where METIS
cannot pay for itself, AMD) of the node graph.

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

from fem_squeal.util.native import address, first_library

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
    rc = lib.METIS_NodeND(ctypes.byref(ctypes.c_int32(n)), address(xadj), address(adjncy), None, opts,
                          address(perm), address(iperm))
    if rc != _METIS_OK or not is_permutation(perm):
        return None
    return perm.astype(np.int64)


def is_permutation(p: np.ndarray) -> bool:
    """``p`` holds each of 0 … len(p) − 1 once (what a library returned is an order to trust)."""
    n = len(p)
    return n == 0 or (p.min() >= 0 and p.max() < n and np.bincount(p, minlength=n).max() == 1)


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


# Where METIS pays for itself.  METIS_NodeND took 0.26, 0.31, 0.34 µs per node-graph entry (8.7k,
# 29k, 87k nodes of the clamped P2 disc); AMD (0.005 s at 8.7k nodes) predicts its own factorisation's
# flops exactly (1.94 GFlop at 26k DOFs, CHOLMOD counted 1.94).  METIS saved 29 % and 48 % of AMD's
# flops at 26k and 87k DOFs, so it runs where its time is below half of AMD's factorisation at the
# supernodal rate of one thread here (147 GFlop in 4.7 s at 260k DOFs).  Measured, order +
# factorisation + 13 block solves: 26k DOFs AMD 0.350 s, METIS 0.367 s (AMD chosen); 87k AMD
# 2.08 s, METIS 1.78 s (METIS chosen: 0.55 s of possible saving against 0.20 s of METIS).
METIS_SECONDS_PER_ENTRY = 0.3e-6
FACTOR_FLOPS_PER_SECOND = 30e9
ORDERINGS = ("auto", "metis", "amd")


@lru_cache(maxsize=1)
def _amd_lib() -> ctypes.CDLL | None:
    return first_library(("libamd.so.2",), "amd_order", search=("amd",))


def _amd(indptr: np.ndarray, indices: np.ndarray) -> tuple[np.ndarray, float] | None:
    """AMD's order of the symmetric graph and its predicted multiply-subtract count of an LDLᵀ
    factorisation (``Info[AMD_NMULTSUBS_LDL]``); None where libamd is missing or fails."""
    lib = _amd_lib()
    n = len(indptr) - 1
    if lib is None or n < 1 or indptr[-1] >= 2**31:
        return None
    ap = np.ascontiguousarray(indptr, dtype=np.int32)
    ai = np.ascontiguousarray(indices, dtype=np.int32)
    perm = np.full(n, -1, np.int32)
    control, info = (ctypes.c_double * 5)(), (ctypes.c_double * 20)()
    lib.amd_defaults(control)
    rc = lib.amd_order(ctypes.c_int32(n), address(ap), address(ai), address(perm), control, info)
    if rc not in (0, 1) or not is_permutation(perm):      # AMD_OK, AMD_OK_BUT_JUMBLED
        return None
    return perm.astype(np.int64), float(info[11])


def metis_pays(graph_entries: int, factor_flops: float) -> bool:
    """METIS's expected time (:data:`METIS_SECONDS_PER_ENTRY` per entry of the node graph) is below
    half of the factorisation AMD's order gives (``factor_flops`` at :data:`FACTOR_FLOPS_PER_SECOND`)."""
    return METIS_SECONDS_PER_ENTRY * graph_entries < 0.5 * factor_flops / FACTOR_FLOPS_PER_SECOND


def fill_reducing_order(A: PETSc.Mat, pattern: tuple[np.ndarray, np.ndarray] | None = None,
                        how: str = "auto") -> np.ndarray | None:
    """A fill-reducing row permutation p of the serial matrix ``A`` (new row i = old row p[i]) from
    its node graph (blocks of ``A.getBlockSize()`` rows; each node's rows kept together): ``how`` =
    "metis" (nested dissection), "amd" (approximate minimum degree) or "auto" (AMD, then METIS where
    :func:`metis_pays`: the factorisation of a b×b block graph costs 2b³ flops per multiply-subtract
    AMD counts).  ``pattern``: the CSR (indptr, indices) of the matrix to factorise where the caller
    has it (A's, or one with more entries, such as A − σM); else A's own.  None where it cannot be
    had (parallel matrix, no library): keep the solver's own."""
    if how not in ORDERINGS:
        raise ValueError(f"ordering: {how!r} is not one of {ORDERINGS}")
    if A.getComm().getSize() > 1:
        return None
    bs = node_block_size(A)
    return node_order(node_graph(A, bs, pattern), bs, how)


def node_block_size(A: PETSc.Mat) -> int:
    """Rows per node of ``A``: its block size where that divides its rows, else 1."""
    n, bs = A.getSize()[0], A.getBlockSize()
    return bs if bs > 0 and n % bs == 0 else 1


def node_order(graph: tuple[np.ndarray, np.ndarray], bs: int, how: str = "auto") -> np.ndarray | None:
    """:func:`fill_reducing_order` from a node graph (:func:`node_graph`'s CSR) of nodes of ``bs`` rows."""
    perm = None
    if how != "metis":
        amd = _amd(*graph)
        if amd is not None and (how == "amd" or not metis_pays(len(graph[1]), 2 * bs ** 3 * amd[1])):
            perm = amd[0]
    if perm is None and how != "amd" and metis_available():
        perm = _node_nd(*graph)
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
