"""The model's operators on its mesh: K (elastic + springs), K_f, M, C, the loads and the interfaces
(:func:`assemble_operators`), with the Dirichlet conditions and the point loads."""
from __future__ import annotations

import functools
import operator
import time
import warnings
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np
import ufl
from dolfinx import fem, la
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe import c3d8r as c8r
from fem_squeal.fe import forms, hexahedra
from fem_squeal.fe import interface as itf
from fem_squeal.fe.assembly.compiled import (
    _add,
    _assemble,
    _block_masses,
    _compile,
    _owned_global_rows,
    assemble_form,
)
from fem_squeal.fe.model import Interface, ModelSpec, RigidPlate, sliding_speed, speed_friction
from fem_squeal.util.errors import ModelError, UnknownNameError


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
    op = itf.interface_operator(V, mesh_data.facet_tags, mesh_data.faces[it.slave],
                                mesh_data.faces[it.master], sliding=float(it.sliding), axis=spec.axis,
                                quadrature_degree=spec.interface_quadrature_degree, name=it.name)
    if it.initial_gap is not None:
        centroid = None
        if it.initial_gap.at is None:              # the slave face's area centroid (collective)
            comm = V.mesh.comm
            area = comm.allreduce(float(np.sum(op.weight)), op=MPI.SUM)
            centroid = np.array(comm.allreduce(op.weight @ op.x if len(op.weight) else np.zeros(3),
                                               op=MPI.SUM)) / area
        op = op._replace(gap0=op.gap0 + it.initial_gap.values(op.x, centroid))
    return op


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


def part_stiffnesses(V: fem.FunctionSpace, mesh_data, spec: ModelSpec, c3: dict | None = None
                     ) -> Iterator[tuple[str, PETSc.Mat]]:
    """Each part's elastic stiffness K_p = ∫_(part) ε(v) : D : ε(u) dx on ``V`` (no boundary-condition rows;
    on C3D8R hexahedra with its hourglass correction), one part at a time: (part, K_p), K_p the caller's.
    :func:`assemble_operators` keeps them all with ``parts=True``; the CEA's strain-energy shares take them
    one after the other where nothing else needs them (at 1.32M DOFs they are 1.2 GiB, held otherwise from
    the operators to the descriptors).  ``c3``: the C3D8R corrections where already computed."""
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.Measure("dx", domain=V.mesh, subdomain_data=mesh_data.cell_tags)
    qd = spec.quadrature_degree
    if c3 is None:
        c3 = _c3d8r_corrections(V, mesh_data, spec) if spec.c3d8r else {}
    for part, mat in spec.materials.items():
        a_p = forms.material_stiffness_form(u, v, mat, dx(mesh_data.volumes[part]), qd)
        fp = _compile(hexahedra.with_cell_rule(a_p, c8r.ONE_POINT) if spec.c3d8r else a_p, qd)
        Kp = _assemble(fp, fp, [], 0.0)
        if part in c3:
            c8r.add_cell_matrices(Kp, V, c3[part][0], c3[part][1], np.zeros(0, np.int32))
        yield part, Kp


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
    K, compiled_K = assemble_form(a_K, qd, bcs, 1.0, bc_dofs)
    # K's form, the pattern of the matrices below: compiled where one of them needs it
    fK = functools.cache(lambda: _compile(a_K, qd) if compiled_K is None else compiled_K)

    def scalar_mass(us, vs):
        terms = [forms.mass_form(us, vs, m.rho, dx(mesh_data.volumes[p])) for p, m in spec.materials.items()]
        a = functools.reduce(operator.add, terms)
        return hexahedra.with_cell_rule(a, c8r.ONE_POINT) if spec.c3d8r else a
    masses = _block_masses(V, scalar_mass, qd, [np.eye(V.dofmap.index_map_bs), np.outer(spec.axis, spec.axis)],
                           bc_dofs, K)
    if masses is not None:
        M, Mz = masses
    else:
        M = _assemble(_compile(a_M, qd), fK(), bcs, 0.0)
        Mz = _assemble(_compile(a_Mz, qd), fK(), bcs, 0.0)
    C = _assemble(_compile(a_C, qd), fK(), bcs, 0.0) if a_C is not None else None
    Kf = _assemble(_compile(a_f, qd), fK(), bcs, 0.0) if a_f is not None else None
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
    springs = []
    for it in spec.interfaces:
        op = build_interface(V, mesh_data, spec, it)
        if it.kind == "contact":
            contacts.append((it, op))
            continue
        kt = it.kn if it.kind == "bonded" else it.kt
        S = itf.spring_stiffness(op, it.kn, kt)
        S.zeroRowsColumns(bc_rows, diag=0.0)
        springs.append(S)
        op.destroy()
    _add_springs(K, springs)

    t2 = time.perf_counter()
    K_parts = M_parts = plate_parts = None
    if parts:
        K_parts = dict(part_stiffnesses(V, mesh_data, spec, c3))
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


def _add_springs(K: PETSc.Mat, springs: list[PETSc.Mat]) -> None:
    """K += S_1 + S_2 + ..., each S added in turn (the same sums, to the bit, as one addition after
    another), with K's pattern grown to all of theirs once: an addition of another pattern copies K
    (MatAXPY with DIFFERENT_NONZERO_PATTERN), one within K's pattern touches the springs' rows only.
    Destroys the springs."""
    if not springs:
        return
    union = springs[0].duplicate(copy=True)
    for S in springs[1:]:
        _add(union, S)
    union.zeroEntries()
    _add(K, union)                 # K's entries + 0: unchanged; the springs' entries now in K's pattern
    union.destroy()
    for S in springs:
        K.axpy(1.0, S, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        S.destroy()


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
