"""A sparse Cholesky factorisation on N ranks by substructuring: every rank's interior factorised by
CHOLMOD at once, the interface by the dense Schur complement.

A symmetric positive definite A (K − σM, rows distributed as PETSc distributes them) is split by a
vertex separator Γ: rows of different ranks' interiors I_r are never coupled, so

    A = [A_II  A_IΓ]     (A_II block diagonal over the ranks),    S = A_ΓΓ − Σ_r A_ΓI_r A_I_rI_r⁻¹ A_I_rΓ.
        [A_ΓI  A_ΓΓ]

Rank r factorises A_r = [A_I_rI_r  A_I_rΓ; A_ΓI_r  A_ΓΓ] (a principal submatrix of A, so positive
definite) with Γ ordered last, L_r = [L₁₁ 0; L₂₁ L₂₂]: L₂₁L₂₁ᵀ = A_ΓI_r A_I_rI_r⁻¹ A_I_rΓ = A_ΓΓ − L₂₂L₂₂ᵀ,
so S = A_ΓΓ − Σ_r (A_ΓΓ − L₂₂L₂₂ᵀ)_r, factorised densely once.  A solve A x = b is a forward sweep
of each rank's interior (y = L₁₁⁻¹b_I; the interface rows become −L₂₁y), one sum over the ranks
g = b_Γ − Σ_r L₂₁y, x_Γ = S⁻¹g, and a backward sweep x_I = L₁₁⁻ᵀ(y − L₂₁ᵀx_Γ)
(:meth:`fem_squeal.fe.cholmod.Cholesky.sweep`, the compiled block solve stopped at the interface).

Γ: for each pair of ranks q < r, a minimum vertex cover of the bipartite graph of q's nodes coupled
to r's nodes (König: from a maximum matching), so every coupling between two ranks has an end in Γ;
on the clamped P2 disc of 87k DOFs on 2 ranks it holds 843 rows where "every row of rank 0 coupled
to rank 1" holds 1896 (the dense work goes with the cube).  Nodes (``bs`` rows) stay
whole.  This is MUMPS' tree parallelism done with the serial factorisation that is fastest here
(CHOLMOD on a METIS order, :mod:`fem_squeal.fe.ordering`), and the block solves the real-mode
Lanczos needs on every rank's rows; MUMPS on 2 ranks was slower than CHOLMOD on one (issue 34).
"""
from __future__ import annotations

import ctypes
import time
from functools import lru_cache

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from mpi4py import MPI
from scipy.sparse.csgraph import maximum_bipartite_matching

from fem_squeal.fe import kernels
from fem_squeal.fe.cholmod import WMAX, Cholesky, NotPositiveDefinite, aligned_rows
from fem_squeal.fe.csr import find_sorted
from fem_squeal.fe.ordering import node_graph, node_order
from fem_squeal.util.native import address

# The dense interface: S is n_Γ × n_Γ on every rank (8 n_Γ² bytes) and its factorisation n_Γ³/3
# flops; past this many rows the caller keeps MUMPS (an interface of 8000 rows: 0.5 GB, ~25 s).
MAX_INTERFACE = 8000


class Unavailable(RuntimeError):
    """The substructured factorisation does not apply here (the caller keeps another solver)."""


