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

from collections.abc import Iterable, Mapping
from typing import NamedTuple

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.hexahedra import dof_coordinates


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
        x = dof_coordinates(V)[:n_owned]
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
        kt = np.outer(self.k, self.theta)
        self.cs = np.concatenate([np.cos(kt), np.sin(kt)])      # (2 (k), node): e^{−ikθ} = cos kθ − i sin kθ
        ones.destroy()
        w.destroy()

    def _cyl(self, v: np.ndarray) -> np.ndarray:
        v = v.reshape(-1, 3)
        return np.stack([self.cos * v[:, 0] + self.sin * v[:, 1],
                         -self.sin * v[:, 0] + self.cos * v[:, 1], v[:, 2]])

    def describe(self, xr: PETSc.Vec, xi: PETSc.Vec | None = None) -> ModeDescriptors:
        """Descriptors of x = xr + i xi (xi None for a real mode)."""
        return self.describe_all([(xr, xi)])[0]

    def describe_all(self, modes: list[tuple[PETSc.Vec, PETSc.Vec | None]]) -> list[ModeDescriptors]:
        """Descriptors of each x = xr + i xi of ``modes`` (xi None for a real mode): M X and M_z X by one
        sparse-times-dense product per block of modes instead of a MatMult per vector, the harmonic
        sums c_{±k} of a block by one dense product."""
        sums, energies = [], []
        for j in range(0, len(modes), BLOCK_MODES):
            X, cols = _dense_block(self.M, modes[j:j + BLOCK_MODES])
            mx, e = _products(self.M, X)
            e_ax = _products(self.Mz, X, keep=False)[1]
            X.destroy()
            # μ = a + ib (a, b: cylindrical components of M xr, M xi; node x (component, mode)) and
            # e^{∓ikθ} = C ∓ iS: c_{±k} m = (C a ± S b) + i (C b ∓ S a), from one real product [C; S] [a b]
            ab = np.zeros((len(self.theta), 2, 3, len(cols)))
            for n, (re, im) in enumerate(cols):
                ab[:, 0, :, n] = self._cyl(mx[:, re]).T
                if im is not None:
                    ab[:, 1, :, n] = self._cyl(mx[:, im]).T
                energies.append((e[re] + (e[im] if im is not None else 0.0),
                                 e_ax[re] + (e_ax[im] if im is not None else 0.0)))
            p = (self.cs @ ab.reshape(len(self.theta), -1)).reshape(2, len(self.k), 2, 3, len(cols))
            (ca, cb), (sa, sb) = p[0].transpose(1, 0, 2, 3), p[1].transpose(1, 0, 2, 3)
            sums.append((ca + sb + 1j * (cb - sa), ca - sb + 1j * (cb + sa)))   # c_{±k} m: (k, comp, mode)
        if not sums:
            return []
        cp = self.comm.allreduce(np.concatenate([c for c, _ in sums], axis=2), op=MPI.SUM) / self.mass
        cm = self.comm.allreduce(np.concatenate([c for _, c in sums], axis=2), op=MPI.SUM) / self.mass
        return [self._summary(cp[:, :, n], cm[:, :, n], e_tot, e_ax) for n, (e_tot, e_ax) in enumerate(energies)]

    def _summary(self, cp: np.ndarray, cm: np.ndarray, e_tot: float, e_ax: float) -> ModeDescriptors:
        pp, pm = (np.abs(cp) ** 2).sum(axis=1), (np.abs(cm) ** 2).sum(axis=1)
        power = self.mass * (pp + pm)
        power[0] = self.mass * pp[0]
        k = int(np.argmax(power))
        tau = 0.0 if k == 0 or pp[k] + pm[k] == 0 else float((pm[k] - pp[k]) / (pm[k] + pp[k]))
        direction = 0 if abs(tau) < 0.5 else int(np.sign(tau))
        share = float(power[k] / e_tot) if e_tot > 0 else 0.0
        return ModeDescriptors(float(1.0 - e_ax / e_tot), k, share, tau, direction)


