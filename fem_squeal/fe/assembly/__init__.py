"""Assemble the PETSc operators of a model: K (elastic + springs), K_f, M, C, loads, interfaces.

The operator is λ²M + λC + (K + K_f): ``Kf`` is stored with the sign it has in the operator.
Volume forms are assembled into the cell sparsity pattern of K; spring and bonded interfaces
(built from the interface operator G) add entries between bodies.  Contact interfaces are kept
apart as :class:`~fem_squeal.fe.interface.InterfaceOperator` s: their K_c, K_f depend on which
points are closed, which the preload decides (:func:`linearise`).  Dirichlet (clamped) DOFs
get 1 on the diagonal of K and 0 on those of M, C, K_f and the interface matrices: they become
infinite eigenvalues that shift-invert never returns.

The package, one concept a module:

- :mod:`.compiled`: forms compiled and assembled into PETSc matrices (Dirichlet rows, vector masses);
- :mod:`.operators`: the model's operators on its mesh (:func:`assemble_operators`), loads, interfaces;
- :mod:`.contact`: contact matrices of a closed set and the linearised operators;
- :mod:`.static`: static solves;
- :mod:`.operating`: rotation, stress stiffening and the operators at a speed.

Every name of the former module ``fem_squeal.fe.assembly`` is importable from here.
"""
from __future__ import annotations

from fem_squeal.fe.assembly.compiled import (  # noqa: F401
    JIT_PARAMS,
    _add,
    _assemble,
    _block_masses,
    _compile,
    _LiftFloats,
    _owned_global_rows,
    assemble_form,
)
from fem_squeal.fe.assembly.contact import (  # noqa: F401
    contact_change,
    contact_matrices,
    destroy_relinearised,
    linearise,
    relinearise,
)
from fem_squeal.fe.assembly.operating import (  # noqa: F401
    OperatingTerms,
    RotationMatrices,
    _part_measure,
    combination,
    geometric_stiffness,
    operating_operators,
    operating_terms,
    rotation_matrices,
)
from fem_squeal.fe.assembly.operators import (  # noqa: F401
    LOCKING_NU,
    Operators,
    PlateMatrices,
    _c3d8r_corrections,
    _check_c3d8r,
    _face_tag,
    _plate_forms,
    add_point_loads,
    assemble_operators,
    build_interface,
    dirichlet_conditions,
    locking_warnings,
    part_stiffnesses,
    plate_friction_fields,
    point_load_nodes,
)
from fem_squeal.fe.assembly.static import (  # noqa: F401
    direct_solver,
    static_displacement,
)
