"""Assemble the PETSc operators of a model: K (elastic + springs), K_f, M, C, loads, interfaces.

The operator is λ²M + λC + (K + K_f): ``Kf`` is stored with the sign it has in the operator.
Volume forms are assembled into the cell sparsity pattern of K; spring and bonded interfaces
(built from the interface operator G) add entries between bodies.  Contact interfaces are kept
apart as :class:`~fem_squeal.fe.interface.InterfaceOperator` s: their K_c, K_f depend on which
points are closed, which the preload decides (:func:`linearise`).  Dirichlet (clamped) DOFs
get 1 on the diagonal of K and 0 on those of M, C, K_f and the interface matrices: they become
infinite eigenvalues that shift-invert never returns.
"""
from __future__ import annotations

import functools
import logging
import operator
import time
import warnings
from typing import NamedTuple

import numpy as np
import ufl
from dolfinx import fem, la
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc
from ufl.algorithms.map_integrands import map_integrand_dags
from ufl.corealg.multifunction import MultiFunction

from fem_squeal.fe import c3d8r as c8r
from fem_squeal.fe import cell_assembly, forms, hexahedra, kernels
from fem_squeal.fe import interface as itf
from fem_squeal.fe.factorisation import LU, factor_solver
from fem_squeal.fe.model import Interface, ModelSpec, RigidPlate, sliding_speed, speed_friction
from fem_squeal.util.errors import ModelError, UnknownNameError

# The JIT's compiler driver logs INFO lines through the root logger: keep only warnings from it.
logging.getLogger().addFilter(lambda rec: rec.name != "root" or rec.levelno >= logging.WARNING)

JIT_PARAMS = {"cffi_extra_compile_args": ["-O2"]}


class PlateMatrices(NamedTuple):
    """One rigid plate's share of K and K_f, without boundary-condition rows (the per-interface
    parameters of :class:`fem_squeal.fe.projection.ParametricOperators`)."""

    plate: RigidPlate
    Kc: PETSc.Mat          # ∫ k_n (u·n)(v·n) ds at the nominal k_n
    Kt: PETSc.Mat          # ∫ (u·t₂)(v·t₂) ds: the tangential penalty for k_t = 1
    Kf: PETSc.Mat | None   # −∫ k_n (u·n)(v·s) ds: the friction stiffness for μ = 1 (None: no friction)


