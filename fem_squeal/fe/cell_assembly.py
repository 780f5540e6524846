"""Serial matrices written row by row, without PETSc's per-entry search: cell-integral forms and
the Kronecker expansion of a scalar matrix.

dolfinx assembles a matrix by handing each element matrix to PETSc's ``MatSetValuesBlockedLocal``,
which on an AIJ matrix expands the blocks and searches every one of the element's (b·n)² entries
in its row.  On the clamped P2 disc (255k DOFs, 52k cells, 900 entries per cell) that insertion
took twice the time of the element kernels themselves (``perf``: 0.8 of 1.25 s).  Here
(:func:`assemble_matrix`) the pattern is written once, each row as a whole (``MAT_SORTED_FULL``:
a copy per row), and the FFCx kernel is called from a small C loop that finds each of the n² node
pairs once (a binary search in the node row) and adds the b × b block at its place in PETSc's value
array: the same additions in the same order as dolfinx's, so the matrix is the same to the last
bit (K at 255k DOFs: 0.7 s against 1.3 s).  :func:`kronecker` writes M_s ⊗ W the same way (the
vector masses from the scalar one).

What :func:`assemble_matrix` covers: a form whose integrals are all cell integrals without
coefficients (constants are fine: the material values), the same space for the test and trial
functions, and an element without DOF transformations (Lagrange).  Anything else, or a machine where
the C loops cannot be built, gives None and the caller assembles with dolfinx.  On N ranks the same
loop fills each rank's local rows (owned and ghost nodes) in a NumPy array; the ghost rows go to
their owners in one all-to-all, and each owned row, merged with them, is written whole into PETSc's
diagonal and off-diagonal parts of an exactly preallocated matrix (:func:`owned_rows_matrix`): no
sparsity pattern built apart and no search per entry (the 348k-DOF brake's ten matrices on 2 ranks:
dolfinx's ``create_matrix`` and ``MatSetValuesBlockedLocal`` of every node row took 2.3 s of the
operators' 7 s).  :func:`kronecker_rows` expands a parallel scalar matrix.

The C loops (``fem_squeal/fe/kernels/cell_assembly.c``) are built with the package
(:mod:`fem_squeal.fe.kernels`) and called through ctypes, with PETSc's ``MatSetValues`` and the FFCx
kernel passed in by address.
"""
from __future__ import annotations

import contextlib
import ctypes
from functools import lru_cache

import cffi
import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from dolfinx.fem.assemble import pack_constants
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe import kernels
from fem_squeal.fe.csr import csr_values, csr_view, petsc_library
from fem_squeal.util.native import address


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL | None:
    """The compiled C loops (built with the package); None where they were not built."""
    lib = kernels.library("cell_assembly")
    if lib is None:
        return None
    p = ctypes.c_void_p
    i32 = ctypes.c_int32
    lib.assemble_cells.argtypes = [p, i32, p, p, i32, i32, p, p, i32, p, p, p, p, p, p, p, p, p]
    lib.assemble_cells.restype = ctypes.c_int
    lib.fill_pattern.argtypes = [p, p, i32, i32, p, p, p, p]
    lib.fill_pattern.restype = ctypes.c_int
    lib.merge_rows.argtypes = [i32, i32, ctypes.c_int64, ctypes.c_int64] + [p] * 14
    lib.merge_rows.restype = ctypes.c_int
    lib.kronecker_rows.argtypes = [i32, i32, i32, p, p, p, p, p]
    lib.kronecker_rows.restype = None
    lib.fill_kronecker.argtypes = [p, p, i32, i32, p, p, p, p, p, p, p]
    lib.fill_kronecker.restype = ctypes.c_int
    lib.kronecker_csr.argtypes = [i32, i32, i32, p, p, p, p, p, p, p, p]
    lib.kronecker_csr.restype = None
    return lib


@lru_cache(maxsize=1)
def _ffi() -> cffi.FFI:
    """cffi's public FFI, for the address of an FFCx kernel (a cdata function pointer); built once."""
    return cffi.FFI()


def _set_values(name: str = "MatSetValues") -> ctypes.c_void_p:
    """The address of PETSc's ``MatSetValues`` (or another function of its signature, ``name``) in
    the library petsc4py links."""
    return ctypes.cast(getattr(petsc_library(), name), ctypes.c_void_p)


