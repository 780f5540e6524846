"""The factorisation factory: sparse direct solvers of A with their settings as a typed object.

A :class:`Factorisation` says how a matrix is factorised: PETSc's ``pc_type`` (``lu``, or ``cholesky``:
MUMPS' LDLᵀ, CHOLMOD's LLᵀ), the solver package (``pc_factor_mat_solver_type``), MUMPS' integer
controls ICNTL(i) and any other option of the factor.  Its values are **defaults**: the user's PETSc
options under the solver's prefix override them, given on the command line
(``-basis_static_pc_factor_mat_solver_type superlu_dist``) or in the scene's ``solver.petsc_options``
(which win over the command line, as they always have).

The factory hands these settings to the objects it sets up only for the duration of that set-up
(:func:`scoped_options`): afterwards PETSc's global options database holds exactly what it held
before.  Nothing is keyed by object handles (PETSc reuses them); what a solve learns about a matrix
(K − σM not positive definite) the caller passes on explicitly.

Where a run's factors do not fit in memory, :func:`factors_out_of_core` keeps every MUMPS factor set
up inside it in files (ICNTL(22) = 1, a default like the others: the user's option wins).
"""
from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, replace

from petsc4py import PETSc

from fem_squeal.util.blas import serial_openmp
from fem_squeal.util.memory import release_freed_memory

Options = Mapping[str, object]     # PETSc options with their full prefix, e.g. the scene's petsc_options

#: the folder of MUMPS's factor files while :func:`factors_out_of_core` is active (None: in core)
_OUT_OF_CORE: ContextVar[str | None] = ContextVar("fem_squeal_out_of_core", default=None)


@dataclass(frozen=True)
class Factorisation:
    """How a sparse matrix is factorised (defaults; the user's PETSc options under the prefix win)."""

    kind: str = "lu"                          # PETSc pc_type: "lu" or "cholesky"
    package: str = "mumps"                    # PETSc MatSolverType (mumps, cholmod, ...); "": chosen later
    icntl: tuple[tuple[int, int], ...] = ()   # MUMPS ICNTL(i) = v (MUMPS' own defaults otherwise)
    extra: tuple[tuple[str, str], ...] = ()   # further options of the factor, without prefix

    def options(self, prefix: str) -> dict[str, str]:
        """These settings as PETSc options under ``prefix`` (the KSP's prefix)."""
        out = {f"{prefix}ksp_type": "preonly", f"{prefix}pc_type": self.kind}
        if self.package:
            out[f"{prefix}pc_factor_mat_solver_type"] = self.package
        if _OUT_OF_CORE.get() is not None and self.package in ("mumps", ""):     # "": MUMPS if it is chosen
            out[f"{prefix}mat_mumps_icntl_22"] = "1"
        out.update({f"{prefix}mat_mumps_icntl_{i}": str(v) for i, v in self.icntl})
        out.update({f"{prefix}{k}": v for k, v in self.extra})
        return out

    def with_(self, **changes) -> Factorisation:
        """A copy with ``changes`` (dataclass fields); ``icntl``/``extra`` given as dicts are merged."""
        for name in ("icntl", "extra"):
            if isinstance(changes.get(name), Mapping):
                changes[name] = tuple({**dict(getattr(self, name)), **changes[name]}.items())
        return replace(self, **changes)


#: MUMPS LU: the default for non-symmetric operators (the CEA's shift-and-invert, the preload's Jacobian).
LU = Factorisation()
#: MUMPS LDLᵀ of a symmetric matrix.
CHOLESKY = Factorisation("cholesky")
#: CHOLMOD's own "not positive definite" line silenced (MUMPS LDLᵀ takes over: :func:`symmetric_packages`)
QUIET_CHOLMOD = {"mat_cholmod_print": "0"}


def out_of_core_folder() -> str | None:
    """The folder of MUMPS's factor files inside :func:`factors_out_of_core`, else None (in core)."""
    return _OUT_OF_CORE.get()


@contextmanager
def factors_out_of_core(folder: str) -> Iterator[None]:
    """Every MUMPS factorisation set up in this block keeps its factors in files in ``folder``
    (ICNTL(22) = 1 as a default of :meth:`Factorisation.options`; MUMPS reads $MUMPS_OOC_TMPDIR when
    it factorises and deletes its files when the factor is destroyed).  The factors are the in-core
    ones, stored elsewhere: the same values, read back at every solve.  Collective where the
    factorisations are: every rank enters it."""
    token, old = _OUT_OF_CORE.set(folder), os.environ.get("MUMPS_OOC_TMPDIR")
    os.environ["MUMPS_OOC_TMPDIR"] = folder
    try:
        yield
    finally:
        _OUT_OF_CORE.reset(token)
        if old is None:
            os.environ.pop("MUMPS_OOC_TMPDIR", None)
        else:
            os.environ["MUMPS_OOC_TMPDIR"] = old


def _text(value: object) -> str:
    return ("true" if value else "false") if isinstance(value, bool) else str(value)