class Operators(NamedTuple):
    """Assembled operators of λ²M + λC + (K + K_f) (PETSc ``aij``)."""

    V: fem.FunctionSpace
    K: PETSc.Mat          # elasticity + springs (+ closed contact after linearise), symmetric
    Kf: PETSc.Mat | None  # friction stiffness incl. μ and sliding sign (asymmetric) or None
    M: PETSc.Mat
    C: PETSc.Mat | None   # Rayleigh damping or None
    M_axial: PETSc.Mat    # mass of the motion along the axis, for in-plane/out-of-plane shares
    bc_dofs: np.ndarray   # local indices of clamped DOFs (blocked x bs)
    f: PETSc.Vec | None = None                       # pressure loads (0 on clamped DOFs)
    contacts: tuple = ()                             # ((Interface, InterfaceOperator), ...)
    K_parts: dict | None = None                      # part -> elastic stiffness (no BC rows)
    M_parts: dict | None = None                      # part -> (M, M_axial) of that part
    Cd: PETSc.Mat | None = None                      # friction damping (already in C; fe.preload.friction_damping)
    plate_parts: dict | None = None                  # plate name -> PlateMatrices (with parts=True)

    def K_total(self) -> PETSc.Mat:
        """K + K_f as a new matrix (K itself when there is no friction)."""
        if self.Kf is None:
            return self.K
        A = self.K.copy()
        # K_f's pattern is a subset of K's at best (PETSc squeezes unused slots at assembly, so
        # SAME_NONZERO_PATTERN would give wrong sums): let PETSc merge the patterns.
        A.axpy(1.0, self.Kf, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        return A


class _LiftFloats(MultiFunction):
    """Each real literal of a form (material values, k_n, μ, ... given as Python floats) becomes a
    ``fem.Constant`` holding it: the form's signature, which keys FFCx's compiled-form cache
    (``~/.cache/fenics``, or ``$XDG_CACHE_HOME/fenics``), then depends on the form's structure only, so
    a scene run with another E or μ, in this process or another, reuses the compiled code."""

    expr = MultiFunction.reuse_if_untouched

    def __init__(self, domain):
        super().__init__()
        self.domain = domain

    def float_value(self, o):
        return fem.Constant(self.domain, PETSc.ScalarType(float(o)))


def _compile(a, quadrature_degree):
    """JIT-compile ``a``; ``quadrature_degree`` (``discretisation.quadrature_degree``) goes into each
    integral's metadata: FFCx 0.5 ignores it as a form-compiler parameter (it was silently unused).
    Real literals are lifted into constants (:class:`_LiftFloats`): compiled once per form structure.
    Not set, on a hexahedral mesh: the 2 × 2 × 2 Gauss rule on the cell integrals
    (:mod:`~fem_squeal.fe.hexahedra`)."""
    if quadrature_degree is not None:
        a = ufl.Form([itg.reconstruct(metadata={"quadrature_degree": quadrature_degree, **itg.metadata()})
                      for itg in a.integrals()])
    else:
        a = hexahedra.with_cell_rule(a)
    a = map_integrand_dags(_LiftFloats(a.ufl_domain()), a)
    return fem.form(a, form_compiler_params={}, jit_params=JIT_PARAMS)


def _assemble(form, pattern: fem.FormMetaClass, bcs, diagonal: float, bc_dofs: np.ndarray | None = None
              ) -> PETSc.Mat:
    """The matrix of ``form`` on the sparsity of ``pattern``, Dirichlet rows and columns of ``bcs``
    zero with ``diagonal`` on them.  On one rank, a cell-integral form on its own pattern goes
    through :mod:`fem_squeal.fe.cell_assembly` (the same matrix, bit for bit, without PETSc's
    per-entry insertion); it needs the unrolled DOFs of ``bcs`` as ``bc_dofs``."""
    if pattern is form and (not bcs or bc_dofs is not None):
        A = cell_assembly.assemble_matrix(form, bc_dofs if bcs else np.zeros(0, dtype=np.int32), diagonal)
        if A is not None:
            kernels.note("assembly", "compiled")
            return A
    kernels.note("assembly", "dolfinx")
    A = fem_petsc.create_matrix(pattern)
    fem_petsc.assemble_matrix(A, form, bcs=bcs, diagonal=diagonal)
    A.assemble()
    return A


def _owned_global_rows(A: PETSc.Mat, V, local_dofs: np.ndarray) -> np.ndarray:
    bs = V.dofmap.index_map_bs
    n_owned = V.dofmap.index_map.size_local * bs
    lo = A.getOwnershipRange()[0]
    local_dofs = np.asarray(local_dofs)
    return (local_dofs[local_dofs < n_owned] + lo).astype(PETSc.IntType)


def _add(A: PETSc.Mat, B: PETSc.Mat, alpha: float = 1.0) -> None:
    A.axpy(alpha, B, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)


def _block_masses(V, a_scalar, quadrature_degree, weights: list[np.ndarray], bc_dofs: np.ndarray,
                  pattern: PETSc.Mat) -> list[PETSc.Mat] | None:
    """The vector masses M_W = M_s ⊗ W (one per b×b weight W) from ONE assembly of the scalar mass
    M_s = ∫ ρ φ_i φ_j dx (``a_scalar``, on the scalar space of V's element): ∫ ρ (W u)·v dx has
    the block W M_s(i, j) between nodes i and j.  W = I gives M = ∫ ρ u·v dx, W = a aᵀ the axial
    mass ∫ ρ (u·a)(v·a) dx.  Only W's non-zero entries are stored (M: b× fewer than on K's 3×3
    blocks), and the rows and columns of ``bc_dofs`` are left out (as a Dirichlet assembly with
    diagonal 0 leaves them zero).  Inserting the b²× smaller element matrices of the scalar form is
    what saves the time: 255k DOFs, P2: 0.17 s for M_s against 1.0 s for each vector mass; the
    expansion (:func:`fem_squeal.fe.cell_assembly.kronecker`) takes 0.05 s.

    None on more than one rank (the vector forms are assembled instead: the expansion of ghost
    rows and columns failed its 2-rank check and is not used), when the scalar space does not
    number its nodes as V numbers its blocks, or where the compiled expansion cannot be had."""
    if V.mesh.comm.size > 1:
        return None
    S = fem.FunctionSpace(V.mesh, V.ufl_element().sub_elements()[0])
    bs = V.dofmap.index_map_bs
    if not np.array_equal(S.dofmap.list.array, V.dofmap.list.array):
        return None
    u, v = ufl.TrialFunction(S), ufl.TestFunction(S)
    f = _compile(a_scalar(u, v), quadrature_degree)
    Ms = _assemble(f, f, [], 0.0)
    flag = np.zeros(bs * Ms.getSize()[0], dtype=bool)   # the Dirichlet DOFs
    flag[bc_dofs] = True
    out = [cell_assembly.kronecker(Ms, W, flag, pattern) for W in weights]
    Ms.destroy()
    if any(M is None for M in out):
        for M in out:
            if M is not None:
                M.destroy()
        return None
    return out


def _face_tag(mesh_data, face: str, present: set[int], where: str) -> int:
    if face not in mesh_data.faces:
        raise UnknownNameError(f"{where}: face {face!r} not in mesh; faces: {sorted(mesh_data.faces)}")
    tag = mesh_data.faces[face]
    if tag not in present:
        raise ModelError(f"{where}: mesh has no facets tagged {tag} ({face})")
    return tag


def build_interface(V, mesh_data, spec: ModelSpec, it: Interface) -> itf.InterfaceOperator:
    """The operator G of interface ``it`` (slave/master faces looked up by name)."""
    for face in (it.slave, it.master):
        if face not in mesh_data.faces:
            raise UnknownNameError(f"interfaces.{it.name}: face {face!r} not in mesh; "
                                   f"faces: {sorted(mesh_data.faces)}")
    return itf.interface_operator(V, mesh_data.facet_tags, mesh_data.faces[it.slave],
                                  mesh_data.faces[it.master], sliding=float(it.sliding), axis=spec.axis,
                                  quadrature_degree=spec.interface_quadrature_degree, name=it.name)


def contact_matrices(ops: Operators, stiffness: dict[str, np.ndarray] | None = None,
                     friction: bool = True) -> tuple[PETSc.Mat | None, PETSc.Mat | None]:
    """Σ K_c and Σ K_f over the contact interfaces, zero on the clamped DOFs.

    ``stiffness[name]`` is the normal stiffness dσ/dg at each quadrature point of that contact
    (k_n where closed, 0 where open, for the linear penalty); None: k_n everywhere (all closed).
    K_c includes the tangential penalty k_t of the points where dσ/dg > 0 (the closed ones):
    k_t G_t₂ᵀ W G_t₂ for a sliding contact, k_t (G_t₁ᵀ W G_t₁ + G_t₂ᵀ W G_t₂) for sliding = 0.
    K_f only for ``friction`` and interfaces with friction; None where there is nothing to add."""
    bc_rows = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
    total: list[PETSc.Mat | None] = [None, None]
    for it, op in ops.contacts:
        k = it.kn if stiffness is None else stiffness[it.name]
        mats = [itf.contact_stiffness(op, k)]
        if it.kt > 0:   # tangential penalty on the closed points (dσ/dg > 0), μ-independent: in K_c
            closed = 1.0 if stiffness is None else (np.asarray(k) > 0).astype(float)
            T = itf.tangential_stiffness(op, it.kt * closed, it.sliding != 0)
            _add(mats[0], T)
            T.destroy()
        mu = it.mu if it.law is None else it.friction_coefficient(op.x)    # μ(V) at V = Ω r per point
        mats.append(itf.friction_stiffness(op, k, mu) if friction and it.has_friction else None)
        for j, A in enumerate(mats):
            if A is None:
                continue
            A.zeroRowsColumns(bc_rows, diag=0.0)
            if total[j] is None:
                total[j] = A
            else:
                _add(total[j], A)
                A.destroy()
    return total[0], total[1]


def plate_friction_fields(V, plate) -> tuple[fem.Function, fem.Function]:
    """μ(V) and dμ/dV of a rigid plate's friction law at V = Ω r, interpolated into the scalar
    Lagrange space of V's degree (the law's own ``coefficient``, not a second UFL copy of it)."""
    S = fem.FunctionSpace(V.mesh, ("Lagrange", V.ufl_element().degree()))
    out = []
    for j in (0, 1):
        f = fem.Function(S)
        f.interpolate(lambda x, j=j: speed_friction(plate.mu, plate.law, sliding_speed(x.T, plate.speed))[j])
        out.append(f)
    return out[0], out[1]


def linearise(ops: Operators, active: dict[str, np.ndarray] | None = None,
              friction: bool = True) -> Operators:
    """Operators with the contact interfaces' K_c and K_f added for the closed points.

    ``active[name]`` flags the closed quadrature points of each contact (None: all closed, the
    linear route).  Returns new K and K_f (the inputs are not modified)."""
    if not ops.contacts:
        return ops
    stiffness = None if active is None else \
        {it.name: it.kn * active[it.name].astype(float) for it, _ in ops.contacts}
    Kc, Fc = contact_matrices(ops, stiffness, friction)
    K = ops.K.copy()
    _add(K, Kc)
    Kc.destroy()
    Kf = ops.Kf
    if Fc is not None:
        if Kf is None:
            Kf = Fc
        else:
            Kf = Kf.copy()
            _add(Kf, Fc)
            Fc.destroy()
    return ops._replace(K=K, Kf=Kf)


#: ν above which displacement tetrahedra of each degree are warned about (benchmarks/stress_extremes.py,
#: ring growth rates against theory: P1 is 12–20 % low at ν = 0.3 already (bending locking), 15–30 % at
#: 0.45, and loses the flutter pairs k ≥ 3–4 from 0.49; P2 stays within 0.3 % up to 0.499, the last ν tested)
LOCKING_NU = {1: 0.45, 2: 0.499}


def locking_warnings(spec: ModelSpec) -> list[str]:
    """Volumetric-locking warnings: parts with ν ≥ LOCKING_NU[1] for P1, ν > LOCKING_NU[2] for P2 (bulk/shear
    K/G = 2(1+ν)/(3(1−2ν)): 9.7 at ν = 0.45, 25 at 0.49, 250 at 0.499)."""
    out = []
    for part, m in spec.materials.items():
        if m.anisotropic:       # ν = −S₁₂/S₁₁ of the material frame says nothing of the bulk/shear ratio
            continue
        nus = [m.nu] + ([m.nu_axial] if m.nu_axial is not None else [])
        nu = max(nus)
        limit = LOCKING_NU.get(spec.degree, 1.0)
        if nu > limit or (spec.degree == 1 and nu >= limit):
            ratio = 2 * (1 + nu) / (3 * (1 - 2 * nu))
            out.append(f"materials.{part}: nu = {nu:g} with P{spec.degree} tetrahedra: nearly incompressible "
                       f"(bulk/shear modulus {ratio:.3g}); displacement elements lock volumetrically and "
                       + ("over-predict stiffness — use degree 2" if spec.degree == 1 else
                          f"may over-predict stiffness (P2 verified up to nu = {limit})")
                       + " (benchmarks/stress_extremes.py)")
    return out


def dirichlet_conditions(V, mesh_data, spec: ModelSpec) -> tuple[list, np.ndarray]:
    """The Dirichlet conditions of ``boundary.clamped`` (all three components) and ``boundary.fixed``
    (the named global components, each on the subspace V.sub(i)), and their local DOF indices
    (blocked index × bs + component, sorted, unique)."""
    facet_tags = mesh_data.facet_tags
    fdim = V.mesh.topology.dim - 1
    bs = V.dofmap.index_map_bs

    def facets_of(face, where):
        if face not in mesh_data.faces:
            raise UnknownNameError(f"{where}: face {face!r} not in mesh; faces: {sorted(mesh_data.faces)}")
        return facet_tags.indices[facet_tags.values == mesh_data.faces[face]]

    bcs, dofs_all = [], [np.zeros(0, dtype=np.int32)]
    if spec.clamped:
        facets = np.unique(np.concatenate([facets_of(f, "boundary.clamped") for f in spec.clamped]))
        dofs = fem.locate_dofs_topological(V, fdim, facets)
        bcs.append(hexahedra.zero_condition(V, dofs))
        dofs_all.append((dofs[:, None] * bs + np.arange(bs)[None, :]).ravel())
    for i in range(bs):   # one condition per component over every face that fixes it
        faces = [fx.face for fx in spec.fixed if i in fx.indices]
        if not faces:
            continue
        facets = np.unique(np.concatenate([facets_of(f, "boundary.fixed") for f in faces]))
        if hexahedra.point_evaluation(V):
            dofs = fem.locate_dofs_topological(V.sub(i), fdim, facets)   # unrolled: block × bs + i
            bcs.append(hexahedra.zero_condition(V, dofs, i))
        else:   # (dofs in V, dofs in the collapsed component space)
            pair = fem.locate_dofs_topological((V.sub(i), V.sub(i).collapse()[0]), fdim, facets)
            bcs.append(hexahedra.zero_condition(V, pair, i))
            dofs = pair[0]
        dofs_all.append(np.asarray(dofs))
    return bcs, np.unique(np.concatenate(dofs_all)).astype(np.int32)


def _check_c3d8r(mesh, spec: ModelSpec) -> None:
    """C3D8R runs on Q1 hexahedra (degree 1), the cell rule not set, isotropic materials (``hgstiffness.f``
    takes E from an isotropic material's constants): a named error otherwise."""
    if not hexahedra.is_hexahedral(mesh) or spec.degree != 1 or spec.quadrature_degree is not None:
        raise ModelError("C3D8R (one point with hourglass control) needs native hexahedra at "
                         "discretisation.degree = 1 "
                         "without discretisation.quadrature_degree")
    odd = sorted(p for p, m in spec.materials.items()
                 if getattr(m, "anisotropic", False) or getattr(m, "transversely_isotropic", False))
    if odd:
        raise ModelError(f"materials.{odd[0]}: C3D8R's hourglass stiffness (CalculiX hgstiffness.f) is defined "
                         "here for isotropic materials only; use discretisation.degree = 2")


def _c3d8r_corrections(V, mesh_data, spec: ModelSpec) -> dict:
    """part -> (owned cells, ΔK (m, 24, 24), scalar ΔM (m, 8, 8)) of :func:`fem_squeal.fe.c3d8r.corrections`."""
    X, _, _ = c8r.cell_dofs(V)
    tags = mesh_data.cell_tags
    out = {}
    for part, mat in spec.materials.items():
        cells = tags.indices[(tags.values == mesh_data.volumes[part]) & (tags.indices < len(X))]
        one = np.ones(len(cells))
        dK, dM = c8r.corrections(X[cells], mat.E * one, mat.nu * one, mat.rho * one)
        out[part] = (cells, dK, dM)
    return out


def assemble_operators(mesh_data, spec: ModelSpec, *, parts: bool = False,
                       describe_part: str | None = None, timings: dict | None = None) -> Operators:
    """Build V = [P_degree]³ on the mesh (on hexahedra: :func:`fem_squeal.fe.hexahedra.displacement_space`)
    and assemble K, K_f, M, C, M_axial, loads and interfaces.

    ``parts``: also assemble each part's elastic stiffness (strain-energy shares, parametric
    stiffness); ``describe_part``: also that part's M and M_axial (its nodal diameters);
    ``timings``: filled with the wall time of the volume forms and of the interface operators."""

    t0 = time.perf_counter()
    mesh, cell_tags, facet_tags = mesh_data.mesh, mesh_data.cell_tags, mesh_data.facet_tags
    if spec.c3d8r:
        _check_c3d8r(mesh, spec)
    elif spec.degree == 1 and hexahedra.is_hexahedral(mesh):
        warnings.warn("degree 1 on hexahedra: Q1 with 2x2x2 Gauss points (CalculiX C3D8) locks in bending "
                      "(benchmarks/hex_native.py: the thin plate's frequencies 2.4x C3D20R's); use degree 2",
                      stacklevel=2)
    elif spec.degree == 1:
        warnings.warn("degree 1: P1 tetrahedra lock in bending (ring frequencies +2 % at 158k DOFs, "
                      "degenerate pairs split by as much as the friction effect); use degree 2",
                      stacklevel=2)
    elif spec.degree != 2:
        raise ModelError(f"discretisation.degree: must be 1 or 2 (got {spec.degree})")
    for w in locking_warnings(spec):
        warnings.warn(w, stacklevel=2)
    V = hexahedra.displacement_space(mesh, spec.degree)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=cell_tags)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags)
    present_cells = set(np.concatenate(mesh.comm.allgather(np.unique(cell_tags.values))).tolist())
    present_faces = set(np.concatenate(mesh.comm.allgather(np.unique(facet_tags.values))).tolist())

    a_K = a_M = a_C = a_Mz = None
    axis_c = fem.Constant(mesh, np.asarray(spec.axis, dtype=PETSc.ScalarType))
    for part, mat in spec.materials.items():
        if part not in mesh_data.volumes:
            raise UnknownNameError(f"materials.{part}: no such part; "
                                   f"parts of this mesh: {sorted(mesh_data.volumes)}")
        tag = mesh_data.volumes[part]
        if tag not in present_cells:
            raise ModelError(f"materials.{part}: mesh has no cells tagged {tag}")
        dxp = dx(tag)
        k = forms.material_stiffness_form(u, v, mat, dxp, spec.quadrature_degree)
        m = forms.mass_form(u, v, mat.rho, dxp)
        mz = forms.axial_mass_form(u, v, mat.rho, dxp, axis_c)
        a_K = k if a_K is None else a_K + k
        a_M = m if a_M is None else a_M + m
        a_Mz = mz if a_Mz is None else a_Mz + mz
        if mat.rayleigh_alpha > 0 or mat.rayleigh_beta > 0:
            c = mat.rayleigh_alpha * forms.mass_form(u, v, mat.rho, dxp) + \
                mat.rayleigh_beta * forms.material_stiffness_form(u, v, mat, dxp, spec.quadrature_degree)
            a_C = c if a_C is None else a_C + c
    missing = sorted(set(mesh_data.volumes) - set(spec.materials))
    if missing:
        raise UnknownNameError(f"materials: no material for part(s) {missing}")

    n = ufl.FacetNormal(mesh)
    x = ufl.SpatialCoordinate(mesh)
    a_f = None
    for plate in spec.plates:
        ftag = _face_tag(mesh_data, plate.face, present_faces, "interfaces")
        if plate.kn > 0:
            mu = plate.mu if plate.law is None else plate_friction_fields(V, plate)[0]
            a_c, a_t, a_fp = _plate_forms(u, v, x, n, ds(ftag), plate, spec, plate.kt, mu)
            a_K = a_K + a_c
            if plate.kt > 0:
                a_K = a_K + a_t
            if a_fp is not None:
                a_f = a_fp if a_f is None else a_f + a_fp
    for gs in spec.ground_springs:
        ftag = _face_tag(mesh_data, gs.face, present_faces, "boundary.ground_springs")
        a_K = a_K + forms.ground_spring_form(u, v, gs.k_axial, gs.k_transverse, axis_c, ds(ftag))
    L = None
    for pr in spec.pressures:
        ftag = _face_tag(mesh_data, pr.face, present_faces, "loads.pressure")
        lp = forms.pressure_load_form(v, pr.p, n, ds(ftag))
        L = lp if L is None else L + lp

    bcs, bc_dofs = dirichlet_conditions(V, mesh_data, spec)

    qd = spec.quadrature_degree
    if spec.c3d8r:   # the one-point rule on the cell integrals (fem_squeal.fe.c3d8r adds the rest)
        a_K, a_M, a_Mz = (hexahedra.with_cell_rule(a, c8r.ONE_POINT) for a in (a_K, a_M, a_Mz))
        if a_C is not None:
            a_C = hexahedra.with_cell_rule(a_C, c8r.ONE_POINT)
    fK = _compile(a_K, qd)
    K = _assemble(fK, fK, bcs, 1.0, bc_dofs)

    def scalar_mass(us, vs):
        terms = [forms.mass_form(us, vs, m.rho, dx(mesh_data.volumes[p])) for p, m in spec.materials.items()]
        a = functools.reduce(operator.add, terms)
        return hexahedra.with_cell_rule(a, c8r.ONE_POINT) if spec.c3d8r else a
    masses = _block_masses(V, scalar_mass, qd, [np.eye(V.dofmap.index_map_bs), np.outer(spec.axis, spec.axis)],
                           bc_dofs, K)
    if masses is not None:
        M, Mz = masses
    else:
        M = _assemble(_compile(a_M, qd), fK, bcs, 0.0)
        Mz = _assemble(_compile(a_Mz, qd), fK, bcs, 0.0)
    C = _assemble(_compile(a_C, qd), fK, bcs, 0.0) if a_C is not None else None
    Kf = _assemble(_compile(a_f, qd), fK, bcs, 0.0) if a_f is not None else None
    c3 = _c3d8r_corrections(V, mesh_data, spec) if spec.c3d8r else {}
    for part, (cells, dK, dM) in c3.items():
        mat = spec.materials[part]
        c8r.add_cell_matrices(K, V, cells, dK, bc_dofs)
        c8r.add_cell_matrices(M, V, cells, c8r.vector_mass(dM, np.eye(3)), bc_dofs)
        c8r.add_cell_matrices(Mz, V, cells, c8r.vector_mass(dM, np.outer(spec.axis, spec.axis)),
                                        bc_dofs)
        if C is not None:
            c8r.add_cell_matrices(
                C, V, cells, mat.rayleigh_alpha * c8r.vector_mass(dM, np.eye(3)) + mat.rayleigh_beta * dK,
                bc_dofs)

    f = None
    if L is not None:
        fL = _compile(L, qd)
        f = fem_petsc.assemble_vector(fL)
        f.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fem_petsc.set_bc(f, bcs)
    if spec.point_loads:
        if f is None:
            f = la.create_petsc_vector(V.dofmap.index_map, V.dofmap.index_map_bs)
            f.set(0.0)
        add_point_loads(f, V, spec.point_loads)
        fem_petsc.set_bc(f, bcs)

    t1 = time.perf_counter()
    contacts = []
    bc_rows = _owned_global_rows(K, V, bc_dofs)
    for it in spec.interfaces:
        op = build_interface(V, mesh_data, spec, it)
        if it.kind == "contact":
            contacts.append((it, op))
            continue
        kt = it.kn if it.kind == "bonded" else it.kt
        S = itf.spring_stiffness(op, it.kn, kt)
        S.zeroRowsColumns(bc_rows, diag=0.0)
        _add(K, S)
        S.destroy()
        op.destroy()

    t2 = time.perf_counter()
    K_parts = M_parts = plate_parts = None
    if parts:
        K_parts = {}
        for part, mat in spec.materials.items():
            a_p = forms.material_stiffness_form(u, v, mat, dx(mesh_data.volumes[part]), qd)
            fp = _compile(hexahedra.with_cell_rule(a_p, c8r.ONE_POINT) if spec.c3d8r else a_p, qd)
            K_parts[part] = _assemble(fp, fp, [], 0.0)
            if part in c3:
                c8r.add_cell_matrices(K_parts[part], V, c3[part][0], c3[part][1], np.zeros(0, np.int32))
        plate_parts = {}
        for plate in spec.plates:
            if plate.kn > 0 and plate.name:
                shape = 1.0 if plate.law is None else plate_friction_fields(V, plate)[0] / plate.mu
                a_c, a_t, a_f1 = _plate_forms(u, v, x, n, ds(mesh_data.faces[plate.face]), plate, spec, 1.0, shape)
                fc = _compile(a_c, qd)
                plate_parts[plate.name] = PlateMatrices(
                    plate, _assemble(fc, fc, [], 0.0), _assemble(_compile(a_t, qd), fc, [], 0.0),
                    None if a_f1 is None else _assemble(_compile(a_f1, qd), fc, [], 0.0))
    if describe_part is not None:
        if describe_part not in spec.materials:
            raise UnknownNameError(f"describe_part: no part {describe_part!r}; parts: {sorted(spec.materials)}")
        mat, dxp = spec.materials[describe_part], dx(mesh_data.volumes[describe_part])
        a_m, a_mz = forms.mass_form(u, v, mat.rho, dxp), forms.axial_mass_form(u, v, mat.rho, dxp, axis_c)
        if spec.c3d8r:
            a_m, a_mz = (hexahedra.with_cell_rule(a, c8r.ONE_POINT) for a in (a_m, a_mz))
        fm = _compile(a_m, qd)
        M_parts = {describe_part: (_assemble(fm, fm, [], 0.0), _assemble(_compile(a_mz, qd), fm, [], 0.0))}
        if describe_part in c3:
            cells, _, dM = c3[describe_part]
            for A, W in zip(M_parts[describe_part], (np.eye(3), np.outer(spec.axis, spec.axis))):
                c8r.add_cell_matrices(A, V, cells, c8r.vector_mass(dM, W), np.zeros(0, np.int32))
    if timings is not None:
        timings.update(volume_forms=t1 - t0 + time.perf_counter() - t2, interfaces=t2 - t1)
    return Operators(V, K, Kf, M, C, Mz, bc_dofs, f, tuple(contacts), K_parts, M_parts,
                     plate_parts=plate_parts)


