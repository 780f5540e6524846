"""The registry of stages: one module per stage, in execution order.

Each module declares ``STAGE``, a :class:`~fem_squeal.app.stage.Stage`: its name, the stages it
needs, what it reads of the scene, its section ``analyses.<name>`` (fields with defaults and
checks, and its cross-checks), the function that computes it (writing its files and plots) and its
part of the report.  The scene loader, the pipeline, the runner and the report loop over
:data:`STAGES`; adding an analysis is one new module here and its line below.

    mesh → operators → preload → real_modes
                               → cea
                               → reduced → sweep, map, sensitivity, masa, transient → limit_cycle
                               → reduced + preload → robustness (its spot checks solve the full CEA),
                                                     operating_matrix (its corner checks too)
    segmented_pad (no mesh: a lumped model)
    matrices → real_modes, cea, sweep, map, sensitivity, robustness (a model given as matrices:
               ``Stage.on_matrices``, in place of mesh, operators, preload and reduced)
"""
from __future__ import annotations

from fem_squeal.app.analyses import (
    cea,
    limit_cycle,
    masa,
    matrices,
    mesh,
    operating_matrix,
    operators,
    preload,
    real_modes,
    reduced,
    robustness,
    segmented_pad,
    sensitivity,
    stability_map,
    sweep,
    transient,
)
from fem_squeal.app.stage import Stage

STAGES: dict[str, Stage] = {m.STAGE.name: m.STAGE for m in (
    matrices, mesh, operators, preload, real_modes, cea, reduced, sweep, stability_map, sensitivity, robustness,
    operating_matrix, masa, transient, limit_cycle, segmented_pad,
)}

#: the analyses a scene can ask for (stages with a section ``analyses.<name>``)
ANALYSES: dict[str, Stage] = {n: s for n, s in STAGES.items() if s.section is not None}
