"""The compiled kernels of the finite-element layer: C sources built with the package (``setup.py``,
by ``pip install`` and ``pip install -e``), loaded here with ctypes.  Nothing is compiled at run time.

=====================  ========================================================  =======================
library                what it does                                              where it is missing
=====================  ========================================================  =======================
``csr_block``          A X for a serial CSR matrix and a column-major block      PETSc's MatMatMult
                       (:mod:`fem_squeal.fe.csr`)
``cell_assembly``      cell-integral matrices written row by row, M_s ⊗ W        dolfinx's assembly
                       (:mod:`fem_squeal.fe.cell_assembly`)
``supernodal_solve``   block solves on CHOLMOD's supernodal factor (AVX2 or      CHOLMOD's own solve
                       AVX-512 builds, picked for the CPU), and the sweeps       (MUMPS on N ranks)
                       stopped at an interface (:mod:`fem_squeal.fe.substructured`)
``cholmod_shim``       CHOLMOD's factorisation and solve behind plain functions  PETSc's CHOLMOD or
                       (:mod:`fem_squeal.fe.cholmod`), compiled against the      MUMPS
                       cholmod.h of the CHOLMOD it links
``substructure``       the local matrix of the substructured factorisation       NumPy
                       from a rank's rows, in one pass
                       (:mod:`fem_squeal.fe.substructured`)
=====================  ========================================================  =======================

:func:`library` gives a loaded kernel or None; :func:`status` says which were built.  Each place
that chooses between a kernel and the library path it replaces notes its choice (:func:`note`); the
runner reads the tally per stage (:func:`tally`) into ``results.json``'s ``solver`` section, so a
result says which path produced it.
"""
from __future__ import annotations

import ctypes
from collections import Counter
from functools import cache
from importlib.machinery import EXTENSION_SUFFIXES
from pathlib import Path

FOLDER = Path(__file__).resolve().parent
NAMES = ("csr_block", "cell_assembly", "supernodal_solve", "cholmod_shim", "substructure")
_TALLY: Counter[tuple[str, str]] = Counter()     # (operation, path) -> times chosen in this process


def path(name: str) -> Path | None:
    """The built shared library of kernel ``name`` (the extension suffix of this Python), or None."""
    for suffix in EXTENSION_SUFFIXES:
        p = FOLDER / f"{name}{suffix}"
        if p.is_file():
            return p
    return None


@cache
def library(name: str) -> ctypes.CDLL | None:
    """Kernel ``name`` loaded (once per process); None where it was not built or does not load."""
    if name not in NAMES:
        raise ValueError(f"unknown kernel {name!r}; kernels: {NAMES}")
    p = path(name)
    if p is None:
        return None
    try:
        return ctypes.CDLL(str(p))
    except OSError:
        return None


def status() -> dict[str, bool]:
    """name -> whether the kernel is built and loads."""
    return {n: library(n) is not None for n in NAMES}


def note(operation: str, path: str) -> None:
    """Record that ``operation`` (``assembly``, ``block_product``, ``factorisation``, ``block_solve``)
    ran on ``path`` (``compiled``, ``compiled-avx512``, ``cholmod``, ``petsc``, ``dolfinx``, ...)."""
    _TALLY[(operation, path)] += 1


def tally(reset: bool = False) -> dict[str, dict[str, int]]:
    """``{operation: {path: count}}`` since the last reset (this process); ``reset`` starts anew."""
    out: dict[str, dict[str, int]] = {}
    for (op, path), n in sorted(_TALLY.items()):
        out.setdefault(op, {})[path] = n
    if reset:
        _TALLY.clear()
    return out