def _plate_forms(u, v, x, n, dsp, plate: RigidPlate, spec: ModelSpec, kt, mu):
    """The forms of rigid plate ``plate`` on its face measure ``dsp``: (a_c at its k_n, a_t at
    ``kt``, −a_f at ``mu`` (a number or a μ(V) field) or None without friction).  a_t acts across
    the sliding direction (sliding = 0: on the whole tangent plane)."""
    s = forms.circumferential_direction(x, float(plate.sliding)) if plate.sliding != 0 else None
    # t₂ = n × s/|n × s| is not polynomial: FFCx's estimate (1444 points per facet) is replaced
    # by the degree of a product of two P_k traces on a P2 facet, 2k + 2
    qdeg = spec.quadrature_degree or 2 * spec.degree + 2
    a_t = forms.tangential_penalty_form(u, v, kt, n, s, dsp.reconstruct(metadata={"quadrature_degree": qdeg}))
    a_f1 = None
    if plate.mu > 0 and plate.sliding != 0:
        # the traction μ k_n (u·n) s is a load: it enters the operator as −a_f
        a_f1 = -forms.friction_form(u, v, plate.kn, mu, n, s, dsp)
    return forms.contact_form(u, v, plate.kn, n, dsp), a_t, a_f1


class RotationMatrices(NamedTuple):
    """Per-unit-speed operators of the parts spinning about z (:mod:`fem_squeal.fe.forms`, rotation):
    the damping matrix is Ω G, the stiffness gains −Ω² S, the centrifugal load is Ω² f."""

    G: PETSc.Mat    # skew: transport G₁ (frame "fixed") or Coriolis G_c (frame "rotating")
    S: PETSc.Mat    # symmetric positive semi-definite: K_L ("fixed") or M_r ("rotating")
    f: PETSc.Vec    # centrifugal load per unit Ω², 0 on the clamped DOFs


