"""Interface operator G between two deformable surfaces (segment-to-segment penalty).

Seed 001 eq. 4 couples the contact nodes of disc and pad with springs k and friction terms ±μk.
On non-matching P2 meshes the same operator is built at quadrature points of the *slave*
(lining) surface: each point x_q is projected onto the *master* (disc) surface, and both sides'
basis functions are evaluated there.  With n the master's outward normal at the projection
(pointing towards the slave), t₁ the sliding direction s projected on the tangent plane and
t₂ = n × t₁, the rows of

    (G_d u)_q = d_q · (u_slave(x_q) − u_master(π(x_q))),    d ∈ {n, t₁, t₂},

are the relative displacements at point q.  With area weights w_q (Σ_q w_q = slave area):

    K_c = G_nᵀ diag(k_n w) G_n                 (symmetric, positive semidefinite)
          + G_t₂ᵀ diag(k_t w) G_t₂              (tangential penalty across the sliding direction)
    K_f = μ G_sᵀ diag(k_n w) G_n               (asymmetric friction stiffness)

enter M ü + (K + K_c + K_f) u = 0.  Sign: a closing gap g = (x_s − x_m)·n < 0 raises the
pressure by −k_n g; the friction force on the slave is μ p s with s the velocity of the master
relative to the slave (the disc drags the pad), giving +μ k_n G_sᵀG_n in the operator.
The tangential penalty k_t (0 by default, the seed 001 model) is the elastic slip of the
industrial codes' friction laws: sliding, the force along s is μ p (no stiffness), across it a
spring k_t on the relative displacement along t₂ (closed points only, like k_n).
Nodal lumping would be wrong for P2 triangles (their vertex weights vanish), hence quadrature.

Rows are owned by the rank that owns the slave facet (ghost facets are skipped); master facets
near the slave surface are gathered on every rank, so pairs whose two sides live on different
ranks need no special case.
"""
from __future__ import annotations

from typing import NamedTuple

import basix
import numpy as np
import scipy.sparse as sp
from ffcx.element_interface import create_element
from mpi4py import MPI
from petsc4py import PETSc
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from fem_squeal.util.errors import ModelError

# Reference tetrahedron (basix): facet i is opposite vertex i.
_REF_VERTICES = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
_REF_FACETS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
_REF_NORMALS = np.array([[1.0, 1, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]]) / np.array([[3 ** 0.5], [1], [1], [1]])


class RefCell(NamedTuple):
    """A reference cell's vertices, facets (basix order), outward facet normals and facet type.  A
    facet point is v₀ + ξ₁(v₁ − v₀) + ξ₂(v₂ − v₀): ξ in the triangle ξ ≥ 0, ξ₁ + ξ₂ ≤ 1, or, for the
    quadrilaterals of the hexahedron (v₃ = v₁ + v₂ − v₀ in basix's order), in the square [0, 1]²."""

    vertices: np.ndarray
    facets: np.ndarray
    normals: np.ndarray
    facet: basix.CellType


