"""CalculiX's C3D8R: the 8-node hexahedron with one (mean-strain) point and hourglass control.

As CalculiX 2.20 (Debian calculix-ccx, the ``ccx`` of benchmarks/hex_native.py) computes it in a frequency
step (ccx source, github.com/Dhondtguido/CalculiX src/: ``e_c3d.f`` with ``intscheme = 0`` as set in
``arpack.c``; ``shape8hr.f`` as it was before commit 2465dbb; ``hgstiffness.f``; Flanagan & Belytschko,
IJNME 17 (1981) 679-706), for an element of nodes x_a (a = 1..8) and isotropic E, ν, ρ:

- volume and mean-strain operator (``shape8hr.f``, F&B eqs 15-16): V = ∫_e dV and
  b̄_a = (1/V) ∫_e ∇N_a dV = (1/V) ∂V/∂x_a (the exact volume average of the trilinear gradients, not
  their value at the centre);
- stiffness at the one point (``e_c3d.f``, weight 8, xsj = V/8):
  K_(a,i)(b,j) = V [λ b̄_ai b̄_bj + μ (b̄_aj b̄_bi + δ_ij b̄_a·b̄_b)];
- hourglass stiffness (``shape8hr.f``, ``hgstiffness.f``): with the base vectors Γ = [ηζ, ξζ, ξη, ξηζ]
  at the nodes (8 × 4) and z_a the nodes' third coordinates,
  γ_ak = Γ_ak − b̄_a3 Σ_c z_c Γ_ck,  α = 0.0005 V Σ_a |b̄_a|²,  K^hg_(a,i)(b,j) = δ_ij E α Σ_k γ_ak γ_bk
  (``elas(1)`` = E for an isotropic material).  This is the ``shape8hr.f`` of ccx 2.20: its loop resets
  γ_ak = Γ_ak for each coordinate j before subtracting b̄_aj Σ_c x_cj Γ_ck, so only j = 3 stays (F&B
  eq 49 subtracts all three), and its factor is 0.0005 V Σ|b̄|² (the comment says Abaqus uses 0.005).
  So on a cell that is not a parallelepiped it resists fields linear in x or y, every rigid rotation
  among them (weakly: 0.0005), and it depends on which axis is z.  CalculiX's commit 2465dbb
  (2025-10-10) changed both: γ = Γ − b̄ (Xᵀ Γ) and 0.005 V Σ|b̄|² (ten times stiffer hourglass modes);
  that is not what the installed ccx 2.20 runs.  Checked against ccx 2.20's own element matrices
  (``*FREQUENCY, SOLVER=MATRIXSTORAGE``: the .sti/.mas files) on a distorted element to 1.5e-14
  (tests/unit/fe/test_c3d8r.py);
- mass (``e_c3d.f``: the same single point, shape functions 1/8, weight 8, xsj = V/8):
  M_(a,i)(b,j) = δ_ij ρ V / 64 — a rank-one consistent mass per component, not a lumped one, and not
  the 2 × 2 × 2 rule (that is ``intscheme = 1``: the initial acceleration of a dynamic step only).

fem_squeal assembles the UFL forms of K, M (and the axial mass, Rayleigh C, the parts' K and M) with
the cell integrals at quadrature degree 1 (one point at the centre, :data:`ONE_POINT`), which gives
V_c G_cᵀ D G_c and ρ V_c / 64 with G_c = ∇N at the centre and V_c = |det J(centre)| (reference
volume 1): equal to the above where the map is affine.  :func:`corrections` computes, per cell and in
NumPy, the differences to CalculiX's element (mean strain instead of the centre gradient, V instead of
V_c) plus the hourglass stiffness, and :func:`add_cell_matrices` adds them into the assembled PETSc
matrices (owned cells only, ``ADD_VALUES``, Dirichlet rows and columns left out): the same on any
number of ranks.  V and b̄ are integrated with 2 × 2 × 2 Gauss points, exact for them (the integrands'
degree is at most 3 in each reference coordinate).  The other volume forms (rotation, stress stiffening)
keep the 2 × 2 × 2 rule of C3D8.
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

#: UFL quadrature degree of the one-point rule on hexahedra (basix: (degree + 2) // 2 = 1 point per axis).
ONE_POINT = 1
#: CalculiX 2.20's hourglass factor (``shape8hr.f``: ``a=0.0005d0*a/vol``).
HOURGLASS_FACTOR = 0.0005
#: reference coordinates in [-1, 1]³ of the Q1 hexahedron's nodes in dolfinx/basix order (lexicographic).
NODES = np.array([[2 * (k & 1) - 1, 2 * ((k >> 1) & 1) - 1, 2 * ((k >> 2) & 1) - 1] for k in range(8)], float)
#: Flanagan-Belytschko hourglass base vectors at the nodes: ηζ, ξζ, ξη, ξηζ (8 × 4).
GAMMA = np.stack([NODES[:, 1] * NODES[:, 2], NODES[:, 0] * NODES[:, 2], NODES[:, 0] * NODES[:, 1],
                  NODES.prod(axis=1)], axis=1)


def _reference_gradients(xi: np.ndarray) -> np.ndarray:
    """∂N_a/∂ξ_d of the trilinear shape functions N_a = Π (1 + ξ_d ξ_ad)/8 at points ``xi`` (p, 3): (p, 8, 3)."""
    f = 1.0 + xi[:, None, :] * NODES[None, :, :]          # (p, 8, 3)
    out = np.empty_like(f)
    for d in range(3):
        others = [e for e in range(3) if e != d]
        out[:, :, d] = NODES[None, :, d] * f[:, :, others[0]] * f[:, :, others[1]] / 8.0
    return out


def _gradients(X: np.ndarray, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """det J (m, p) and physical gradients ∇N_a (m, p, 8, 3) of cells with nodes X (m, 8, 3) at ``xi``."""
    dN = _reference_gradients(xi)                          # (p, 8, 3)
    J = np.einsum("mai,pad->mpid", X, dN)                  # J_id = ∂x_i/∂ξ_d
    Jinv = np.linalg.inv(J)                                # (m, p, 3(d), 3(i))
    return np.linalg.det(J), np.einsum("pad,mpdi->mpai", dN, Jinv)


def mean_strain(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Volumes V (m,) and mean gradients b̄ (m, 8, 3) = (1/V) ∫ ∇N dV of hexahedra X (m, 8, 3)."""
    g = np.array(np.meshgrid(*[[-1 / np.sqrt(3), 1 / np.sqrt(3)]] * 3, indexing="ij")).reshape(3, -1).T
    det, G = _gradients(X, g)
    V = det.sum(axis=1)
    return np.abs(V), np.einsum("mp,mpai->mai", det, G) / V[:, None, None]