def _part_measure(mesh_data, spec: ModelSpec, parts, where: str):
    dx = ufl.Measure("dx", domain=mesh_data.mesh, subdomain_data=mesh_data.cell_tags)
    for p in parts:
        if p not in mesh_data.volumes or p not in spec.materials:
            raise UnknownNameError(f"{where}: no part {p!r}; parts: {sorted(mesh_data.volumes)}")
    return [(spec.materials[p], dx(mesh_data.volumes[p])) for p in parts]


def rotation_matrices(ops: Operators, mesh_data, spec: ModelSpec, parts, frame: str = "fixed") -> RotationMatrices:
    """G, S and f of the spinning ``parts`` (about z through the origin), per unit Ω and Ω².

    ``frame`` "fixed": the transport form of a part turning under stationary observers (the disc under
    the pads): G₁ = ∫ρ [(L u)·v − u·(L v)], S = K_L = ∫ρ (L u)·(L v), L = x ∂_y − y ∂_x.
    ``frame`` "rotating": the co-rotating frame (CalculiX ``*COMPLEX FREQUENCY, CORIOLIS``):
    G_c = 2∫ρ (e_z × u)·v, S = M_r = ∫ρ (u − u_z e_z)·(v − v_z e_z).  Both: f = ∫ρ (x − x_z e_z)·v.
    Rows and columns of the clamped DOFs are zero."""
    if frame not in ("fixed", "rotating"):
        raise ModelError(f"frame: must be 'fixed' or 'rotating' (got {frame!r})")
    V = ops.V
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    x = ufl.SpatialCoordinate(V.mesh)
    a = fem.Constant(V.mesh, np.array([0.0, 0.0, 1.0], dtype=PETSc.ScalarType))
    a_G = a_S = L = None
    for mat, dxp in _part_measure(mesh_data, spec, parts, "operating.rotating_parts"):
        if frame == "fixed":
            g, s = forms.gyroscopic_form(u, v, mat.rho, x, dxp), forms.convective_form(u, v, mat.rho, x, dxp)
        else:
            g, s = forms.coriolis_form(u, v, mat.rho, a, dxp), forms.spin_softening_form(u, v, mat.rho, a, dxp)
        lc = forms.centrifugal_load_form(v, mat.rho, x, a, dxp)
        a_G, a_S, L = (g, s, lc) if a_G is None else (a_G + g, a_S + s, L + lc)
    if a_G is None:
        raise ModelError("operating.rotating_parts: no part rotates")
    bc_rows = _owned_global_rows(ops.K, V, ops.bc_dofs)
    mats = []
    for form in (a_G, a_S):
        c = _compile(form, spec.quadrature_degree)
        A = _assemble(c, c, [], 0.0)
        A.zeroRowsColumns(bc_rows, diag=0.0)
        mats.append(A)
    f = fem_petsc.assemble_vector(_compile(L, spec.quadrature_degree))
    f.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    f.setValues(bc_rows, np.zeros(len(bc_rows)))
    f.assemble()
    return RotationMatrices(mats[0], mats[1], f)


