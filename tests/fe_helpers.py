"""Small helpers shared by the FE-layer tests: nodal fields as PETSc vectors and bilinear forms."""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc


def nodal_vector(ops, field) -> PETSc.Vec:
    """The nodal interpolant of ``field(x, y, z) -> (3, n)`` in ``ops.V`` (exact for fields of degree ≤ 2)."""
    n = ops.V.dofmap.index_map.size_local
    x = ops.V.tabulate_dof_coordinates()[:n]
    v = ops.K.createVecRight()
    v.array[:] = np.asarray(field(x[:, 0], x[:, 1], x[:, 2])).T.ravel()
    return v


def bilinear(A: PETSc.Mat, u: PETSc.Vec, v: PETSc.Vec) -> float:
    """vᵀ A u."""
    w = A.createVecLeft()
    A.mult(u, w)
    return v.dot(w)
