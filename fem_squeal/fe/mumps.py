"""A distributed sparse symmetric factorisation A = L D Lᵀ by MUMPS, called directly, with block
solves on rank-local rows.

PETSc's MUMPS interface gathers every block of right-hand sides on rank 0 before MUMPS solves
(MatMatSolve_MUMPS, PETSc 3.18) and scatters the solution back column by column: on 2 ranks that
cost more than the solve (clamped P2 disc, 87k DOFs: 13 block solves of 8 columns, the Lanczos of
20 modes).  Here MUMPS gets each rank's own rows of the right-hand sides (ICNTL(20) = 10) and hands
back its own distribution of the solution (ICNTL(21) = 1), which one ``Alltoallv`` per block brings
to the caller's rows.  The matrix goes in as each rank's triplets of one triangle (ICNTL(18) = 3),
with SYM = 1 (LDLᵀ without pivoting) where it is declared positive definite: cheaper than the
pivoting LDLᵀ (SYM = 2).  MUMPS does not refuse an indefinite matrix there (it factorises it without
pivoting, its stability not assured): a negative pivot (INFOG(12) > 0) or a null one raises
:class:`NotPositiveDefinite`, and the caller factorises again with SYM = 2.
:class:`LDLT` owns one MUMPS instance and its factor (state with a lifecycle: :meth:`LDLT.close`).

MUMPS is reached through the package's compiled shim (``fem_squeal/fe/kernels/mumps_shim.c``, built
with the package against the ``dmumps_c.h`` of the MUMPS it links: Debian's, the one PETSc links), so
no MUMPS structure is laid out by hand here.  Where the shim was not built, :func:`available` is False
and the callers keep PETSc's path (``results.json`` says which ran).
"""
from __future__ import annotations

import ctypes
import time
from functools import lru_cache

import numpy as np
from mpi4py import MPI

from fem_squeal.fe import kernels
from fem_squeal.util.native import address

_NOT_DEFINITE = (-10, -40)     # INFOG(1): numerically singular; SYM = 1 and a null pivot
_ORDERING_AUTO = 7             # ICNTL(7): MUMPS chooses (Debian's build: PORD)


class NotPositiveDefinite(ArithmeticError):
    """MUMPS's LDLᵀ without pivoting (SYM = 1) met a pivot that is not positive."""


@lru_cache(maxsize=1)
def _lib() -> ctypes.CDLL | None:
    """The MUMPS shim with its signatures, or None where it was not built."""
    lib = kernels.library("mumps_shim")
    if lib is None:
        return None
    p, i32, i64 = ctypes.c_void_p, ctypes.c_int32, ctypes.c_int64
    for name, args, res in (("fsm_version", [p, i32], None), ("fsm_new", [i32, i32], p),
                            ("fsm_factor", [p, i32, i64, p, p, p, i32], ctypes.c_int),
                            ("fsm_solution_rows", [p], ctypes.c_int),
                            ("fsm_solve", [p, i32, i32, p, p, i32, p, p], ctypes.c_int),
                            ("fsm_info", [p, p, p], None), ("fsm_free", [p], None)):
        f = getattr(lib, name)
        f.argtypes, f.restype = args, res
    return lib


def available() -> bool:
    """MUMPS is reachable directly: the package's shim was built (against dmumps_c.h) and loads."""
    return _lib() is not None


def version() -> str | None:
    """The MUMPS version the shim was built against (``"5.5.1"``), or None."""
    lib = _lib()
    if lib is None:
        return None
    buf = ctypes.create_string_buffer(32)
    lib.fsm_version(buf, 32)
    return buf.value.decode()