def point_load_nodes(V, loads) -> list[np.ndarray]:
    """Per load, the local (owned) block index of the DOF node at its point (empty on the ranks that do not
    own it); a point that is no node of V's on any rank is a :class:`ModelError` naming the load.  Nodes of an
    element whose DOFs are not all point values (serendipity hexahedra: edge moments) are its vertices only."""
    x = hexahedra.dof_coordinates(V)
    n_owned = V.dofmap.index_map.size_local
    candidates = np.arange(n_owned)
    if not hexahedra.point_evaluation(V):
        mesh = V.mesh
        mesh.topology.create_connectivity(0, mesh.topology.dim)
        nv = mesh.topology.index_map(0).size_local + mesh.topology.index_map(0).num_ghosts
        vert = fem.locate_dofs_topological(V, 0, np.arange(nv, dtype=np.int32))
        candidates = np.intersect1d(candidates, vert)
    comm = V.mesh.comm
    lo = comm.allreduce(float(np.min(x[:n_owned])) if n_owned else np.inf, op=MPI.MIN)
    hi = comm.allreduce(float(np.max(x[:n_owned])) if n_owned else -np.inf, op=MPI.MAX)
    tol = 1e-9 * max(hi - lo, 1e-300)
    out = []
    for load in loads:
        d = np.linalg.norm(x[candidates] - np.asarray(load.point), axis=1) if len(candidates) else np.zeros(0)
        hit = candidates[d <= tol] if len(d) else candidates[:0]
        found = comm.allreduce(len(hit), op=MPI.SUM)
        if found == 0:
            near = comm.allreduce(float(d.min()) if len(d) else np.inf, op=MPI.MIN)
            raise ModelError(f"loads.point.{load.name}: no node of the mesh at {list(load.point)} (nearest "
                             f"{near:.3g} m away" + ("; the DOFs of serendipity hexahedra on edges are moments: "
                                                     "load a corner node" if not hexahedra.point_evaluation(V)
                                                     else "") + ")")
        out.append(hit[:1])
    return out


