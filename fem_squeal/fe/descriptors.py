"""Mode descriptors: in-plane kinetic-energy share, nodal diameters, travelling-wave direction.

For a (complex) mode x with x^H M x = 1 and the rotation axis z:

* in-plane share  = 1 − x^H M_z x, with M_z the mass of the axial motion;
* circumferential content: c_k = (1/m) Σ_n e^{−ikθ_n} (M x)_n per cylindrical component
  (≈ (1/m)∫ρ x e^{−ikθ} dV, m the total mass); the nodal share of harmonic k is
  m(|c_k|² + |c_−k|²) summed over components, and the nodal-diameter number is its argmax.
  The nodal share is a projection on the radially and axially *uniform* harmonic e^{ikθ}, not a
  kinetic-energy share: by Cauchy–Schwarz it is at most the energy share of harmonic k, with
  equality only for an amplitude uniform over radius and thickness.  A pure k-diameter plate
  mode, whose amplitude grows with the radius, gives about 0.70; a thin ring's mode about 1.
  Use it to rank the harmonics of one mode, not as an energy fraction;
* travelling index τ = (|c_−k|² − |c_k|²)/(|c_−k|² + |c_k|²) of the dominant k: the response
  Re(x e^{iωt}), ω > 0, has a part c_k e^{i(kθ+ωt)} running towards −θ and c_−k e^{i(−kθ+ωt)}
  running towards +θ.  τ = +1 is a pure forward (+θ) wave, 0 a standing wave.
All sums are over owned DOFs and reduced over MPI, so they do not depend on the partition.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


class ModeDescriptors(NamedTuple):
    in_plane_share: float
    nodal_diameter: int
    nodal_share: float          # m(|c_k|²+|c_−k|²): projection on the uniform harmonic ±k (not an energy share)
    travelling_index: float     # τ in [−1, 1]
    travelling_direction: int   # +1 forward (+θ), −1 backward, 0 standing (|τ| < 0.5)


class CircumferentialBasis:
    """Angles of the owned nodes and the total mass, built once per function space."""

    def __init__(self, V, M: PETSc.Mat, M_axial: PETSc.Mat, kmax: int = 24):
        n_owned = V.dofmap.index_map.size_local
        x = V.tabulate_dof_coordinates()[:n_owned]
        self.theta = np.arctan2(x[:, 1], x[:, 0])
        self.cos, self.sin = np.cos(self.theta), np.sin(self.theta)
        self.M, self.Mz, self.kmax = M, M_axial, kmax
        self.comm = V.mesh.comm
        ones = M.createVecRight()
        ones.array.reshape(-1, 3)[:, 0] = 1.0
        w = ones.duplicate()
        M.mult(ones, w)
        self.mass = w.sum()  # 1ᵀ M 1 over the x component = total mass (0 rows of clamped DOFs aside)
        self.k = np.arange(0, kmax + 1)
        self.phase = np.exp(-1j * np.outer(self.k, self.theta))  # (k, node)
        ones.destroy()
        w.destroy()

    def _cyl(self, v: np.ndarray) -> np.ndarray:
        v = v.reshape(-1, 3)
        return np.stack([self.cos * v[:, 0] + self.sin * v[:, 1],
                         -self.sin * v[:, 0] + self.cos * v[:, 1], v[:, 2]])

    def describe(self, xr: PETSc.Vec, xi: PETSc.Vec | None = None) -> ModeDescriptors:
        """Descriptors of x = xr + i xi (xi None for a real mode)."""
        t = xr.duplicate()
        self.M.mult(xr, t)
        mxr = self._cyl(t.array)
        e_tot = xr.dot(t)
        self.Mz.mult(xr, t)
        e_ax = xr.dot(t)
        if xi is not None:
            self.M.mult(xi, t)
            mxi = self._cyl(t.array)
            e_tot += xi.dot(t)
            self.Mz.mult(xi, t)
            e_ax += xi.dot(t)
        else:
            mxi = np.zeros_like(mxr)
        t.destroy()
        mu = mxr + 1j * mxi                          # (component, node)
        cp = self.phase @ mu.T                        # c_{+k} * m, (k, component)
        cm = np.conj(self.phase) @ mu.T               # c_{−k} * m
        cp = self.comm.allreduce(cp, op=MPI.SUM) / self.mass
        cm = self.comm.allreduce(cm, op=MPI.SUM) / self.mass
        pp, pm = (np.abs(cp) ** 2).sum(axis=1), (np.abs(cm) ** 2).sum(axis=1)
        power = self.mass * (pp + pm)
        power[0] = self.mass * pp[0]
        k = int(np.argmax(power))
        tau = 0.0 if k == 0 or pp[k] + pm[k] == 0 else float((pm[k] - pp[k]) / (pm[k] + pp[k]))
        direction = 0 if abs(tau) < 0.5 else int(np.sign(tau))
        share = float(power[k] / e_tot) if e_tot > 0 else 0.0
        return ModeDescriptors(float(1.0 - e_ax / e_tot), k, share, tau, direction)


def strain_energy_shares(K_parts: dict[str, PETSc.Mat], xr: PETSc.Vec, xi: PETSc.Vec | None = None,
                         groups: dict[str, tuple[str, ...]] | None = None) -> dict[str, float]:
    """Share of each part (or group of parts) in the strain energy of a mode.

    For x = xr + i xi and symmetric part stiffnesses K_p: E_p = xrᵀK_p xr + xiᵀK_p xi (twice the
    time-averaged strain energy of Re(x e^{iωt})); shares are E_p / Σ_q E_q."""
    t = xr.duplicate()
    energy = {}
    for part, Kp in K_parts.items():
        Kp.mult(xr, t)
        e = xr.dot(t)
        if xi is not None:
            Kp.mult(xi, t)
            e += xi.dot(t)
        energy[part] = e
    t.destroy()
    total = sum(energy.values())
    if groups:
        energy = {g: sum(energy[p] for p in parts if p in energy) for g, parts in groups.items()}
    return {k: (float(v / total) if total > 0 else 0.0) for k, v in energy.items()}
