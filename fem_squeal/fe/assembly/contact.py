"""The contact matrices of the closed points and the operators linearised about a contact state."""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from fem_squeal.fe import interface as itf
from fem_squeal.fe.assembly.compiled import _add, _owned_global_rows
from fem_squeal.fe.assembly.operators import Operators
from fem_squeal.fe.csr import drop_zeros


def contact_matrices(ops: Operators, stiffness: dict[str, np.ndarray] | None = None,
                     friction: bool = True) -> tuple[PETSc.Mat | None, PETSc.Mat | None]:
    """Σ K_c and Σ K_f over the contact interfaces, zero on the clamped DOFs.

    ``stiffness[name]`` is the normal stiffness dσ/dg at each quadrature point of that contact
    (k_n where closed, 0 where open, for the linear penalty); None: k_n everywhere (all closed).
    K_c includes the tangential penalty k_t of the points where dσ/dg > 0 (the closed ones):
    k_t G_t₂ᵀ W G_t₂ for a sliding contact, k_t (G_t₁ᵀ W G_t₁ + G_t₂ᵀ W G_t₂) for sliding = 0.
    K_f only for ``friction`` and interfaces with friction; None where there is nothing to add."""
    bc_rows = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
    total: list[PETSc.Mat | None] = [None, None]
    for it, op in ops.contacts:
        k = it.kn if stiffness is None else stiffness[it.name]
        mats = [itf.contact_stiffness(op, k)]
        if it.kt > 0:   # tangential penalty on the closed points (dσ/dg > 0), μ-independent: in K_c
            closed = 1.0 if stiffness is None else (np.asarray(k) > 0).astype(float)
            T = itf.tangential_stiffness(op, it.kt * closed, it.sliding != 0)
            _add(mats[0], T)
            T.destroy()
        mu = it.mu if it.law is None else it.friction_coefficient(op.x)    # μ(V) at V = Ω r per point
        mats.append(itf.friction_stiffness(op, k, mu) if friction and it.has_friction else None)
        for j, A in enumerate(mats):
            if A is None:
                continue
            A.zeroRowsColumns(bc_rows, diag=0.0)
            if total[j] is None:
                total[j] = A
            else:
                _add(total[j], A)
                A.destroy()
    return total[0], total[1]


def linearise(ops: Operators, active: dict[str, np.ndarray] | None = None,
              friction: bool = True) -> Operators:
    """Operators with the contact interfaces' K_c and K_f added for the closed points.

    ``active[name]`` flags the closed quadrature points of each contact (None: all closed, the
    linear route).  Returns new K and K_f (the inputs are not modified).  Only the closed points'
    couplings enter their patterns: the open ones' stored zeros would be factorised as entries (the
    brake corner at 348k DOFs on 2 ranks, 3554 of 5400 points closed: the CEA's LU of K − σM takes
    13–22 % fewer flops and 5–10 % fewer factor entries without them; ``benchmarks/contact_factorisation.py``,
    docs/validation.md)."""
    if not ops.contacts:
        return ops
    stiffness = None if active is None else \
        {it.name: it.kn * active[it.name].astype(float) for it, _ in ops.contacts}
    Kc, Fc = contact_matrices(ops, stiffness, friction)
    if active is not None:      # the open points' stored zeros left out of K's pattern (docstring)
        Kc, Fc = (_without_zeros(A) for A in (Kc, Fc))
    K = ops.K.copy()
    _add(K, Kc)
    Kc.destroy()
    Kf = ops.Kf
    if Fc is not None:
        if Kf is None:
            Kf = Fc
        else:
            Kf = Kf.copy()
            _add(Kf, Fc)
            Fc.destroy()
    return ops._replace(K=K, Kf=Kf)


def _without_zeros(A: PETSc.Mat | None) -> PETSc.Mat | None:
    """``A`` without its stored zeros (:func:`fem_squeal.fe.csr.drop_zeros`), ``A`` destroyed if copied."""
    if A is None:
        return None
    B = drop_zeros(A)
    if B is not A:
        A.destroy()
    return B


def contact_change(ops: Operators, active: dict[str, np.ndarray], to: dict[str, np.ndarray],
                   friction: bool = True) -> tuple[PETSc.Mat | None, PETSc.Mat | None]:
    """ΔK_c, ΔK_f from the contact state ``active`` to the state ``to``: the contact matrices
    (:func:`contact_matrices`) of the points that closed added, of those that opened subtracted; None where
    nothing changes.  Collective (a rank without changed points still takes part)."""
    comm = ops.K.getComm().tompi4py()
    total: list[PETSc.Mat | None] = [None, None]
    for sign, flags in ((1.0, {n: to[n] & ~active[n] for n in to}), (-1.0, {n: active[n] & ~to[n] for n in to})):
        if not comm.allreduce(int(sum(np.count_nonzero(f) for f in flags.values()))):   # collective: every rank
            continue
        mats = contact_matrices(ops, {it.name: it.kn * flags[it.name].astype(float) for it, _ in ops.contacts},
                                friction)
        for j, A in enumerate(mats):
            if A is None:
                continue
            if total[j] is None:
                A.scale(sign)
                total[j] = A
            else:
                _add(total[j], A, sign)
                A.destroy()
    return total[0], total[1]


def relinearise(ops: Operators, active: dict[str, np.ndarray], to: dict[str, np.ndarray],
                friction: bool = True) -> Operators:
    """Operators linearised about the contact state ``active`` (:func:`linearise`'s) moved to the state
    ``to`` by :func:`contact_change` (the same K and K_f as :func:`linearise` about ``to``, without
    re-assembling the rest).  New K and K_f."""
    if not ops.contacts:
        return ops
    dK, dF = contact_change(ops, active, to, friction)
    K, Kf = ops.K.copy(), (ops.Kf.copy() if ops.Kf is not None else None)
    if dK is not None:
        _add(K, dK)
        dK.destroy()
    if dF is not None:
        if Kf is None:
            Kf = dF
        else:
            _add(Kf, dF)
            dF.destroy()
    return ops._replace(K=K, Kf=Kf)


def destroy_relinearised(ops: Operators) -> None:
    """Destroy the K and K_f that :func:`relinearise` made (the other operators are its input's)."""
    for A in (ops.K, ops.Kf):
        if A is not None:
            A.destroy()