def add_point_loads(f: PETSc.Vec, V, loads) -> None:
    """f += F at the three DOFs of each load's node (:func:`point_load_nodes`; global rows)."""
    lo = f.getOwnershipRange()[0]
    bs = V.dofmap.index_map_bs
    for load, nodes in zip(loads, point_load_nodes(V, loads)):
        for node in nodes:
            rows = (lo + bs * int(node) + np.arange(3)).astype(PETSc.IntType)
            f.setValues(rows, np.asarray(load.force), addv=PETSc.InsertMode.ADD_VALUES)
    f.assemble()


def direct_solver(A: PETSc.Mat, options: dict | None, prefix: str) -> PETSc.KSP:
    """A direct solver of A, factorised (:func:`fem_squeal.fe.factorisation.factor_solver`: MUMPS LU
    by default; PETSc options under ``prefix`` override it)."""
    return factor_solver(A, LU, prefix, options)


def static_displacement(K: PETSc.Mat, f: PETSc.Vec, options: dict | None = None,
                        prefix: str = "prestress_") -> PETSc.Vec:
    """u with K u = f (direct LU; K with the clamped rows as identity and f zero there).  Raises
    :class:`ModelError` when the solve fails or its residual exceeds 1e-6‖f‖ (a part not held against
    rigid-body motion under a load that is not self-equilibrated).  A free body under a self-equilibrated
    load (the centrifugal load of a free disc) gets one solution: its rigid part carries no stress."""
    ksp = None
    u = K.createVecRight()
    r = K.createVecLeft()
    try:
        ksp = direct_solver(K, options, prefix)
        ksp.solve(f, u)
        K.mult(u, r)
        r.axpy(-1.0, f)
        fn = f.norm()
        bad = ksp.getConvergedReason() < 0 or not np.isfinite(u.norm()) or (fn > 0 and r.norm() > 1e-6 * fn)
    except PETSc.Error:
        bad = True
    finally:
        if ksp is not None:
            ksp.destroy()
        r.destroy()
    if bad:
        u.destroy()
        raise ModelError("prestress: the static problem K u = f has no unique solution (is every part held "
                         "against rigid-body motion? the centrifugal and preload stresses need it)")
    return u


