"""Penalty stiffness against the stiffness of the bodies it couples (a conditioning diagnostic).

A penalty layer k_n [N/m³] on a face is a spring in series with the layer of elements under it,
whose normal stiffness per unit area is about C₁₁/h (h the element size, C₁₁ the constrained
modulus E(1−ν)/((1+ν)(1−2ν)) of an isotropic material, the largest normal entry of the Voigt
stiffness otherwise).  Their ratio

    r = k_n h / C₁₁

says what the penalty does:

* r ≪ 1: a compliant layer (the physical contact stiffness of a lining: r ≈ 0.1–1 in the brake);
* r ≫ 1: a constraint.  The interface's share of the series compliance is 1/(1 + r), so raising
  k_n further changes the eigenvalues by O(1/r), while the condition number of K grows ∝ r
  (the penalty block dominates ‖K‖ and the smallest eigenvalues stay) and with it the round-off of
  the factorisation, ε·κ.

:data:`WARN_RATIO` = 1e3: past it the contact is rigid to 0.1 % and more k_n only costs accuracy
(``benchmarks/stress_penalty.py`` measures it on the ring).  The ratio uses the median h of the
cells on the face and, for a face pair, the larger ratio of the two sides.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from petsc4py import PETSc

from geometry.quality import longest_edge

WARN_RATIO = 1e3
#: the edges of a dolfinx hexahedron (vertices (0,0,0), (1,0,0), (0,1,0), (1,1,0), then z = 1 likewise)
_HEX_EDGES = [(0, 1), (0, 2), (1, 3), (2, 3), (4, 5), (4, 6), (5, 7), (6, 7), (0, 4), (1, 5), (2, 6), (3, 7)]


class PenaltyRatio(NamedTuple):
    name: str          # scene key: interfaces.<name> or boundary.ground_springs[i]
    kn: float          # penalty [N/m³]
    body: float        # C₁₁/h of the stiffer-relative side [N/m³]
    ratio: float       # k_n / body
    h: float           # median cell size on that face [m]

    def as_dict(self) -> dict:
        return self._asdict()


def _face_cells(mesh_data, face: str) -> np.ndarray:
    """The local cell under each owned facet of ``face``."""
    mesh, ft = mesh_data.mesh, mesh_data.facet_tags
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    f2c = mesh.topology.connectivity(tdim - 1, tdim)
    n_owned = mesh.topology.index_map(tdim - 1).size_local
    facets = ft.indices[(ft.values == mesh_data.faces[face]) & (ft.indices < n_owned)]
    return np.array([f2c.links(f)[0] for f in facets], dtype=np.int32)


def cell_size(mesh, cells: np.ndarray) -> np.ndarray:
    """Longest edge of each tetrahedron (its corner nodes: the first four geometry nodes, also
    for a curved P2 geometry), or of each hexahedron (its first eight, dolfinx's vertex order).
    ``dolfinx.cpp.mesh.h`` does not accept the Python mesh in 0.5.2."""

    dm = mesh.geometry.dofmap
    if mesh.ufl_cell().cellname() == "hexahedron":   # the native path: the 12 edges of the 8 corners
        corners = np.array([dm.links(c)[:8] for c in cells], dtype=np.int64).reshape(-1, 8)
        x = mesh.geometry.x[corners]
        return np.max([np.linalg.norm(x[:, a] - x[:, b], axis=1) for a, b in _HEX_EDGES], axis=0,
                      initial=0.0) if len(cells) else np.zeros(0)
    corners = np.array([dm.links(c)[:4] for c in cells], dtype=np.int64).reshape(-1, 4)
    return longest_edge(mesh.geometry.x[corners])


def face_stiffness(mesh_data, spec, face: str) -> tuple[float, float]:
    """(median over the face of C₁₁/h of the cell under each facet, median h), over all ranks."""
    mesh = mesh_data.mesh
    cells = _face_cells(mesh_data, face)
    modulus = {mesh_data.volumes[p]: float(np.max(np.diag(m.voigt_stiffness())[:3]))
               for p, m in spec.materials.items()}
    ct = mesh_data.cell_tags
    tag_of = np.full(mesh.topology.index_map(3).size_local + mesh.topology.index_map(3).num_ghosts, -1)
    tag_of[ct.indices] = ct.values
    hs = cell_size(mesh, cells)
    c11 = np.array([modulus.get(int(t), np.nan) for t in tag_of[cells]])
    pairs = mesh.comm.allgather((c11 / np.maximum(hs, 1e-300), hs))
    stiff = np.concatenate([p[0] for p in pairs])
    hs = np.concatenate([p[1] for p in pairs])
    if not len(stiff) or np.isnan(stiff).all():
        return float("nan"), float("nan")
    return float(np.nanmedian(stiff)), float(np.median(hs))


def penalty_ratios(mesh_data, spec) -> list[PenaltyRatio]:
    """r = k_n h / C₁₁ (module docstring) of every rigid plate, interface and ground spring."""
    out = []
    items = [(f"rigid plate on {p.face!r}", p.kn, (p.face,)) for p in spec.plates if p.kn > 0]
    items += [(f"interfaces.{it.name}", it.kn, (it.slave, it.master)) for it in spec.interfaces]
    items += [(f"boundary.ground_springs[{i}]", max(g.k_axial, g.k_transverse), (g.face,))
              for i, g in enumerate(spec.ground_springs)]
    for name, kn, faces in items:
        sides = [face_stiffness(mesh_data, spec, f) for f in faces if f in mesh_data.faces]
        sides = [s for s in sides if np.isfinite(s[0])]
        if not sides:
            continue
        body, h = min(sides)          # the softer side gives the larger ratio
        out.append(PenaltyRatio(name, float(kn), body, float(kn) / body, h))
    return out


def penalty_warnings(ratios: list[PenaltyRatio], warn_ratio: float = WARN_RATIO) -> list[str]:
    """A message for each penalty more than ``warn_ratio`` times the stiffness of its bodies."""
    return [f"{r.name}: kn = {r.kn:.3g} N/m³ is {r.ratio:.3g}× the normal stiffness C11/h = {r.body:.3g} N/m³ "
            f"of the elements under it (h = {r.h:.3g} m): the contact is already rigid to {100 / r.ratio:.2g} %, "
            f"and a larger kn only multiplies the condition number of K (round-off in the eigensolve); "
            f"kn ≈ {100 * r.body:.2g} N/m³ (ratio 100) gives the same physics to 1 %"
            for r in ratios if r.ratio > warn_ratio]


def condition_number_1(A, *, solver: str = "mumps", max_iterations: int = 5) -> float:
    """Estimate of κ₁(A) = ‖A‖₁ ‖A⁻¹‖₁ for a distributed PETSc matrix: Hager's (Higham's LAPACK
    xLACON) 1-norm estimator of A⁻¹, a lower bound that is usually within a factor of 3, from at
    most 2·``max_iterations`` solves with one LU factorisation (A⁻¹ and A⁻ᵀ)."""

    ksp = PETSc.KSP().create(A.getComm())
    try:
        ksp.setOperators(A)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType(solver)
        ksp.setUp()
        n = A.getSize()[0]
        x, y, z = A.createVecRight(), A.createVecRight(), A.createVecRight()
        x.set(1.0 / n)
        est, last = 0.0, -1
        for _ in range(max_iterations):
            ksp.solve(x, y)
            est = y.norm(PETSc.NormType.NORM_1)
            xi = y.duplicate()
            xi.setArray(np.where(y.getArray() >= 0, 1.0, -1.0))
            ksp.solveTranspose(xi, z)
            j, zmax = z.max() if abs(z.max()[1]) >= abs(z.min()[1]) else z.min()
            xi.destroy()
            if abs(zmax) <= z.dot(x) or j == last:
                break
            x.set(0.0)
            x.setValue(j, 1.0)
            x.assemble()
            last = j
        for v in (x, y, z):
            v.destroy()
        return float(A.norm(PETSc.NormType.NORM_1) * est)
    finally:
        ksp.destroy()
