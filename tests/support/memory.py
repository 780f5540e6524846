"""A machine faked to hold a model's out-of-core factors but not its in-core ones (issue 36: the memory
model then chooses out of core, fem_squeal.app.resources.check_resources)."""
from __future__ import annotations


def between_the_fits(scene, ranks: int = 1) -> tuple[float, float, float]:
    """(in-core, out-of-core, machine) bytes for ``scene``'s estimated DOFs on ``ranks`` ranks: the machine's
    memory halfway between the two fits, over the share of it a run may take."""
    from fem_squeal.app import resources

    dofs = resources.estimate(scene).dofs
    exact, ooc = (resources.solve_memory(dofs, ranks, k) for k in ("exact", "ooc"))
    return exact, ooc, 0.5 * (exact + ooc) / resources.REFUSE_SHARE
