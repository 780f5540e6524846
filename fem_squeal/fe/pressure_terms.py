"""The operators that change with the brake pressure (issue 39): the stress stiffening K_σ of the preload and
the friction damping C_d (∝ the contact pressure) at every pressure scale s of the scene's ``loads.pressure``,
as the reduced model's affine terms and, for its full-order check, from each pressure's own preload state.

K_σ is linear in the displacement (σ₀ = C ε(u), :func:`fem_squeal.fe.assembly.geometric_stiffness`) and C_d
in the contacts' pressures p (:func:`fem_squeal.fe.preload.friction_damping`).  With the contact set of the
scene at every s and the linear penalty, the preload solves a linear problem whose load is affine in s (s f,
plus the fixed gap terms of the closed points), so u(s) and p(s) are affine in s and

    K_σ(u(s)) = K_σ(u(1)) + (s − 1) K_σ,s,      K_σ,s = K_σ((u(s*) − u(1)) / (s* − 1))
    C_d(p(s)) = C_d(p(1)) + (s − 1) C_d,s,      C_d,s = C_d((p(s*) − p(1)) / (s* − 1))

with s* the continued scale farthest from 1 (slopes of two converged states: exact to the preload's
tolerance).  The reduced model carries Φᵀ K_σ,s Φ and Φᵀ C_d,s Φ with the coefficient s − 1
(:mod:`fem_squeal.reduced.affine`); :meth:`PressureTerms.stiffness_at` and :meth:`PressureTerms.damping_at`
assemble the operators from the state continued to s itself (:mod:`fem_squeal.fe.preload_continuation`), not
from the affine formula: the corner checks compare the reduced model with a full CEA at that pressure's own
operators.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from petsc4py import PETSc

from fem_squeal.util.errors import ModelError

#: the scene's own pressure (the scale of its preload, whose operators the linearised model holds)
REFERENCE = 1.0


class PressureTerms:
    """The pressure-dependent operators of the preload states by pressure scale s (``states``: s ↦ a state with
    ``u``, the displacement, and ``pressure``, the contacts' pressures by interface; the scene's s = 1 among
    them).  ``stiffness`` (u ↦ K_σ(u)) and ``damping`` (pressures ↦ C_d), each a new matrix or None where the
    model has no such term.  The slopes :attr:`stiffness_slope`, :attr:`damping_slope` (None without the term)
    and each state's operators (:meth:`stiffness_at`, :meth:`damping_at`, assembled once).  Owns its matrices
    (:meth:`destroy`), not the states."""

    def __init__(self, states: Mapping[float, Any], stiffness: Callable[[PETSc.Vec], PETSc.Mat] | None = None,
                 damping: Callable[[dict], PETSc.Mat] | None = None):
        self.states = {float(s): st for s, st in states.items()}
        if stiffness is None and damping is None:
            raise ModelError("pressure: no operator depends on the pressure (neither the stress stiffening nor "
                             "the friction damping)")
        if REFERENCE not in self.states:
            raise ModelError("pressure: the operators across pressures need the scene's preload state (scale 1)")
        others = [s for s in self.states if s != REFERENCE]
        if not others:
            raise ModelError("pressure: the operators across pressures need a preload state at another "
                             "pressure scale than 1")
        self.stiffness, self.damping = stiffness, damping
        self.far = max(others, key=lambda s: (abs(s - REFERENCE), s))
        a, b, h = self.states[REFERENCE], self.states[self.far], self.far - REFERENCE
        self.stiffness_slope = self.damping_slope = None
        self._stiffness: dict[float, PETSc.Mat] = {}
        self._damping: dict[float, PETSc.Mat] = {}
        if stiffness is not None:
            du = b.u.copy()
            du.axpy(-1.0, a.u)
            du.scale(1.0 / h)
            try:
                self.stiffness_slope = stiffness(du)
            finally:
                du.destroy()
        if damping is not None:
            self.damping_slope = damping({n: (b.pressure[n] - a.pressure[n]) / h for n in a.pressure})

    @property
    def scales(self) -> list[float]:
        """The pressure scales with a state, ascending."""
        return sorted(self.states)

    def _state(self, s: float):
        if s not in self.states:
            raise ModelError(f"pressure: no preload state at {s:g} × loads.pressure (states at "
                             f"{[float(f'{x:g}') for x in self.scales]}); its operators are assembled from "
                             "the state continued to that pressure")
        return self.states[s]

    def stiffness_at(self, scale: float) -> PETSc.Mat:
        """K_σ(u(s)) assembled from the preload state at ``scale`` (kept; a ModelError naming the scales with
        a state when there is none)."""
        s = float(scale)
        if s not in self._stiffness:
            self._stiffness[s] = self.stiffness(self._state(s).u)
        return self._stiffness[s]

    def damping_at(self, scale: float) -> PETSc.Mat:
        """C_d(p(s)) assembled from the contact pressures of the preload state at ``scale`` (kept)."""
        s = float(scale)
        if s not in self._damping:
            self._damping[s] = self.damping(self._state(s).pressure)
        return self._damping[s]

    def destroy(self) -> None:
        for A in (self.stiffness_slope, self.damping_slope, *self._stiffness.values(), *self._damping.values()):
            if A is not None:
                A.destroy()
        self._stiffness.clear()
        self._damping.clear()