def geometric_stiffness(ops: Operators, mesh_data, spec: ModelSpec, u0: PETSc.Vec) -> PETSc.Mat:
    """K_σ = Σ_parts ∫ σ₀_ij ∂_i u_k ∂_j v_k dx with σ₀ = C ε(u₀) of each part's material (the initial
    stress of the static displacement u₀); zero rows and columns on the clamped DOFs."""
    V = ops.V
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    u0h = fem.Function(V)
    n = u0.getLocalSize()
    u0h.x.array[:n] = u0.array_r
    u0h.x.scatter_forward()
    a = None
    for mat, dxp in _part_measure(mesh_data, spec, list(spec.materials), "materials"):
        k = forms.geometric_stiffness_form(u, v, forms.material_stress(u0h, mat), forms.varying_frame_measure(
            dxp, u, mat, spec.quadrature_degree))
        a = k if a is None else a + k
    c = _compile(a, spec.quadrature_degree)
    A = _assemble(c, c, [], 0.0)
    A.zeroRowsColumns(_owned_global_rows(ops.K, V, ops.bc_dofs), diag=0.0)
    return A


class OperatingTerms(NamedTuple):
    """The disc's rotation and the stress stiffening per unit speed (issue 20 items 4–6):

        C(Ω) = C₀ + Ω G,   K(Ω) = K₀ + K_f + K_σ0 + Ω² (K_σc − S).

    G, S of the rotating parts in the transport form (:func:`rotation_matrices`, frame "fixed"),
    K_σ0 = K_σ(u_static) the stress stiffening of the preload, K_σc = K_σ(u_c¹) that of the
    centrifugal displacement per unit Ω² (K_total u_c¹ = f_c¹; K_σ is linear in u).  A term that the
    scene does not ask for is None."""

    G: PETSc.Mat | None      # gyroscopic, per unit Ω (skew)
    S: PETSc.Mat | None      # convective stiffness K_L, per unit Ω² (enters as −Ω² S)
    Ks0: PETSc.Mat | None    # K_σ of the preload displacement
    Ksc: PETSc.Mat | None    # K_σ of the centrifugal displacement per unit Ω²
    uc_max: float = 0.0      # max |u_c¹| [m per (rad/s)²]

    def stiffness_per_speed2(self) -> PETSc.Mat | None:
        """K_σc − S: the stiffness per unit Ω² (a new matrix; None without rotation)."""
        if self.S is None:
            return None
        out = self.S.copy()
        out.scale(-1.0)
        if self.Ksc is not None:
            _add(out, self.Ksc)
        return out

    def destroy(self) -> None:
        for A in (self.G, self.S, self.Ks0, self.Ksc):
            if A is not None:
                A.destroy()