def user_option(name: str) -> str | None:
    """The value of the PETSc option ``name`` (full name with its prefix, no dash) in PETSc's
    options database: the command line's, and inside :func:`scoped_options` the scene's; None if
    not given."""
    db = PETSc.Options()
    return db.getString(name) if db.hasName(name) else None


@contextmanager
def scoped_options(defaults: Mapping[str, str], options: Options | None = None) -> Iterator[None]:
    """PETSc's options database with ``defaults`` where the user gave no value and with the scene's
    ``options`` (they win over the command line), for the duration of the block; afterwards every
    entry is as it was (a removed default, a restored command-line value)."""
    db = PETSc.Options()
    saved: dict[str, str | None] = {}
    for name, value in (options or {}).items():
        name = name.lstrip("-")
        saved.setdefault(name, user_option(name))
        db[name] = _text(value)
    for name, value in defaults.items():
        if not db.hasName(name):
            saved.setdefault(name, None)
            db[name] = value
    try:
        yield
    finally:
        for name, old in saved.items():
            if old is None:
                db.delValue(name)
            else:
                db[name] = old


def factor_solver(A: PETSc.Mat, factorisation: Factorisation, prefix: str, options: Options | None = None
                  ) -> PETSc.KSP:
    """A KSP that solves with a factorisation of ``A``, set up (factorised) here: ``factorisation``'s
    settings under ``prefix``, overridden by the user's (``options``: the scene's, then the command
    line).  Later solves with new values of ``A`` (same pattern) refactorise numerically only.  The heap's
    free pages are returned first (:func:`fem_squeal.util.memory.release_freed_memory`), so that the factor
    does not sit beside what the assembly of ``A`` left there."""
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    release_freed_memory()
    try:
        with scoped_options(factorisation.options(prefix), options):
            ksp.setFromOptions()
            ksp.setUp()
    except PETSc.Error:
        ksp.destroy()
        raise
    return ksp


def out_of_core_by_the_model(prefix: str, options: Options | None = None) -> bool:
    """Whether a MUMPS factorisation under ``prefix`` goes out of core by the run's choice: inside
    :func:`factors_out_of_core` (the memory model's) with no ICNTL(22) of the user's under ``prefix`` (the
    scene's ``options``, then the command line), which would decide instead."""
    if out_of_core_folder() is None:
        return False
    with scoped_options({}, options):
        return user_option(f"{prefix}mat_mumps_icntl_22") is None


def symmetric_packages(ranks: int, prefix: str, definite: bool = True) -> list[str]:
    """The packages to try, in order, for a Cholesky factorisation of a symmetric matrix under ``prefix``:
    the user's ``<prefix>pc_factor_mat_solver_type``, else CHOLMOD on one rank where the matrix may be
    ``definite`` (supernodal LLᵀ, in core; MUMPS LDLᵀ after it for a matrix that is not positive
    definite), MUMPS LDLᵀ on more ranks."""
    chosen = user_option(f"{prefix}pc_factor_mat_solver_type")
    if chosen:
        return [chosen]
    if ranks == 1 and definite and PETSc.Sys.hasExternalPackage("suitesparse"):
        return ["cholmod", "mumps"]
    return ["mumps"]


def symmetric_solver(A: PETSc.Mat, prefix: str, options: Options | None = None) -> PETSc.KSP:
    """A KSP that solves with a Cholesky factorisation of the symmetric ``A`` (:func:`factor_solver`; the
    first of :func:`symmetric_packages` that factorises it), set up here, in core also inside
    :func:`factors_out_of_core` (MUMPS's ICNTL(22) = 0 unless the user's option says otherwise: the
    preload takes it where the LU would go out of core and it fits); its package is the KSP's factor
    solver type.
    Half the factor of an LU: CHOLMOD's 0.19 s solves and 2.1 GiB peak against MUMPS LDLᵀ's 0.36 s and
    more than 4 GiB, and MUMPS LU's 24 s factorisation against 12 s (the brake corner's frictionless
    Jacobian at 347,853 DOFs, one rank, 2026-11-29)."""
    with scoped_options({}, options):
        packages = symmetric_packages(A.getComm().getSize(), prefix)
    for k, package in enumerate(packages):
        try:
            with serial_openmp():           # CHOLMOD's OpenMP loops (fem_squeal.util.blas); nothing for MUMPS
                factor = CHOLESKY.with_(package=package, extra=QUIET_CHOLMOD, icntl={22: 0})
                return factor_solver(A, factor, prefix, options)
        except PETSc.Error:
            if k + 1 == len(packages):
                raise
    raise AssertionError("unreachable")


def refactorise(ksp: PETSc.KSP) -> None:
    """Factorise ``ksp``'s operator anew, now, after its values changed (same pattern: numerically only,
    with the kept ordering).  Once a KSP has been set up, KSPSetUp leaves the new factorisation to the
    next solve; PCSetUp sees the operator's new state and performs it here, so that it can be timed."""
    release_freed_memory()
    with serial_openmp():                   # CHOLMOD's OpenMP loops (fem_squeal.util.blas); nothing for MUMPS
        ksp.getPC().setUp()