def node_pattern(dofmap: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """The node graph of the cells (``dofmap``: cells × nodes): node i couples to node j when a cell
    has both; CSR with sorted columns (entries are the number of shared cells)."""
    cells, n = dofmap.shape
    C = sp.csr_matrix((np.ones(cells * n, dtype=np.int32), dofmap.ravel(), np.arange(0, cells * n + 1, n)),
                      shape=(cells, n_nodes))
    G = (C.T @ C).tocsr()
    G.sort_indices()
    return G


def _native() -> ctypes.CDLL | None:
    """The compiled loops where they apply: 32-bit PETSc indices, PETSc's library at hand."""
    if np.dtype(PETSc.IntType) != np.int32 or petsc_library() is None:
        return None
    return _library()


def _applies(form: fem.FormMetaClass) -> bool:
    V0, V1 = form.function_spaces
    types = set(form.integral_types)
    return (V0 is V1 and types <= {fem.IntegralType.cell} and form.ufcx_form.num_coefficients == 0
            and not V0.element.needs_dof_transformations and _native() is not None)


def _write_rows(M: PETSc.Mat, fill) -> None:
    """Run ``fill(set_values, mat)``, a compiled loop that hands M its preallocated rows whole and in
    order to MatSetValues, with MAT_SORTED_FULL on (a copy per row, no search) and off again
    afterwards (later insertions search as usual); then assemble M."""
    M.setOption(PETSc.Mat.Option.SORTED_FULL, True)
    rc = fill(_set_values(), ctypes.c_void_p(M.handle))
    M.setOption(PETSc.Mat.Option.SORTED_FULL, False)
    if rc != 0:
        raise RuntimeError(f"cell_assembly: MatSetValues returned {rc}")
    M.assemble()


def assemble_matrix(form: fem.FormMetaClass, bc_dofs: np.ndarray, diagonal: float) -> PETSc.Mat | None:
    """The matrix of the bilinear ``form`` as a PETSc AIJ matrix, with the rows and columns of the
    unrolled DOFs ``bc_dofs`` (local: owned and ghost) zero and ``diagonal`` on their diagonal: the
    matrix dolfinx's ``create_matrix`` + ``assemble_matrix(A, form, bcs, diagonal)`` gives, with its
    block size and local-to-global map.  On one rank bit for bit; on N ranks each rank adds its
    cells into its local rows (owned and ghost nodes), and :func:`owned_rows_matrix` sums the ghost
    rows into their owners' (so a row shared by ranks sums in another order than dolfinx's, within
    a few ε).  None where this path does not apply (see the module docstring)."""
    if not _applies(form):
        return None
    V = form.function_spaces[0]
    mesh = V.mesh
    b = V.dofmap.index_map_bs
    imap = V.dofmap.index_map
    n_nodes = imap.size_local + imap.num_ghosts
    cell_nodes = V.dofmap.list() if callable(V.dofmap.list) else V.dofmap.list    # the C++ or Python object
    dofs = cell_nodes.array.reshape(-1, V.dofmap.dof_layout.num_dofs)
    n = dofs.shape[1]
    uf = form.ufcx_form
    domains = [np.asarray(form.domains(fem.IntegralType.cell, uf.integral_ids(0)[i]), dtype=np.int32)
               for i in range(uf.num_integrals(0))]
    # dolfinx's pattern of a form: the cells of its integrals
    G = node_pattern(dofs[np.unique(np.concatenate(domains))] if domains else dofs[:0], n_nodes)
    # DOF rows: b per node, each with b columns per node column
    length = np.repeat(np.diff(G.indptr) * b, b)
    row_ptr = np.zeros(b * n_nodes + 1, dtype=np.int64)
    np.cumsum(length, out=row_ptr[1:])
    node_ptr = G.indptr.astype(np.int64)
    node_col = G.indices.astype(np.int32)
    # the diagonal entry of Dirichlet row r = b·k + i: node k's own column, component i (owned rows:
    # a ghost row's owner sets it; a ghost node of ghost cells only has no local row at all)
    rows_bc = np.unique(np.asarray(bc_dofs, dtype=np.int64))
    own = np.full(n_nodes, -1, dtype=np.int64)
    at = np.flatnonzero(G.indices == np.repeat(np.arange(n_nodes), np.diff(G.indptr)))
    own[G.indices[at]] = at - G.indptr[G.indices[at]]
    owned = rows_bc < b * imap.size_local
    if np.any(own[rows_bc[owned] // b] < 0):
        return None               # a Dirichlet DOF outside the form's cells: dolfinx's error, not ours
    rows_bc = rows_bc[owned]
    diagonal_at = row_ptr[rows_bc] + b * own[rows_bc // b] + rows_bc % b
    lib = _library()
    serial = mesh.comm.size == 1
    if serial:
        M = PETSc.Mat().createAIJ((b * imap.size_local, b * imap.size_global), bsize=b, comm=mesh.comm,
                                  nnz=length.astype(PETSc.IntType))
        longest = int(length.max(initial=0))
        cols, zeros = np.empty(longest, dtype=np.int32), np.zeros(longest)
        _write_rows(M, lambda set_values, mat: lib.fill_pattern(
            set_values, mat, n_nodes, b, address(node_ptr), address(node_col), address(cols), address(zeros)))
    bc = np.zeros(b * n_nodes, dtype=np.int8)
    bc[np.asarray(bc_dofs, dtype=np.int64)] = 1
    geo = mesh.geometry
    x = np.ascontiguousarray(geo.x, dtype=np.float64)
    xdofs = geo.dofmap.array.reshape(len(geo.dofmap.offsets) - 1, -1).astype(np.int32)
    nx = xdofs.shape[1]
    constants = np.ascontiguousarray(pack_constants(form), dtype=np.float64)
    dofs32 = np.ascontiguousarray(dofs, dtype=np.int32)
    A = np.empty((n * b) ** 2)
    coords = np.empty(3 * nx)
    pos = np.empty(n, dtype=np.int64)
    with csr_values(M) if serial else contextlib.nullcontext(np.zeros(int(row_ptr[-1]))) as val:
        for i, cells in enumerate(domains):
            kernel = ctypes.c_void_p(int(_ffi().cast("uintptr_t", uf.integrals(0)[i].tabulate_tensor_float64)))
            rc = lib.assemble_cells(kernel, len(cells), address(cells), address(dofs32), n, b, address(x),
                                    address(xdofs), nx, address(constants), address(node_ptr),
                                    address(node_col), address(row_ptr), address(bc), address(A),
                                    address(coords), address(pos), address(val))
            if rc != 0:
                raise RuntimeError("cell_assembly: a node pair of a cell is missing from the pattern")
        val[diagonal_at] = diagonal
        if not serial:
            M = owned_rows_matrix(mesh.comm, imap, b, node_ptr, node_col, row_ptr, val)
    lg = PETSc.LGMap().create(imap.local_to_global(np.arange(n_nodes, dtype=np.int32)).astype(PETSc.IntType),
                              bsize=b, comm=mesh.comm)
    M.setLGMap(lg, lg)
    M.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    return M


def owned_rows_matrix(comm: MPI.Comm, imap, b: int, node_ptr: np.ndarray, node_col: np.ndarray,
                      row_ptr: np.ndarray, val: np.ndarray) -> PETSc.Mat:
    """The parallel AIJ matrix (block size ``b``, rows and columns laid out by ``imap``) of the
    cells each rank assembled into its local node rows (owned, then ghost nodes of ``imap``;
    ``node_ptr``/``node_col`` the node pattern with local columns, ``row_ptr``/``val`` the DOF rows
    of :func:`assemble_matrix`).  Every ghost node row goes to its owner (one all-to-all) and is
    added there to the owner's own row, the owner's part first, then the other ranks' in rank order
    (A_ij = Σ_r A_ij^(r), the sum dolfinx's stash forms at the assembly).  The merged rows are
    counted, the matrix preallocated exactly, and each row written whole into PETSc's diagonal and
    off-diagonal parts (the C loop ``merge_rows``): no sparsity pattern built apart, no per-entry
    search."""
    lib, petsc = _library(), petsc_library()
    n_own, n_nodes = imap.size_local, len(node_ptr) - 1
    lo, hi = imap.local_range
    l2g = imap.local_to_global(np.arange(n_nodes, dtype=np.int32)).astype(np.int64)
    gcol = l2g[node_col]
    # the ghost rows, grouped by owner: global row and length, columns, values (DOF rows' layout)
    owners = np.asarray(imap.owners, dtype=np.int64)
    order = np.argsort(owners, kind="stable") + n_own
    lens = (node_ptr[order + 1] - node_ptr[order]).astype(np.int64)
    per_rank = np.bincount(owners, minlength=comm.size)
    entries = np.bincount(owners[order - n_own], weights=lens, minlength=comm.size).astype(np.int64)
    rows = _exchange(comm, np.stack([l2g[order], lens], axis=1).ravel(), 2 * per_rank).reshape(-1, 2)
    recv_col = _exchange(comm, gcol[_ranges(node_ptr[order], lens)], entries)
    recv_val = _exchange(comm, val[_ranges(row_ptr[b * order], b * b * lens)], b * b * entries)
    recv_ptr = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(rows[:, 1], out=recv_ptr[1:])
    target = rows[:, 0] - lo
    in_rows = np.argsort(target, kind="stable").astype(np.int32)     # by node, each in rank order
    in_ptr = np.zeros(n_own + 1, dtype=np.int64)
    np.cumsum(np.bincount(target, minlength=n_own), out=in_ptr[1:])
    n_diag, n_off = np.empty(n_own, dtype=np.int32), np.empty(n_own, dtype=np.int32)
    args = [n_own, b, lo, hi] + [address(a) for a in (node_ptr, gcol, row_ptr, val, in_ptr, in_rows, recv_ptr,
                                                      recv_col, recv_val, n_diag, n_off)]
    if lib.merge_rows(*args, None, None, None) != 0:
        raise MemoryError("cell_assembly.merge_rows: no memory for a row's scratch")
    size = (b * n_own, b * imap.size_global)
    M = PETSc.Mat().createAIJ((size, size), bsize=b, comm=comm,
                              nnz=tuple(np.repeat(b * n, b).astype(PETSc.IntType) for n in (n_diag, n_off)))
    diag, off = ctypes.c_void_p(), ctypes.c_void_p()
    garray = ctypes.POINTER(ctypes.c_int32)()
    if petsc.MatMPIAIJGetSeqAIJ(ctypes.c_void_p(M.handle), ctypes.byref(diag), ctypes.byref(off),
                                ctypes.byref(garray)) != 0:
        raise RuntimeError("cell_assembly: MatMPIAIJGetSeqAIJ failed")
    sorted_full = int(PETSc.Mat.Option.SORTED_FULL)
    for part in (diag, off):
        petsc.MatSetOption(part, sorted_full, 1)
    rc = lib.merge_rows(*args, _set_values(), diag, off)
    for part in (diag, off):
        petsc.MatSetOption(part, sorted_full, 0)
    if rc != 0:
        raise RuntimeError(f"cell_assembly: MatSetValues returned {rc}")
    M.setOption(PETSc.Mat.Option.NO_OFF_PROC_ENTRIES, True)
    M.assemble()
    M.setOption(PETSc.Mat.Option.NO_OFF_PROC_ENTRIES, False)
    return M


def _ranges(starts: np.ndarray, lens: np.ndarray) -> np.ndarray:
    """The indices starts[0] .. starts[0] + lens[0] - 1, then those of the next range, and so on."""
    offsets = np.cumsum(lens) - lens
    return np.repeat(np.asarray(starts, dtype=np.int64) - offsets, lens) + np.arange(int(np.sum(lens)))


def _exchange(comm: MPI.Comm, send: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """All-to-all of ``send`` (grouped by destination rank, ``counts`` items each): what this rank
    receives, by source rank."""
    recv_counts = np.empty(comm.size, dtype=np.int64)
    comm.Alltoall(np.ascontiguousarray(counts, dtype=np.int64), recv_counts)
    recv = np.empty(int(recv_counts.sum()), dtype=send.dtype)
    sd = np.concatenate([[0], np.cumsum(counts)[:-1]])
    rd = np.concatenate([[0], np.cumsum(recv_counts)[:-1]])
    comm.Alltoallv([np.ascontiguousarray(send), (counts, sd)], [recv, (recv_counts, rd)])
    return recv


def kronecker(A: PETSc.Mat, W: np.ndarray, drop: np.ndarray, like: PETSc.Mat) -> PETSc.Mat | None:
    """A ⊗ W as a serial AIJ matrix with the layout, block size and local-to-global map of ``like``,
    without the rows and columns flagged in ``drop`` (as a Dirichlet assembly with diagonal 0
    leaves them) and without W's zero entries: the entry W(c, d) A(i, j) at row b·i + c, column
    b·j + d (A: the serial scalar matrix; W: b × b).  Each row is written once, in order, through
    MatSetValues on exactly preallocated rows (255k DOFs, P2 mass: 6.4M entries in 0.05 s, against
    0.35 s for NumPy index arrays and PETSc's copy of them).  None where the compiled loop or
    PETSc's library cannot be had, or on more than one rank (:func:`kronecker_rows`)."""
    lib = _native()
    if lib is None or A.getComm().getSize() > 1:
        return None
    b = W.shape[0]
    Wc = np.ascontiguousarray(W, dtype=np.float64)
    flag = np.ascontiguousarray(drop, dtype=np.int8)
    with csr_view(A) as (ai, aj, av):
        n = len(ai) - 1
        ai, aj, av = (np.ascontiguousarray(a) for a in (ai, aj, av))
        count = np.empty(b * n, dtype=np.int32)
        lib.kronecker_rows(n, b, 0, address(ai), address(aj), address(Wc), address(flag), address(count))
        M = PETSc.Mat().createAIJ(like.getSizes(), bsize=b, comm=like.getComm(), nnz=count)
        longest = int(count.max(initial=0))
        cols, vals = np.empty(longest, dtype=np.int32), np.empty(longest)
        _write_rows(M, lambda set_values, mat: lib.fill_kronecker(
            set_values, mat, n, b, address(ai), address(aj), address(av), address(Wc), address(flag),
            address(cols), address(vals)))
    M.setLGMap(*like.getLGMap())
    M.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    return M


def kronecker_rows(A: PETSc.Mat, W: np.ndarray, drop: np.ndarray, like: PETSc.Mat) -> PETSc.Mat | None:
    """:func:`kronecker` on any number of ranks, from each rank's own rows of the parallel scalar
    matrix ``A`` (``MatGetRow``: global columns, sorted): row b·i + c of A ⊗ W holds W(c, d) A(i, j)
    at column b·j + d, j in A's order, d inner, so every row comes out sorted and no rank needs
    another's rows.  ``drop``: the global numbers of the DOFs (every rank's, sorted) whose rows and
    columns are left out (an owned row couples to nodes of other ranks' cells, which this rank
    does not hold).  The rows are written by the compiled loop straight into CSR arrays, then one
    MatCreateMPIAIJWithArrays with ``like``'s sizes, block size and local-to-global map.  None
    where the compiled loop or PETSc's library cannot be had."""
    lib = _native()
    if lib is None:
        return None
    b = W.shape[0]
    Wc = np.ascontiguousarray(W, dtype=np.float64)
    ip, ind, av = (np.ascontiguousarray(a) for a in A.getValuesCSR())
    n, start = len(ip) - 1, A.getOwnershipRange()[0]
    flag = np.zeros(b * A.getSize()[0], dtype=np.int8)       # by global DOF
    flag[np.asarray(drop, dtype=np.int64)] = 1
    count = np.empty(b * n, dtype=np.int32)
    lib.kronecker_rows(n, b, start, address(ip), address(ind), address(Wc), address(flag), address(count))
    indptr = np.zeros(b * n + 1, dtype=np.int32)
    np.cumsum(count, out=indptr[1:])
    indices, data = np.empty(indptr[-1], dtype=np.int32), np.empty(indptr[-1])
    lib.kronecker_csr(n, b, start, address(ip), address(ind), address(av), address(Wc), address(flag),
                      address(indptr), address(indices), address(data))
    M = PETSc.Mat().createAIJ(like.getSizes(), bsize=b, comm=like.getComm(), csr=(indptr, indices, data))
    M.assemble()
    M.setLGMap(*like.getLGMap())
    M.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    return M