def operating_terms(ops: Operators, mesh_data, spec: ModelSpec, *, gyroscopic: bool = False,
                    rotating_parts=("disc",), stress_stiffening: bool = False,
                    u_static: PETSc.Vec | None = None, options: dict | None = None) -> OperatingTerms:
    """The :class:`OperatingTerms` of a scene: G, S of the ``rotating_parts`` when ``gyroscopic``;
    K_σ0 when ``stress_stiffening`` (u_static the preload displacement; None: K_total u = f when there
    is a load), and K_σc with both."""
    G = S = Ks0 = Ksc = None
    uc_max = 0.0
    K = ops.K_total() if stress_stiffening else None
    if stress_stiffening:
        u0 = u_static.copy() if u_static is not None else None
        if u0 is None and ops.f is not None and ops.f.norm() > 0:
            u0 = static_displacement(K, ops.f, options)
        if u0 is not None:
            Ks0 = geometric_stiffness(ops, mesh_data, spec, u0)
            u0.destroy()
    if gyroscopic:
        rot = rotation_matrices(ops, mesh_data, spec, list(rotating_parts), "fixed")
        G, S = rot.G, rot.S
        if stress_stiffening:
            uc = static_displacement(K, rot.f, options)
            uc_max = uc.norm(PETSc.NormType.INFINITY)
            Ksc = geometric_stiffness(ops, mesh_data, spec, uc)
            uc.destroy()
        rot.f.destroy()
    if K is not None and K is not ops.K:
        K.destroy()
    return OperatingTerms(G, S, Ks0, Ksc, uc_max)


def operating_operators(ops: Operators, mesh_data, spec: ModelSpec, *, speed: float = 0.0,
                        gyroscopic: bool = False, rotating_parts=("disc",), stress_stiffening: bool = False,
                        u_static: PETSc.Vec | None = None, options: dict | None = None,
                        terms: OperatingTerms | None = None) -> tuple[PETSc.Mat, PETSc.Mat | None, dict]:
    """K and C of the CEA at speed Ω with the disc's rotation and the stress stiffening
    (:class:`OperatingTerms`; ``terms`` given: those, else :func:`operating_terms` of the flags):

        C = C₀ + Ω G,   K = K₀ + K_f + K_σ0 + Ω² (K_σc − S).

    Both off: K_total() and C unchanged.  ``info``: norms of the added matrices, for the results."""
    K, C, info = ops.K_total(), ops.C, {}
    if terms is None and not (gyroscopic or stress_stiffening):
        return K, C, info
    own = terms is None
    if own:
        terms = operating_terms(ops, mesh_data, spec, gyroscopic=gyroscopic, rotating_parts=rotating_parts,
                                stress_stiffening=stress_stiffening, u_static=u_static, options=options)
    if K is ops.K:
        K = K.copy()
    Ks = None
    if terms.Ks0 is not None or terms.Ksc is not None:
        Ks = combination([(terms.Ks0, 1.0), (terms.Ksc, speed ** 2)])
        if terms.Ksc is not None:
            info["centrifugal_displacement_max"] = speed ** 2 * terms.uc_max
    if terms.G is not None:
        _add(K, terms.S, -speed ** 2)
        info["convective_stiffness_norm"] = speed ** 2 * terms.S.norm(PETSc.NormType.FROBENIUS)
        info["gyroscopic_norm"] = speed * terms.G.norm(PETSc.NormType.FROBENIUS)
        if C is None:
            C = terms.G.copy()
            C.scale(speed)
        else:
            C = C.copy()
            _add(C, terms.G, speed)
    if Ks is not None:
        info["geometric_stiffness_norm"] = Ks.norm(PETSc.NormType.FROBENIUS)
        _add(K, Ks)
        Ks.destroy()
    if own:
        terms.destroy()
    return K, C, info


def combination(terms) -> PETSc.Mat:
    """Σ αⱼ Aⱼ over the (A, α) of ``terms`` with A not None, as a new matrix (the first's pattern
    grown by the others')."""
    terms = [(A, a) for A, a in terms if A is not None]
    out = terms[0][0].copy()
    out.scale(terms[0][1])
    for A, a in terms[1:]:
        _add(out, A, a)
    return out