def min_vertex_cover(G: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """A minimum vertex cover of the bipartite graph with biadjacency ``G`` (left = rows, right =
    columns) as two boolean masks: König's construction from a maximum matching (Z: the vertices
    reached from unmatched left vertices by alternating paths; cover = (left ∖ Z) ∪ (right ∩ Z))."""
    G = sp.csr_matrix(G)
    nl, nr = G.shape
    row_match = maximum_bipartite_matching(G, perm_type="column")      # left i -> right j, or −1
    col_match = np.full(nr, -1)
    col_match[row_match[row_match >= 0]] = np.flatnonzero(row_match >= 0)
    seen_l, seen_r = row_match < 0, np.zeros(nr, bool)
    front = seen_l.copy()
    GT = G.T.tocsr()
    while front.any():
        right = (GT @ front.astype(np.int8)) > 0
        right &= ~seen_r
        seen_r |= right
        left = np.zeros(nl, bool)
        m = col_match[right]
        left[m[m >= 0]] = True      # right vertices reached are matched (else the matching would grow)
        left &= ~seen_l
        seen_l |= left
        front = left
    return ~seen_l, seen_r


def interface_nodes(A_rows: sp.csr_matrix, ranges: np.ndarray, bs: int, comm: MPI.Comm) -> np.ndarray:
    """The global numbers of this rank's nodes in the separator Γ (sorted): for each other rank q,
    this rank's side of a minimum vertex cover of the nodes coupled across (computed by the lower
    rank of each pair and sent to the higher).  ``A_rows``: this rank's rows, global columns."""
    r = comm.rank
    first = ranges[r] // bs
    cols = A_rows.indices
    cross = (cols < ranges[r]) | (cols >= ranges[r + 1])           # the entries coupling to other ranks
    rows = np.repeat(np.arange(A_rows.shape[0]) // bs, np.diff(A_rows.indptr))[cross]
    cols = cols[cross]
    owner = np.searchsorted(ranges, cols, side="right") - 1
    mine, send = [], [np.zeros(0, np.int64) for _ in range(comm.size)]
    for q in range(r + 1, comm.size):
        sel = owner == q
        if not sel.any():
            continue
        a, ia = np.unique(rows[sel], return_inverse=True)
        b, ib = np.unique(cols[sel] // bs, return_inverse=True)
        G = sp.csr_matrix((np.ones(len(ia), np.int8), (ia, ib)), shape=(len(a), len(b)))
        G.data[:] = 1
        left, right = min_vertex_cover(G)
        mine.append(first + a[left])
        send[q] = b[right].astype(np.int64)
    got = comm.alltoall(send)
    return np.unique(np.concatenate([np.zeros(0, np.int64), *mine, *got])).astype(np.int64)


def _lower_gram(L: np.ndarray) -> np.ndarray:
    """The lower triangle of L Lᵀ (L lower triangular; the strict upper triangle returned is zero), in
    s³/3 flops: with J the reversal, U = JLJ is upper triangular and L Lᵀ = J (U Uᵀ) J, which LAPACK's
    dlauum forms in place (its upper triangle; U's strict lower triangle is zero and stays so).  A
    reversed view: no copy back (a 5628-row interface is 253 MB a copy)."""
    if L.size == 0:
        return np.zeros_like(L)
    G, info = sla.lapack.dlauum(np.asfortranarray(L[::-1, ::-1]), lower=0, overwrite_c=1)
    if info:
        raise RuntimeError(f"dlauum failed (info {info})")
    return G[::-1, ::-1]


def _local_matrix(A_rows: sp.csr_matrix, r0: int, r1: int, local: np.ndarray, gamma: np.ndarray, n_i: int,
                  interior: np.ndarray, own_gamma: np.ndarray, comm: MPI.Comm, compiled: bool = True):
    """This rank's local matrix [A_II A_IΓ; · A_ΓΓ] as CSR (indptr, indices: int32, data; CHOLMOD reads the
    upper triangle, rows need not be sorted), the A_II pattern (inner_ptr, inner_idx: the fill-reducing
    order's graph) and A_ΓΓ dense (its lower triangle, the upper one zero; from the ranks' interface
    rows).  ``local``: each owned row's local number (interior 0 … n_i − 1, Γ n_i …); other ranks'
    columns through Γ (``gamma``, sorted global rows).  The compiled kernel ``substructure`` writes
    the interior rows straight into the arrays CHOLMOD reads (255k-DOF disc, 2 ranks, in a fresh
    process: NumPy's pieces and their concatenation took 0.5–0.7 s of the set-up); NumPy where it is
    not built, or ``compiled=False`` (the reference of its test): the same arrays.  Collective."""
    lib = _split_lib() if compiled else None
    if compiled:                      # the reference call of the test is not a path that ran
        kernels.note("interface", "numpy" if lib is None else "compiled")
    s = len(gamma)
    if lib is None:
        top_ptr, top_idx, top_val, inner_ptr, inner_idx, trip, bad = _split_numpy(
            A_rows, r0, r1, local, gamma, n_i, interior, own_gamma)
    else:
        indptr64 = np.ascontiguousarray(A_rows.indptr, dtype=np.int64)
        cols = np.ascontiguousarray(A_rows.indices, dtype=np.int32)
        vals = np.ascontiguousarray(A_rows.data, dtype=np.float64)
        local, gamma, interior, own_gamma = (np.ascontiguousarray(a, dtype=np.int64)
                                             for a in (local, gamma, interior, own_gamma))
        common = (*(address(a) for a in (indptr64, cols, vals, local, gamma)), s, n_i)
        counts = np.diff(indptr64)
        n_gg = int(counts[own_gamma].sum())
        trip = (np.empty(n_gg, np.int64), np.empty(n_gg, np.int64), np.empty(n_gg))
        g = lib.substructure_gamma(r0, r1, *common, address(own_gamma), len(own_gamma), *map(address, trip))
        trip = tuple(a[:g] for a in trip)
    allr, allc, allv = (np.concatenate(x) for x in zip(*comm.allgather(trip)))
    upper = allc >= allr                                   # A_ΓΓ from its upper triangle (CHOLMOD's)
    gg = sp.csr_matrix((allv[upper], (allr[upper], allc[upper])), shape=(s, s))
    A_gg = gg.T.toarray()                                  # dense: its lower triangle only
    if lib is None:
        indptr = np.concatenate([top_ptr, top_ptr[-1] + gg.indptr[1:]]).astype(np.int32)
        indices = np.concatenate([top_idx, n_i + gg.indices]).astype(np.int32)
        data = np.concatenate([top_val, gg.data])
    else:
        n_top = int(counts[interior].sum())
        indptr = np.empty(n_i + s + 1, np.int32)
        indices, data = np.empty(n_top + gg.nnz, np.int32), np.empty(n_top + gg.nnz)
        inner_ptr, inner_idx, got = np.empty(n_i + 1, np.int64), np.empty(n_top, np.int64), np.zeros(1, np.int64)
        bad = lib.substructure_interior(r0, r1, *common, address(interior), address(indptr), address(indices),
                                        address(data), address(inner_ptr), address(inner_idx), address(got))
        inner_idx = inner_idx[:int(got[0])]
        indptr[n_i + 1:] = n_top + gg.indptr[1:]
        indices[n_top:] = n_i + gg.indices
        data[n_top:] = gg.data
    if comm.allreduce(bool(bad), op=MPI.LOR):        # not a separator: a defect here
        raise RuntimeError("substructured Cholesky: an interior row couples to another rank's interior")
    return indptr, indices, data, inner_ptr, inner_idx, A_gg


@lru_cache(maxsize=1)
def _split_lib() -> ctypes.CDLL | None:
    """The compiled kernel ``substructure`` (fem_squeal/fe/kernels/substructure.c), or None."""
    lib = kernels.library("substructure")
    if lib is None:
        return None
    i64, p = ctypes.c_int64, ctypes.c_void_p
    common = [i64, i64, p, p, p, p, p, i64, i64]
    lib.substructure_gamma.argtypes = common + [p, i64, p, p, p]
    lib.substructure_gamma.restype = ctypes.c_int64
    lib.substructure_interior.argtypes = common + [p, p, p, p, p, p, p]
    lib.substructure_interior.restype = ctypes.c_int
    return lib


def _split_numpy(A_rows: sp.csr_matrix, r0: int, r1: int, local: np.ndarray, gamma: np.ndarray, n_i: int,
                 interior: np.ndarray, own_gamma: np.ndarray):
    """The pieces of :func:`_local_matrix` in NumPy: the interior rows' CSR in the local numbering
    (top_ptr, top_idx, top_val), their A_II pattern, the A_ΓΓ triplets of the interface rows, and
    whether an interior row couples to another rank's interior."""
    n_own = A_rows.shape[0]
    cols = A_rows.indices.astype(np.int64)
    owned = (cols >= r0) & (cols < r1)
    where = np.empty(len(cols), np.int64)
    where[owned] = local[cols[owned] - r0]
    pos, hit = find_sorted(gamma, cols[~owned])
    where[~owned] = np.where(hit, n_i + pos, -1)
    counts_row = np.diff(A_rows.indptr)
    in_row = np.zeros(n_own, np.int8)               # 1: interior row, 2: interface row
    in_row[interior], in_row[own_gamma] = 1, 2
    kind = np.repeat(in_row, counts_row)
    m = kind == 1                                   # [A_II A_IΓ]: interior rows in order
    top_idx, top_val = where[m], A_rows.data[m]
    bad = bool(np.any(top_idx < 0))
    top_ptr = np.zeros(n_i + 1, np.int64)
    np.cumsum(counts_row[interior], out=top_ptr[1:])
    g = (kind == 2) & (where >= n_i)                # A_ΓΓ entries of this rank's interface rows
    g_row = np.repeat(local, counts_row)[g] - n_i
    trip = (g_row, where[g] - n_i, A_rows.data[g])
    inner = top_idx < n_i
    inner_ptr = np.zeros(n_i + 1, np.int64)
    np.cumsum(np.bincount(np.repeat(np.arange(n_i), counts_row[interior])[inner], minlength=n_i),
              out=inner_ptr[1:])
    inner_idx = top_idx[inner]
    return top_ptr, top_idx, top_val, inner_ptr, inner_idx, trip, bad


class SubstructuredCholesky:
    """A = L Lᵀ of a symmetric positive definite matrix distributed over ``comm`` by rows
    (``A_rows``: this rank's rows ``ranges[rank]`` … with global column numbers, both triangles;
    ``bs`` rows per node), substructured as the module says.  :meth:`solve` takes and returns this
    rank's rows of column blocks.  Collective: every rank raises :class:`NotPositiveDefinite` if any
    factorisation meets a non-positive pivot, :class:`Unavailable` where the path does not apply
    (the compiled block solve missing, an interface past :data:`MAX_INTERFACE` rows).
    ``seconds``: interface, local factorisation, Schur complement; ``interface_rows``: n_Γ."""

    def __init__(self, A_rows: sp.csr_matrix, ranges: np.ndarray, bs: int, comm: MPI.Comm) -> None:
        t0 = time.perf_counter()
        self.comm = comm
        r, ranges = comm.rank, np.asarray(ranges, np.int64)
        n_own = int(ranges[r + 1] - ranges[r])
        A_rows = sp.csr_matrix(A_rows)
        if A_rows.shape[0] != n_own:
            raise ValueError(f"substructured Cholesky: {A_rows.shape[0]} rows given, the rank owns {n_own}")
        if np.any(ranges % bs):
            raise Unavailable(f"the ranks' row ranges are not whole nodes of {bs} rows")
        gnodes = interface_nodes(A_rows, ranges, bs, comm)
        own_gamma = ((gnodes[:, None] * bs + np.arange(bs)).ravel() - ranges[r]).astype(np.int64)
        counts = comm.allgather(len(own_gamma))
        gamma = np.concatenate(comm.allgather(own_gamma + ranges[r]))      # sorted: ranks in order
        s = len(gamma)
        if s > MAX_INTERFACE:
            raise Unavailable(f"an interface of {s} rows (more than {MAX_INTERFACE})")
        interior = np.setdiff1d(np.arange(n_own), own_gamma)
        n_i = len(interior)
        self._own_gamma, self._gamma_pos = own_gamma, int(sum(counts[:r])) + np.arange(len(own_gamma))
        # columns in the local numbering: interior 0 … n_i − 1, then Γ n_i … n_i + s − 1
        local = np.full(n_own, -1, np.int64)
        local[interior] = np.arange(n_i)
        local[own_gamma] = n_i + self._gamma_pos
        indptr, indices, data, inner_ptr, inner_idx, A_gg = _local_matrix(
            A_rows, ranges[r], ranges[r + 1], local, gamma, n_i, interior, own_gamma, comm)
        t1 = time.perf_counter()
        perm_i = node_order(node_graph(None, bs, (inner_ptr, inner_idx)), bs) if n_i else None
        if perm_i is None:
            perm_i = np.arange(n_i)
        perm = np.concatenate([perm_i, n_i + np.arange(s)]).astype(np.int64)
        factor, code = None, 0
        try:
            factor = Cholesky(indptr, indices, data, perm, keep_order=True)
            if not (factor.can_sweep() and np.array_equal(factor.supernodes()[5], perm)):
                code = 1
        except NotPositiveDefinite:
            code = 2
        except MemoryError:
            code = 3
        code = comm.allreduce(code, op=MPI.MAX)
        if code:
            if factor is not None:
                factor.close()
            if code == 3:
                raise MemoryError("substructured CHOLMOD: out of memory on a rank")
            if code == 2:
                raise NotPositiveDefinite("substructured CHOLMOD: the matrix is not positive definite")
            raise Unavailable("the compiled block solve does not apply to the local factor")
        t2 = time.perf_counter()
        # lower triangles throughout (the upper ones are zero and not read): this rank's L₂₁L₂₁ᵀ =
        # A_ΓΓ − L₂₂L₂₂ᵀ (its factor's trailing block), summed over the ranks, S = A_ΓΓ − Σ L₂₁L₂₁ᵀ
        C = np.subtract(A_gg, _lower_gram(factor.trailing_block(n_i)))
        comm.Allreduce(MPI.IN_PLACE, C, op=MPI.SUM)
        np.subtract(A_gg, C, out=C)
        del A_gg
        Rs, ok = None, True
        if s:
            try:
                # S's lower triangle is the upper one of C's Fortran-order transpose: potrf('U') in
                # place on it, S = RᵀR with R upper triangular (Fortran order, as potrs takes it)
                Rs = sla.cholesky(C.T, lower=False, overwrite_a=True, check_finite=False)
            except np.linalg.LinAlgError:
                ok = False
        if not comm.allreduce(ok, op=MPI.LAND):
            factor.close()
            raise NotPositiveDefinite("substructured CHOLMOD: the interface's Schur complement is not "
                                      "positive definite")
        self._S = Rs
        self._factor, self._n_i, self._s = factor, n_i, s
        self._order = interior[perm_i]                 # factor row i < n_i is this rank's row _order[i]
        self._work: dict[int, np.ndarray] = {}
        self.n = n_own
        self.interface_rows = s
        self.seconds = {"interface": t1 - t0, "factor": t2 - t1, "schur": time.perf_counter() - t2}

    def solve(self, B: np.ndarray) -> np.ndarray:
        """A⁻¹B for this rank's rows B (n or n × k); collective."""
        B = np.asarray(B, dtype=np.float64)
        vec = B.ndim == 1
        B2 = B.reshape(self.n, -1, order="F")
        k = B2.shape[1]
        X = np.empty((self.n, k), order="F")
        n_i, order, gp, og = self._n_i, self._order, self._gamma_pos, self._own_gamma
        kernels.note("block_solve", "compiled sweeps, substructured")
        for j0 in range(0, k, WMAX):
            m = min(WMAX, k - j0)
            w = 8 if m <= 8 else WMAX
            Y = self._work.get(w)
            if Y is None:
                Y = self._work[w] = aligned_rows(n_i + self._s, w)
            Y[:n_i, :m] = B2[order, j0:j0 + m]
            Y[:n_i, m:] = 0.0                                 # padding columns (independent of the others)
            Y[n_i:] = 0.0                                     # b_Γ enters after the forward sweep
            self._factor.sweep(Y, n_i, back=False)           # Y₂ = −L₂₁ L₁₁⁻¹ b_I
            g = np.ascontiguousarray(Y[n_i:, :m])
            g[gp] += B2[og, j0:j0 + m]
            self.comm.Allreduce(MPI.IN_PLACE, g, op=MPI.SUM)
            xg = sla.cho_solve((self._S, False), g, check_finite=False) if self._s else g
            Y[n_i:, :m] = xg
            self._factor.sweep(Y, n_i, back=True)
            X[order, j0:j0 + m] = Y[:n_i, :m]
            X[og, j0:j0 + m] = xg[gp]
        return X[:, 0] if vec else X

    def close(self) -> None:
        """Free the local factor (idempotent)."""
        f = getattr(self, "_factor", None)
        if f is not None:
            f.close()
            self._factor = None

    def __enter__(self) -> SubstructuredCholesky:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