TETRAHEDRON = RefCell(_REF_VERTICES, _REF_FACETS, _REF_NORMALS, basix.CellType.triangle)
HEXAHEDRON = RefCell(np.array(basix.geometry(basix.CellType.hexahedron), dtype=float),
                     np.array(basix.topology(basix.CellType.hexahedron)[2]),
                     np.array([[0.0, 0, -1], [0, -1, 0], [-1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]),
                     basix.CellType.quadrilateral)


def reference_cell(mesh) -> RefCell:
    """The :class:`RefCell` of a tetrahedral or (native path) hexahedral mesh."""
    return HEXAHEDRON if mesh.ufl_cell().cellname() == "hexahedron" else TETRAHEDRON


class SurfacePoints(NamedTuple):
    """Quadrature points on a set of boundary facets (rank-local)."""

    cells: np.ndarray    # (n,) local cell of each point
    ref: np.ndarray      # (n, 3) reference coordinates in that cell
    x: np.ndarray        # (n, 3) physical coordinates
    weight: np.ndarray   # (n,) area weights
    normal: np.ndarray   # (n, 3) outward unit normal of the body


class InterfaceOperator(NamedTuple):
    """G of one slave/master pair: three PETSc matrices with one row per slave quadrature point.

    Every array is rank-local, row-aligned with the locally owned rows of ``Gn``."""

    Gn: PETSc.Mat        # normal relative displacement
    Gt1: PETSc.Mat       # along t₁ (the sliding direction on the tangent plane)
    Gt2: PETSc.Mat       # along t₂ = n × t₁
    B: sp.csr_matrix     # slave-side scalar basis values φ_i(x_q), local rows, global scalar DOFs
    weight: np.ndarray   # area weights w_q
    gap0: np.ndarray     # initial normal gap (x_s − x_m)·n, > 0 open
    x: np.ndarray        # slave points
    normal: np.ndarray   # master normal n at the projections
    t1: np.ndarray       # tangent t₁
    n_global: int        # number of points over all ranks
    n_remote: int = 0    # points (all ranks) whose master facet lives on another rank

    def area(self, comm: MPI.Comm) -> float:
        return comm.allreduce(float(self.weight.sum()), op=MPI.SUM)

    def destroy(self) -> None:
        for m in (self.Gn, self.Gt1, self.Gt2):
            m.destroy()


def lagrange_element(degree: int, cell: basix.CellType = basix.CellType.tetrahedron
                     ) -> basix.finite_element.FiniteElement:
    """The scalar Lagrange element dolfinx 0.5.2 uses on tetrahedra (gll_warped variant), or on ``cell``."""
    return basix.create_element(basix.ElementFamily.P, cell, degree, basix.LagrangeVariant.gll_warped)


def coordinate_element(mesh) -> basix.finite_element.FiniteElement:
    """The mesh's scalar coordinate element (Lagrange of the geometry's degree on its cell)."""
    cell = basix.CellType.hexahedron if reference_cell(mesh) is HEXAHEDRON else basix.CellType.tetrahedron
    return lagrange_element(mesh.geometry.cmap.degree, cell)


def _basis_values(V, X: np.ndarray) -> np.ndarray:
    """(len(X), ndofs) values of V's scalar basis at reference points X: P_k on tetrahedra (as
    always); on hexahedra the element FFCx compiles (serendipity S2 or Q_k; at degree <= 2 one DOF
    per edge and face, so no DOF transformation)."""
    if reference_cell(V.mesh) is TETRAHEDRON:
        el = lagrange_element(V.ufl_element().degree())
        return el.tabulate(0, X)[0, :, :, 0] if len(X) else np.zeros((0, el.dim))
    el = create_element(V.ufl_element().sub_elements()[0])
    return np.asarray(el.tabulate(0, X))[0] if len(X) else np.zeros((0, el.dim))


def _facet_map(lf: np.ndarray, xi: np.ndarray, ref: RefCell = TETRAHEDRON) -> np.ndarray:
    """Reference-cell coordinates of the point ξ of reference facet ``lf`` (vectorised)."""
    v = ref.vertices[ref.facets[lf]]                    # (n, 3 or 4 vertices, 3)
    return v[:, 0] + xi[:, :1] * (v[:, 1] - v[:, 0]) + xi[:, 1:2] * (v[:, 2] - v[:, 0])


def _geometry(cmap_el, X: np.ndarray, gx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Physical points x(X) and Jacobians dx/dX (n, 3, 3) for cells with nodes gx (n, nn, 3)."""
    tab = cmap_el.tabulate(1, X)[:, :, :, 0]            # (4, n, nn)
    x = np.einsum("nk,nkc->nc", tab[0], gx)
    J = np.einsum("dnk,nkc->ncd", tab[1:], gx)         # J[n, c, d] = dx_c/dX_d
    return x, J


def _outward_normal(J: np.ndarray, lf: np.ndarray, ref: RefCell = TETRAHEDRON) -> np.ndarray:
    n = np.linalg.solve(np.transpose(J, (0, 2, 1)), ref.normals[lf][:, :, None])[:, :, 0]
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _cell_geometry(mesh) -> np.ndarray:
    nn = mesh.geometry.dofmap.links(0).size if mesh.topology.index_map(3).size_local else 0
    gdofs = mesh.geometry.dofmap.array.reshape(-1, nn) if nn else np.zeros((0, 1), dtype=np.int32)
    return gdofs


def _local_facets(mesh, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cell, local facet index) of boundary facets."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    mesh.topology.create_connectivity(tdim, tdim - 1)
    f2c, c2f = mesh.topology.connectivity(tdim - 1, tdim), mesh.topology.connectivity(tdim, tdim - 1)
    cells = np.array([f2c.links(f)[0] for f in facets], dtype=np.int32)
    lf = np.array([int(np.flatnonzero(c2f.links(c) == f)[0]) for c, f in zip(cells, facets)], dtype=np.int32)
    return cells, lf


def surface_points(mesh, facets: np.ndarray, degree: int = 4) -> SurfacePoints:
    """Quadrature points of degree ``degree`` on boundary ``facets`` of a (curved) tetrahedral mesh
    (or hexahedral: quadrilateral facets).

    w_q = ŵ_q |J t_a × J t_b| with t_a, t_b the edge vectors of the reference facet, so Σ w_q
    is the (curved) area exactly for the geometry's polynomial degree."""
    ref = reference_cell(mesh)
    cmap_el = coordinate_element(mesh)
    qp, qw = basix.make_quadrature(basix.QuadratureType.Default, ref.facet, degree)
    cells, lf = _local_facets(mesh, np.asarray(facets, dtype=np.int32))
    nq = len(qw)
    cells_q, lf_q = np.repeat(cells, nq), np.repeat(lf, nq)
    X = _facet_map(lf_q, np.tile(qp, (len(cells), 1)), ref)
    gx = mesh.geometry.x[_cell_geometry(mesh)[cells_q]]
    x, J = _geometry(cmap_el, X, gx)
    v = ref.vertices[ref.facets[lf_q]]
    ta = np.einsum("ncd,nd->nc", J, v[:, 1] - v[:, 0])
    tb = np.einsum("ncd,nd->nc", J, v[:, 2] - v[:, 0])
    w = np.tile(qw, len(cells)) * np.linalg.norm(np.cross(ta, tb), axis=1)
    return SurfacePoints(cells_q, X, x, w, _outward_normal(J, lf_q, ref))


class MasterSurface(NamedTuple):
    """Facets of the master surface gathered from all ranks (geometry and global DOF blocks)."""

    gx: np.ndarray       # (F, nn, 3) geometry nodes of the facet's cell
    lf: np.ndarray       # (F,) local facet index
    dofs: np.ndarray     # (F, ndofs) global DOF blocks of the cell
    centroid: np.ndarray  # (F, 3)
    rank: np.ndarray     # (F,) rank that owns the facet


def _gather_master(V, facets: np.ndarray, bbox: tuple[np.ndarray, np.ndarray] | None) -> MasterSurface:
    mesh = V.mesh
    cells, lf = _local_facets(mesh, np.asarray(facets, dtype=np.int32))
    gx = mesh.geometry.x[_cell_geometry(mesh)[cells]] if len(cells) else np.zeros((0, 1, 3))
    nd = V.dofmap.dof_layout.num_dofs
    local = V.dofmap.list.array.reshape(-1, nd)[cells]
    dofs = V.dofmap.index_map.local_to_global(local.ravel()).reshape(-1, nd) if len(cells) else \
        np.zeros((0, nd), dtype=np.int64)
    if len(cells):
        ref = reference_cell(mesh)
        vx = gx[:, :len(ref.vertices)][np.arange(len(cells))[:, None], ref.facets[lf]]     # facet vertices
        centroid = vx.mean(axis=1)
        if bbox is not None:
            lo, hi = bbox
            keep = np.all((vx.max(axis=1) >= lo) & (vx.min(axis=1) <= hi), axis=1)
            gx, lf, dofs, centroid = gx[keep], lf[keep], dofs[keep], centroid[keep]
    else:
        centroid = np.zeros((0, 3))
    comm = mesh.comm
    parts = comm.allgather((gx, lf, dofs, centroid, np.full(len(lf), comm.rank)))
    nn = max(p[0].shape[1] for p in parts)
    parts = [p for p in parts if len(p[1])]
    if not parts:
        return MasterSurface(np.zeros((0, nn, 3)), np.zeros(0, np.int32), np.zeros((0, nd), np.int64),
                             np.zeros((0, 3)), np.zeros(0, int))
    return MasterSurface(*(np.concatenate([p[i] for p in parts]) for i in range(5)))


def project(points: np.ndarray, master: MasterSurface, cmap_el, *, candidates: int = 8,
            iterations: int = 12, ref: RefCell = TETRAHEDRON
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest-point projection of ``points`` onto the curved master facets.

    Projected Gauss–Newton on each of the nearest ``candidates`` facets (by centroid), in the
    facet's reference coordinates ξ ∈ {ξ ≥ 0, ξ₁ + ξ₂ ≤ 1} (quadrilaterals: [0, 1]²); the nearest
    result wins.  Returns
    (facet index, reference coordinates in the master cell, projected point, outward normal)."""
    n = len(points)
    F = len(master.lf)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
    if F == 0:
        raise ModelError("interfaces: the master surface has no facets near the slave surface")
    k = min(candidates, F)
    _, idx = cKDTree(master.centroid).query(points, k=k)
    idx = idx.reshape(n, k)
    pts = np.repeat(points, k, axis=0)
    fac = idx.ravel()
    lf, gx = master.lf[fac], master.gx[fac]
    v = ref.vertices[ref.facets[lf]]
    T = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]], axis=2)     # (m, 3, 2) dX/dξ
    square = ref.facet == basix.CellType.quadrilateral
    xi = np.full((len(fac), 2), 0.5 if square else 1.0 / 3.0)
    for _ in range(iterations):
        X = _facet_map(lf, xi, ref)
        x, J = _geometry(cmap_el, X, gx)
        Jx = J @ T                                                    # (m, 3, 2)
        r = x - pts
        H = np.transpose(Jx, (0, 2, 1)) @ Jx
        g = np.einsum("mcd,mc->md", Jx, r)
        dxi = -np.linalg.solve(H, g[:, :, None])[:, :, 0]
        if square:
            xi = np.clip(xi + dxi, 0.0, 1.0)
        else:
            xi = np.clip(xi + dxi, 0.0, None)
            s = xi.sum(axis=1)
            over = s > 1.0
            xi[over] /= s[over, None]
        if np.max(np.abs(dxi)) < 1e-13:
            break
    X = _facet_map(lf, xi, ref)
    x, J = _geometry(cmap_el, X, gx)
    d = np.linalg.norm(x - pts, axis=1).reshape(n, k)
    best = np.argmin(d, axis=1)
    sel = np.arange(n) * k + best
    return fac[sel], X[sel], x[sel], _outward_normal(J[sel], lf[sel], ref)


def tangent_frame(x: np.ndarray, n: np.ndarray, sliding: float,
                  axis=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """t₁ = the sliding direction s = sliding·e_θ(x) projected on the plane ⊥ n, t₂ = n × t₁.

    Where s is (nearly) parallel to n, any unit vector ⊥ n is used (only springs use it then)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    etheta = np.cross(a, x - np.outer(x @ a, a))
    s = (sliding if sliding != 0 else 1.0) * etheta
    t1 = s - np.einsum("nc,nc->n", s, n)[:, None] * n
    norm = np.linalg.norm(t1, axis=1)
    bad = norm < 1e-8 * np.maximum(np.linalg.norm(s, axis=1), 1e-300)
    if np.any(bad):
        alt = np.where(np.abs(n[bad, 0:1]) < 0.9, [[1.0, 0, 0]], [[0.0, 1, 0]])
        t1[bad] = alt - np.einsum("nc,nc->n", alt, n[bad])[:, None] * n[bad]
        norm[bad] = np.linalg.norm(t1[bad], axis=1)
    t1 = t1 / norm[:, None]
    return t1, np.cross(n, t1)


def _petsc_rows(comm, rows: sp.csr_matrix, n_global_rows: int, col_sizes: tuple[int, int]) -> PETSc.Mat:
    rows.sum_duplicates()
    rows.sort_indices()
    A = PETSc.Mat().createAIJ(size=((rows.shape[0], n_global_rows), col_sizes),
                              csr=(rows.indptr.astype(PETSc.IntType), rows.indices.astype(PETSc.IntType),
                                   rows.data.astype(PETSc.ScalarType)), comm=comm)
    A.assemble()
    return A


def interface_operator(V, facet_tags, slave_tag: int, master_tag: int, *, sliding: float = 1.0,
                       axis=(0.0, 0.0, 1.0), quadrature_degree: int = 4, search_margin: float | None = None,
                       name: str = "interface") -> InterfaceOperator:
    """Assemble G = (G_n, G_t₁, G_t₂) of the pair (slave facets ``slave_tag``, master ``master_tag``).

    ``sliding`` = ±1 orients t₁ along ±e_θ (the master's motion relative to the slave)."""
    mesh = V.mesh
    comm = mesh.comm
    # owned facets only: meshes read by gmshio carry ghost cells, so a facet on the partition
    # boundary is present on two ranks and would be counted twice
    n_owned = mesh.topology.index_map(mesh.topology.dim - 1).size_local
    tagged = facet_tags.indices[facet_tags.indices < n_owned], facet_tags.values[facet_tags.indices < n_owned]
    slave_facets = tagged[0][tagged[1] == slave_tag]
    master_facets = tagged[0][tagged[1] == master_tag]
    for tag, what, f in ((slave_tag, "slave", slave_facets), (master_tag, "master", master_facets)):
        if comm.allreduce(len(f), op=MPI.SUM) == 0:
            raise ModelError(f"interfaces.{name}: the mesh has no facets tagged {tag} ({what} side)")
    sp_ = surface_points(mesh, slave_facets, quadrature_degree)
    nq = len(sp_.weight)
    lo = np.min(sp_.x, axis=0) if nq else np.full(3, np.inf)
    hi = np.max(sp_.x, axis=0) if nq else np.full(3, -np.inf)
    lo, hi = np.array(lo, dtype=float), np.array(hi, dtype=float)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    margin = search_margin if search_margin is not None else 0.05 * float(np.max(hi - lo)) + 1e-9
    master = _gather_master(V, master_facets, (lo - margin, hi + margin))

    cmap_el = coordinate_element(mesh)
    fac, Xm, xm, n = project(sp_.x, master, cmap_el, ref=reference_cell(mesh))
    gap0 = np.einsum("nc,nc->n", sp_.x - xm, n)
    t1, t2 = tangent_frame(sp_.x, n, sliding, axis)

    phi = _basis_values(V, sp_.ref)
    psi = _basis_values(V, Xm)
    nd = phi.shape[1]
    # the basis functions of nodes off the facet vanish on it: drop their round-off values
    phi[np.abs(phi) < 1e-12] = 0.0
    psi[np.abs(psi) < 1e-12] = 0.0
    imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    slave_blocks = imap.local_to_global(V.dofmap.list.array.reshape(-1, nd)[sp_.cells].ravel()).reshape(-1, nd) \
        if nq else np.zeros((0, nd), np.int64)
    master_blocks = master.dofs[fac]
    n_cols = imap.size_global * bs
    col_sizes = (imap.size_local * bs, n_cols)
    n_global = comm.allreduce(nq, op=MPI.SUM)
    row = np.repeat(np.arange(nq), 2 * nd * bs)
    G = []
    for d in (n, t1, t2):
        vals = np.concatenate([phi[:, :, None] * d[:, None, :], -psi[:, :, None] * d[:, None, :]], axis=1)
        cols = np.concatenate([slave_blocks, master_blocks], axis=1)[:, :, None] * bs + np.arange(bs)
        A = sp.csr_matrix((vals.ravel(), (row, cols.ravel())), shape=(nq, n_cols))
        A.eliminate_zeros()
        G.append(_petsc_rows(comm, A, n_global, col_sizes))
    Bs = sp.csr_matrix((phi.ravel(), (np.repeat(np.arange(nq), nd), slave_blocks.ravel())),
                       shape=(nq, imap.size_global))
    Bs.sum_duplicates()
    Bs.eliminate_zeros()
    n_remote = comm.allreduce(int(np.sum(master.rank[fac] != comm.rank)), op=MPI.SUM)
    return InterfaceOperator(G[0], G[1], G[2], Bs, sp_.weight, gap0, sp_.x, n, t1, n_global, n_remote)


def _row_vec(G: PETSc.Mat, values: np.ndarray) -> PETSc.Vec:
    v = G.createVecLeft()
    v.array[:] = values
    return v


def weighted_product(Gl: PETSc.Mat, Gr: PETSc.Mat, d: np.ndarray) -> PETSc.Mat:
    """Glᵀ diag(d) Gr (d rank-local, aligned with the owned rows)."""
    DG = Gr.copy()
    dv = _row_vec(Gr, d)
    DG.diagonalScale(L=dv)
    P = Gl.transposeMatMult(DG)
    DG.destroy()
    dv.destroy()
    return P


def contact_stiffness(op: InterfaceOperator, k) -> PETSc.Mat:
    """K_c = G_nᵀ diag(k w) G_n, k the normal stiffness dσ/dg per point (or one value):
    k_n at closed points and 0 at open ones for the linear penalty."""
    return weighted_product(op.Gn, op.Gn, k * op.weight)


def friction_stiffness(op: InterfaceOperator, k, mu: float) -> PETSc.Mat:
    """K_f = μ G_sᵀ diag(k w) G_n (G_s = G_t₁ oriented along the sliding direction), k as in
    :func:`contact_stiffness`."""
    return weighted_product(op.Gt1, op.Gn, mu * k * op.weight)


def tangential_stiffness(op: InterfaceOperator, kt, across_only: bool = True) -> PETSc.Mat:
    """Tangential penalty of a contact: K_t = G_t₂ᵀ diag(k_t w) G_t₂, across the sliding direction
    only (``across_only``, a sliding contact: along t₁ = s the friction force μ p carries no
    stiffness), or + G_t₁ᵀ diag(k_t w) G_t₁ (sliding = 0, sticking).  ``kt`` per point (k_t on
    the closed points, 0 on the open ones) or one value."""
    S = weighted_product(op.Gt2, op.Gt2, kt * op.weight)
    if not across_only:
        P = weighted_product(op.Gt1, op.Gt1, kt * op.weight)
        S.axpy(1.0, P, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        P.destroy()
    return S


def friction_damping_matrix(op: InterfaceOperator, p: np.ndarray, mu: np.ndarray, dmu: np.ndarray,
                            speed_V: np.ndarray) -> PETSc.Mat:
    """Friction damping of a sliding contact (derivation: :func:`fem_squeal.fe.preload.friction_damping`):

        C_d = G_t₂ᵀ diag(w p μ/V) G_t₂ + G_t₁ᵀ diag(w p dμ/dV) G_t₁

    per point: p the preload pressure, V the sliding speed, μ, dμ/dV the friction law at V."""
    p, speed_V = np.asarray(p, float), np.asarray(speed_V, float)
    C = weighted_product(op.Gt2, op.Gt2, op.weight * p * np.asarray(mu, float) / speed_V)
    d = op.weight * p * np.asarray(dmu, float)
    comm = op.Gt1.getComm().tompi4py()
    if comm.allreduce(bool(np.any(d != 0)), op=MPI.LOR):   # collective: every rank takes the same branch
        P = weighted_product(op.Gt1, op.Gt1, d)
        C.axpy(1.0, P, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        P.destroy()
    return C


def spring_stiffness(op: InterfaceOperator, kn: float, kt: float) -> PETSc.Mat:
    """Elastic layer: G_nᵀ k_n W G_n + k_t (G_t₁ᵀ W G_t₁ + G_t₂ᵀ W G_t₂) (bonded: large k_n = k_t)."""
    S = weighted_product(op.Gn, op.Gn, kn * op.weight)
    if kt > 0:
        for Gt in (op.Gt1, op.Gt2):
            P = weighted_product(Gt, Gt, kt * op.weight)
            S.axpy(1.0, P, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            P.destroy()
    return S


def project_to_nodes(op: InterfaceOperator, values: np.ndarray, comm: MPI.Comm) -> tuple[np.ndarray, np.ndarray]:
    """L²-projection of a quadrature-point field onto the slave surface's scalar P_k nodes.

    Solves (Bᵀ W B) p_h = Bᵀ W p on the surface DOFs (consistent surface mass; nodal lumping
    fails for P2).  Returns (global scalar DOFs, nodal values) on rank 0, empty arrays elsewhere."""

    B = op.B.tocoo()
    parts = comm.gather((B.row, B.col, B.data, op.weight, np.asarray(values, dtype=float)), root=0)
    if comm.rank != 0:
        return np.zeros(0, np.int64), np.zeros(0)
    rows, cols, data, w, p = [], [], [], [], []
    shift = 0
    for r, c, d, wi, pi in parts:
        rows.append(r + shift)
        cols.append(c)
        data.append(d)
        w.append(wi)
        p.append(pi)
        shift += len(wi)
    cols = np.concatenate(cols)
    dofs, local = np.unique(cols, return_inverse=True)
    Bg = sp.csr_matrix((np.concatenate(data), (np.concatenate(rows), local)), shape=(shift, len(dofs)))
    W = sp.diags(np.concatenate(w))
    Ms = (Bg.T @ W @ Bg).tocsc()
    return dofs, spsolve(Ms, Bg.T @ (W @ np.concatenate(p)))
