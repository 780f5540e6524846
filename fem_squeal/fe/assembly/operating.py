"""The operating conditions: rotation (gyroscopic, centrifugal), stress stiffening about a static state,
and the operators at a speed as an affine combination of terms."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_squeal.fe import forms
from fem_squeal.fe.assembly.compiled import _add, _assemble, _compile, _owned_global_rows
from fem_squeal.fe.assembly.operators import Operators
from fem_squeal.fe.assembly.static import static_displacement
from fem_squeal.fe.model import ModelSpec
from fem_squeal.util.errors import ModelError, UnknownNameError


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