def lower_triplets(rows: tuple[int, int], csr: tuple[np.ndarray, np.ndarray, np.ndarray]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """1-based (row, column, value) triplets of the entries on or below the diagonal of this rank's
    rows ``rows`` = [lo, hi) of a symmetric matrix given as their CSR (indptr, global column indices,
    values): one triangle, as MUMPS's symmetric input wants it (an entry given twice is summed)."""
    indptr, cols, vals = csr
    r = np.repeat(np.arange(rows[0], rows[1], dtype=np.int64), np.diff(indptr))
    keep = cols <= r
    return ((r[keep] + 1).astype(np.int32), (np.asarray(cols)[keep] + 1).astype(np.int32),
            np.ascontiguousarray(np.asarray(vals)[keep], dtype=np.float64))


class LDLT:
    """The factorisation A = L D Lᵀ of a symmetric matrix of ``n`` rows distributed by rows (rank r
    owns [lo, hi) = ``rows``), given by this rank's triplets of one triangle (1-based global
    indices; :func:`lower_triplets`).  ``definite``: SYM = 1 (no pivoting; raises
    :class:`NotPositiveDefinite` where a pivot is not positive), else SYM = 2.  Collective: every
    rank of ``comm`` constructs, solves and closes together.  :meth:`solve` returns A⁻¹B for
    rank-local column-major blocks B (rows [lo, hi)); :meth:`close` frees the factor."""

    def __init__(self, comm: MPI.Comm, n: int, rows: tuple[int, int],
                 triplets: tuple[np.ndarray, np.ndarray, np.ndarray], definite: bool) -> None:
        lib = _lib()
        if lib is None:
            raise RuntimeError("MUMPS is not available directly (the package's mumps_shim kernel was not built)")
        self._lib, self.comm, self.n, self.rows, self.definite = lib, comm, n, rows, definite
        self._plan = None
        self._h = ctypes.c_void_p(lib.fsm_new(comm.py2f(), 1 if definite else 2))
        if not self._h.value:
            raise MemoryError("MUMPS: initialisation failed")
        irn, jcn, a = (np.ascontiguousarray(x) for x in triplets)
        try:
            t0 = time.perf_counter()
            status = lib.fsm_factor(self._h, n, len(a), address(irn), address(jcn), address(a), _ORDERING_AUTO)
            self.seconds = {"factor": time.perf_counter() - t0}
            if definite and (status in _NOT_DEFINITE or status >= 0 and self.infog(12) > 0):
                raise NotPositiveDefinite(f"MUMPS LDLᵀ without pivoting: INFOG(1) = {status}, "
                                          f"{self.infog(12)} negative pivots: the matrix is not positive definite")
            if status < 0:
                raise RuntimeError(f"MUMPS analysis/factorisation failed: INFOG(1) = {status}, "
                                   f"INFOG(2) = {self.infog(2)}")
        except BaseException:
            self.close()
            raise
        self.flops = self.rinfog(3)
        self.factor_entries = float(self.infog(29))
        self._sol_rows = lib.fsm_solution_rows(self._h)
        self._irhs = np.arange(rows[0] + 1, rows[1] + 1, dtype=np.int32)

    def _info(self) -> tuple[np.ndarray, np.ndarray]:
        infog, rinfog = np.zeros(80, np.int32), np.zeros(40)
        self._lib.fsm_info(self._h, address(infog), address(rinfog))
        return infog, rinfog

    def infog(self, i: int) -> int:
        """MUMPS's INFOG(i) (1-based, as in its manual)."""
        return int(self._info()[0][i - 1])

    def rinfog(self, i: int) -> float:
        """MUMPS's RINFOG(i) (1-based, as in its manual)."""
        return float(self._info()[1][i - 1])

    def _redistribution(self, isol: np.ndarray) -> tuple:
        """The plan that brings MUMPS's solution rows ``isol`` (1-based global) to their owners: the
        order of this rank's rows by owner, counts sent and received, and where the received rows
        go.  Made at the first solve (MUMPS's distribution is fixed by the factorisation)."""
        comm = self.comm
        ranges = np.array(comm.allgather(self.rows[0]) + [self.n])
        g = isol.astype(np.int64) - 1
        owner = np.searchsorted(ranges, g, side="right") - 1
        order = np.argsort(owner, kind="stable")
        send = np.bincount(owner, minlength=comm.size).astype(np.int64)
        recv = np.empty(comm.size, np.int64)
        comm.Alltoall(send, recv)
        where = np.empty(int(recv.sum()), np.int64)
        comm.Alltoallv([g[order], send], [where, recv])
        return isol.copy(), order, send, recv, where - self.rows[0]

    def solve(self, B: np.ndarray) -> np.ndarray:
        """A⁻¹ B for this rank's rows B (n_local × k, or n_local); a new column-major array."""
        B = np.asfortranarray(B, dtype=np.float64)
        vec = B.ndim == 1
        nloc = self.rows[1] - self.rows[0]
        B2 = B.reshape(nloc, -1, order="F")
        k = B2.shape[1]
        lsol = max(self._sol_rows, 1)
        sol = np.empty((lsol, k), order="F")
        isol = np.zeros(lsol, np.int32)
        status = self._lib.fsm_solve(self._h, k, nloc, address(self._irhs), address(B2), lsol, address(sol),
                                     address(isol))
        if status < 0:
            raise RuntimeError(f"MUMPS solve failed: INFOG(1) = {status}, INFOG(2) = {self.infog(2)}")
        isol = isol[:self._sol_rows]
        if self._plan is None or not np.array_equal(self._plan[0], isol):
            self._plan = self._redistribution(isol)
        _, order, send, recv, where = self._plan
        out_rows = np.ascontiguousarray(sol[:self._sol_rows][order])         # row-major: whole rows
        got = np.empty((int(recv.sum()), k))
        self.comm.Alltoallv([out_rows, send * k], [got, recv * k])
        out = np.empty((nloc, k), order="F")
        out[where] = got
        kernels.note("block_solve", "mumps, distributed right-hand sides")
        return out[:, 0] if vec else out

    def close(self) -> None:
        """Free MUMPS's factor and instance (idempotent; collective)."""
        h = getattr(self, "_h", None)
        if h is None or not h.value:
            return
        self._lib.fsm_free(h)
        self._h = None

    def __enter__(self) -> LDLT:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
