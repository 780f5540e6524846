"""Modal projection of the full operators (the PETSc/SLEPc side of the reduced layer).

Basis (issue 4; seed 001 §2.2 eq. 5 generalised):

* the real modes of the frictionless system K φ = ω² M φ (K with the closed contact springs,
  symmetric) below ``f_cut``;
* modes at sampled parameter values (a part's Young's modulus at the ends of its range), so that
  the basis stays accurate across a design of experiments;
* static correction vectors (K + σM)⁻¹ K_f Φ: the quasi-static response to the friction forces of
  each mode, which the truncated modes cannot represent (measured on the ring with k_n 1e11,
  μ 1: the modal error stalls at 1.5e-3 with 160 modes, 40 modes + 40 corrections give 3e-7);
* all of it M-orthonormalised with deflation: a vector whose part outside the span of the others
  is below ``rtol`` of its M-norm adds nothing and is dropped.

The reduced matrices Φᵀ A Φ are formed with PETSc sparse × dense products and summed over the
ranks, so every rank holds the same :class:`~fem_squeal.reduced.model.ReducedModel`.

One concept per module, imports downward: :mod:`.basis` (M-orthonormal bases) ←
:mod:`.shifted` (the shared shifted factorisation, modes below a cut) ← :mod:`.parametric` (the
operators term by term, lifted residuals) ← :mod:`.sensitivity` (full-order dλ/dp) ←
:mod:`.reductor` (the basis built and the model projected) ← :mod:`.adaptive` (enrichment to the
tolerance), :mod:`.projected_cea` (the CEA of a whole band on the basis, its pairs checked in the full
model).  Every public name is re-exported here (the import paths of the former module).
"""
from __future__ import annotations

from fem_squeal.fe.model import common_mu  # noqa: F401  (re-exported, as before)
from fem_squeal.fe.projection.adaptive import (  # noqa: F401
    DERIVATIVE_ORDER,
    ReductionReport,
    adaptive_reduce,
    relative_change,
    snapshot_step,
)
from fem_squeal.fe.projection.basis import Basis, canonical_order, m_extend, m_orthonormalise, project  # noqa: F401
from fem_squeal.fe.projection.parametric import (  # noqa: F401
    ParametricOperators,
    lifted_residuals,
    lifted_residuals_at,
    parameter_derivative,
    project_plates,
)
from fem_squeal.fe.projection.projected_cea import (  # noqa: F401
    ProjectionReport,
    auto_method,
    projected_complex_modes,
)
from fem_squeal.fe.projection.reductor import (  # noqa: F401
    build_basis,
    contact_attachments,
    correction_operators,
    reduce,
    restrict_contacts,
    static_loads,
)
from fem_squeal.fe.projection.sensitivity import FullSensitivity, full_modes, full_sensitivities  # noqa: F401
from fem_squeal.fe.projection.shifted import (  # noqa: F401
    BASIS_MODE_RESIDUAL,
    BASIS_MODE_TOL,
    ShiftedSolver,
    count_below,
    modes_below,
    static_correction,
)