def centre_gradients(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What UFL's one-point rule integrates with: V_c = 8 |det J(0)| (m,) and ∇N at the centre (m, 8, 3)."""
    det, G = _gradients(X, np.zeros((1, 3)))
    return 8.0 * np.abs(det[:, 0]), G[:, 0]


def isotropic_stiffness(V: np.ndarray, B: np.ndarray, lam: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """(m, 24, 24), DOF 3a + i: V [λ B_ai B_bj + μ (B_aj B_bi + δ_ij B_a·B_b)] (``e_c3d.f``, mattyp 1)."""
    k = (lam[:, None, None, None, None] * np.einsum("mai,mbj->maibj", B, B)
         + mu[:, None, None, None, None] * (np.einsum("maj,mbi->maibj", B, B)
                                            + np.einsum("mab,ij->maibj", np.einsum("mak,mbk->mab", B, B),
                                                        np.eye(3))))
    return (V[:, None, None, None, None] * k).reshape(-1, 24, 24)


def hourglass_vectors(X: np.ndarray, V: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """γ_ak = Γ_ak − b̄_a3 Σ_c z_c Γ_ck (m, 8, 4) and α = 0.0005 V Σ_a |b̄_a|² (m,) (ccx 2.20 ``shape8hr.f``)."""
    gamma = GAMMA[None] - np.einsum("ma,mb,bk->mak", B[:, :, 2], X[:, :, 2], GAMMA)
    return gamma, HOURGLASS_FACTOR * V * np.einsum("mai,mai->m", B, B)


def hourglass_stiffness(X: np.ndarray, E: np.ndarray) -> np.ndarray:
    """K^hg (m, 24, 24): δ_ij E α Σ_k γ_ak γ_bk (``hgstiffness.f``)."""
    V, B = mean_strain(X)
    gamma, alpha = hourglass_vectors(X, V, B)
    s = (E * alpha)[:, None, None] * np.einsum("mak,mbk->mab", gamma, gamma)
    return np.einsum("mab,ij->maibj", s, np.eye(3)).reshape(-1, 24, 24)


def element_stiffness(X: np.ndarray, E: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """CalculiX's C3D8R stiffness (m, 24, 24): mean strain at one point plus hourglass stiffness."""
    lam, mu = lame(E, nu)
    V, B = mean_strain(X)
    return isotropic_stiffness(V, B, lam, mu) + hourglass_stiffness(X, E)


def element_mass(X: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """CalculiX's C3D8R scalar mass (m, 8, 8): ρ V / 64 in every entry (one point, N_a = 1/8)."""
    V, _ = mean_strain(X)
    return np.broadcast_to((rho * V / 64.0)[:, None, None], (len(X), 8, 8)).copy()


def lame(E: np.ndarray, nu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def corrections(X: np.ndarray, E: np.ndarray, nu: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ΔK (m, 24, 24), ΔM scalar (m, 8, 8)): CalculiX's C3D8R element minus UFL's one-point forms
    (centre gradient, V_c): the hourglass stiffness plus the mean-strain and volume differences."""
    lam, mu = lame(E, nu)
    V, B = mean_strain(X)
    Vc, Gc = centre_gradients(X)
    dK = isotropic_stiffness(V, B, lam, mu) - isotropic_stiffness(Vc, Gc, lam, mu) + hourglass_stiffness(X, E)
    dM = np.broadcast_to((rho * (V - Vc) / 64.0)[:, None, None], (len(X), 8, 8)).copy()
    return dK, dM


def cell_dofs(V) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(owned cells' nodal coordinates (m, 8, 3), their global unrolled DOFs (m, 24), 3a + i, their local
    blocked DOFs (m, 8)) of a Q1 vector space V."""
    dm = V.dofmap
    m = V.mesh.topology.index_map(3).size_local
    blocks = dm.list.array.reshape(-1, 8)[:m]
    X = V.tabulate_dof_coordinates()[blocks]
    bs = dm.index_map_bs
    glob = dm.index_map.local_to_global(blocks.ravel()).reshape(m, 8)
    return X, (glob[:, :, None] * bs + np.arange(bs)).reshape(m, 8 * bs), blocks


def add_cell_matrices(A: PETSc.Mat, V, cells: np.ndarray, Ae: np.ndarray, bc_dofs: np.ndarray) -> None:
    """A += Σ over owned ``cells`` of the element matrices ``Ae`` (len(cells), 24, 24) on V's DOFs,
    leaving out the rows and columns of the (local, unrolled) ``bc_dofs``; assembles A.  Element DOFs
    whose row and column are zero in every ``Ae`` (the x, y components of the axial mass) are not sent:
    PETSc keeps zero diagonal entries even when told to ignore zeros, and A's pattern may lack them."""
    _, glob, blocks = cell_dofs(V)
    bs = V.dofmap.index_map_bs
    local = (blocks[:, :, None] * bs + np.arange(bs)).reshape(len(blocks), -1)
    rows = np.where(np.isin(local, bc_dofs), -1, glob).astype(PETSc.IntType)
    used = np.flatnonzero(np.any(Ae != 0, axis=(0, 1)) | np.any(Ae != 0, axis=(0, 2)))
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    A.setOption(PETSc.Mat.Option.IGNORE_ZERO_ENTRIES, True)
    for c, Ke in zip(cells.tolist(), Ae[:, used][:, :, used]):
        A.setValues(rows[c, used], rows[c, used], Ke, addv=PETSc.InsertMode.ADD_VALUES)
    A.assemble()
    A.setOption(PETSc.Mat.Option.IGNORE_ZERO_ENTRIES, False)


def vector_mass(dM: np.ndarray, W: np.ndarray) -> np.ndarray:
    """(m, 24, 24): the scalar mass ``dM`` (m, 8, 8) ⊗ the 3 × 3 weight W (I: M; a aᵀ: the axial mass)."""
    return np.einsum("mab,ij->maibj", dM, W).reshape(-1, 24, 24)
