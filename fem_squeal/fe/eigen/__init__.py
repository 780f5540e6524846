"""SLEPc eigen-solvers: real modes (EPS, GHEP) and complex modes of λ²M + λC + K (PEP or linear EPS).

PETSc here is a real build: targets are real shifts, and complex eigenpairs come back as a complex
eigenvalue plus real and imaginary vector parts.  Every solver takes a PETSc options dict (the
scene's) and a prefix, so ``-cea_st_pc_factor_mat_solver_type superlu_dist`` and the like work from
the command line; the defaults are typed (:mod:`fem_squeal.fe.factorisation`) and every option
applies for the duration of its solve, nothing is left in PETSc's options database.

Complex modes, undamped (C = 0): with θ = −λ², (λ²M + K)x = 0 is the non-symmetric linear
problem K x = θ M x; each θ gives λ = i√θ (principal root, Im λ > 0).  A real shift θ_t = ω_t²
targets a band centre.  With damping the quadratic is solved by PEP (TOAR); a real target σ orders
eigenvalues by |λ − σ|² ≈ σ² + ω², so PEP returns the lowest modes and must be asked for enough of
them to cover the band.

One concept per module, imports downward: :mod:`.results` (the result types and their checks) ←
:mod:`.options` (solver settings with a prefix, the shift-and-invert EPS) ← :mod:`.block_krylov`
(block Lanczos and Arnoldi on block solves) ← :mod:`.real_modes` ← :mod:`.complex_modes` ←
:mod:`.left_vectors`.  The public names are re-exported here (the import paths of the former module);
the block methods' memory budgets (``BLOCK_MEMORY``, ``VECTOR_MEMORY_SHARE``) are read in
:mod:`.block_krylov`.
"""
from __future__ import annotations

from fem_squeal.fe.eigen.block_krylov import (  # noqa: F401
    BEYOND,
    BLOCK_MEMORY,
    VECTOR_MEMORY_SHARE,
    block_size,
)
from fem_squeal.fe.eigen.complex_modes import (  # noqa: F401
    SLEPC_SOLVER_OPTIONS,
    solve_complex_modes,
)
from fem_squeal.fe.eigen.left_vectors import (  # noqa: F401
    LeftVectors,
    solve_left_vectors,
)
from fem_squeal.fe.eigen.options import (  # noqa: F401
    PEP_OPTIONS,
    REAL_MODE_FACTOR,
    REAL_MODE_TOL,
    REAL_MODE_TOL_FALLBACK,
    drop_zeros,
)
from fem_squeal.fe.eigen.real_modes import (  # noqa: F401
    modes_on_factor,
    solve_real_modes,
)
from fem_squeal.fe.eigen.results import (  # noqa: F401
    TWO_PI,
    ComplexModes,
    RealModes,
    quadratic_residual,
)
from fem_squeal.util.errors import EigenSolveError  # noqa: F401  (re-exported, as before)
