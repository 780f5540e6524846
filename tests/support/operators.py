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


def projection_mismatch(par, Phi: np.ndarray, model, point: dict) -> list[float]:
    """max |reduced − ΦᵀAΦ| / max |ΦᵀAΦ| for A = K(p) and, when damped, C(p), at ``point``: the reduced
    model's affine terms against the projection of the full parametric operators."""
    from fem_squeal.fe.projection import project

    full = par.matrices(point)
    red = model.matrices({k: np.array([v]) for k, v in point.items()})
    out = []
    for A, R in zip(full, red):
        if A is None or R is None:
            continue
        P = project(A, Phi)
        A.destroy()
        out.append(float(np.max(np.abs(R[0] - P)) / np.max(np.abs(P))))
    return out