#: modes per sparse-times-dense product: bounds the dense blocks (3 of n × 2·16 values) at any size
BLOCK_MODES = 16


def _dense_block(A: PETSc.Mat, modes) -> tuple[PETSc.Mat, list[tuple[int, int | None]]]:
    """The owned rows of the vectors of ``modes`` ((xr, xi or None) pairs) as columns of a dense
    matrix, and the column of each mode's real and imaginary part (None for a real mode)."""
    vecs, cols = [], []
    for xr, xi in modes:
        cols.append((len(vecs), None if xi is None else len(vecs) + 1))
        vecs += [xr] if xi is None else [xr, xi]
    n_local, n_global = A.getLocalSize()[1], A.getSize()[1]
    data = np.empty((n_local, len(vecs)), order="F")
    for c, v in enumerate(vecs):
        data[:, c] = v.array_r
    X = PETSc.Mat().createDense(((n_local, n_global), (PETSc.DECIDE, len(vecs))), array=data, comm=A.getComm())
    X.assemble()
    return X, cols


def _products(A: PETSc.Mat, X: PETSc.Mat, keep: bool = True) -> tuple[np.ndarray | None, np.ndarray]:
    """A X (owned rows; None unless ``keep``) and the column energies xᵀ A x (summed over the ranks)."""
    AX = A.matMult(X)
    ax, x = AX.getDenseArray(), X.getDenseArray()
    local = np.einsum("ij,ij->j", x, ax)
    ax = ax.copy() if keep else None
    AX.destroy()
    return ax, A.getComm().tompi4py().allreduce(local, op=MPI.SUM)


def strain_energy_shares(K_parts: dict[str, PETSc.Mat], xr: PETSc.Vec, xi: PETSc.Vec | None = None,
                         groups: dict[str, tuple[str, ...]] | None = None) -> dict[str, float]:
    """Share of each part (or group of parts) in the strain energy of a mode.

    For x = xr + i xi and symmetric part stiffnesses K_p: E_p = xrᵀK_p xr + xiᵀK_p xi (twice the
    time-averaged strain energy of Re(x e^{iωt})); shares are E_p / Σ_q E_q."""
    return strain_energy_shares_all(K_parts, [(xr, xi)], groups)[0]


def strain_energy_shares_all(K_parts: Mapping[str, PETSc.Mat] | Iterable[tuple[str, PETSc.Mat]],
                             modes: list[tuple[PETSc.Vec, PETSc.Vec | None]],
                             groups: dict[str, tuple[str, ...]] | None = None,
                             release: bool = False) -> list[dict[str, float]]:
    """:func:`strain_energy_shares` of each mode, one K_p X product per part and block of modes.  ``K_parts``:
    part -> K_p, or (part, K_p) pairs taken one at a time (:func:`fem_squeal.fe.assembly.part_stiffnesses`),
    each destroyed after its products where ``release``."""
    energies: dict[str, np.ndarray] = {}
    for part, Kp in (K_parts.items() if isinstance(K_parts, Mapping) else K_parts):
        e = []
        for j in range(0, len(modes), BLOCK_MODES):
            X, _ = _dense_block(Kp, modes[j:j + BLOCK_MODES])
            e.append(_products(Kp, X, keep=False)[1])
            X.destroy()
        energies[part] = np.concatenate(e) if e else np.zeros(0)
        if release:
            Kp.destroy()
    out = []
    column = 0
    for _, xi in modes:
        re, im = column, (None if xi is None else column + 1)
        column += 1 if xi is None else 2
        energy = {part: ep[re] + (ep[im] if im is not None else 0.0) for part, ep in energies.items()}
        total = sum(energy.values())
        if groups:
            energy = {g: sum(energy[p] for p in parts if p in energy) for g, parts in groups.items()}
        out.append({k: (float(v / total) if total > 0 else 0.0) for k, v in energy.items()})
    return out
