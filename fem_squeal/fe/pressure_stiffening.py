"""The stress stiffening across brake pressures (issue 39): K_σ of the preload at every pressure scale s of
the scene's ``loads.pressure``, as the reduced model's affine term and, for its full-order check, from
each pressure's own preload state.

K_σ is linear in the displacement (σ₀ = C ε(u), :func:`fem_squeal.fe.assembly.geometric_stiffness`).  With
the contact set of the scene at every s and the linear penalty, the preload u(s) solves a linear problem
whose load is affine in s (s f, plus the fixed gap terms of the closed points), so u(s) is affine in s and

    K_σ(u(s)) = K_σ(u(1)) + (s − 1) K_σ,s,      K_σ,s = K_σ(du/ds) = K_σ((u(s*) − u(1)) / (s* − 1))

with s* the continued scale farthest from 1 (the slope of two converged states: exact to the preload's
tolerance).  The reduced model carries Φᵀ K_σ,s Φ with the coefficient s − 1
(:mod:`fem_squeal.reduced.affine`); :meth:`PressureStiffening.at` assembles K_σ(u(s)) from the state
continued to s itself (:mod:`fem_squeal.fe.preload_continuation`), not from the affine formula: the
corner checks compare the reduced model with a full CEA at that pressure's own stress stiffening.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping

from petsc4py import PETSc

from fem_squeal.util.errors import ModelError

#: the scene's own pressure (the scale of its preload, whose K_σ the operators hold)
REFERENCE = 1.0


class PressureStiffening:
    """K_σ of the preload states u(s) by pressure scale s (``states``, the scene's s = 1 among them),
    assembled by ``assemble`` (u ↦ K_σ(u), a new matrix): the slope :attr:`slope` = K_σ(du/ds) and
    K_σ(u(s)) of a state (:meth:`at`, assembled once).  Owns its matrices (:meth:`destroy`), not the
    states."""

    def __init__(self, states: Mapping[float, PETSc.Vec], assemble: Callable[[PETSc.Vec], PETSc.Mat]):
        self.states = {float(s): u for s, u in states.items()}
        if REFERENCE not in self.states:
            raise ModelError("pressure: the stress stiffening across pressures needs the scene's preload "
                             "state (scale 1)")
        others = [s for s in self.states if s != REFERENCE]
        if not others:
            raise ModelError("pressure: the stress stiffening across pressures needs a preload state at "
                             "another pressure scale than 1")
        self.assemble = assemble
        self.far = max(others, key=lambda s: (abs(s - REFERENCE), s))
        du = self.states[self.far].copy()
        du.axpy(-1.0, self.states[REFERENCE])
        du.scale(1.0 / (self.far - REFERENCE))
        try:
            self.slope = assemble(du)
        finally:
            du.destroy()
        self._at: dict[float, PETSc.Mat] = {}

    @property
    def scales(self) -> list[float]:
        """The pressure scales with a state, ascending."""
        return sorted(self.states)

    def at(self, scale: float) -> PETSc.Mat:
        """K_σ(u(s)) assembled from the preload state at ``scale`` (kept; a ModelError naming the scales
        with a state when there is none)."""
        s = float(scale)
        if s not in self.states:
            raise ModelError(f"pressure: no preload state at {s:g} × loads.pressure (states at "
                             f"{[float(f'{x:g}') for x in self.scales]}); its stress stiffening is assembled "
                             "from the state continued to that pressure")
        if s not in self._at:
            self._at[s] = self.assemble(self.states[s])
        return self._at[s]

    def destroy(self) -> None:
        for A in (self.slope, *self._at.values()):
            A.destroy()
        self._at.clear()
