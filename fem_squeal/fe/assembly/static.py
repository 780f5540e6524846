"""Static solves K u = f with a direct factorisation."""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from fem_squeal.fe.factorisation import LU, factor_solver
from fem_squeal.util.errors import ModelError


def direct_solver(A: PETSc.Mat, options: dict | None, prefix: str) -> PETSc.KSP:
    """A direct solver of A, factorised (:func:`fem_squeal.fe.factorisation.factor_solver`: MUMPS LU
    by default; PETSc options under ``prefix`` override it)."""
    return factor_solver(A, LU, prefix, options)


def static_displacement(K: PETSc.Mat, f: PETSc.Vec, options: dict | None = None,
                        prefix: str = "prestress_") -> PETSc.Vec:
    """u with K u = f (direct LU; K with the clamped rows as identity and f zero there).  Raises
    :class:`ModelError` when the solve fails or its residual exceeds 1e-6‖f‖ (a part not held against
    rigid-body motion under a load that is not self-equilibrated).  A free body under a self-equilibrated
    load (the centrifugal load of a free disc) gets one solution: its rigid part carries no stress."""
    ksp = None
    u = K.createVecRight()
    r = K.createVecLeft()
    try:
        ksp = direct_solver(K, options, prefix)
        ksp.solve(f, u)
        K.mult(u, r)
        r.axpy(-1.0, f)
        fn = f.norm()
        bad = ksp.getConvergedReason() < 0 or not np.isfinite(u.norm()) or (fn > 0 and r.norm() > 1e-6 * fn)
    except PETSc.Error:
        bad = True
    finally:
        if ksp is not None:
            ksp.destroy()
        r.destroy()
    if bad:
        u.destroy()
        raise ModelError("prestress: the static problem K u = f has no unique solution (is every part held "
                         "against rigid-body motion? the centrifugal and preload stresses need it)")
    return u
