"""UFL forms of 3D elastodynamics with penalty contact and friction (no PETSc here).

Notation: u trial, v test, n outward unit normal of the body's face, s unit sliding direction.

* stiffness      a_K(u, v) = ∫ σ(u) : ε(v) dx,  σ = λ tr ε I + 2G ε            (isotropic)
                 a_K(u, v) = ∫ (C ε'(u))·ε'(v) dx, ε' = Q ε Qᵀ   (anisotropic C in the frame Q)
* mass           a_M(u, v) = ∫ ρ u·v dx     (axial part ∫ ρ (u·a)(v·a) dx for energy shares)
* contact        a_c(u, v) = ∫ k_n (u·n)(v·n) ds        (penalty to a rigid plate, symmetric)
* friction       a_f(u, v) = ∫ μ k_n (u·n)(s·v) ds      (asymmetric)
* tangential     a_t(u, v) = ∫ k_t (u·t₂)(v·t₂) ds,  t₂ = n × s/|n × s|   (sliding: across s only)
  penalty                  = ∫ k_t (u − (u·n)n)·(v − (v·n)n) ds            (sticking, no sliding)
* fric. damping  a_d(u, v) = ∫ p [μ/V (u·t₂)(v·t₂) + dμ/dV (u·s)(v·s)] ds  (C: sliding speed V, preload p)
* ground spring  a_g(u, v) = ∫ k_a (u·a)(v·a) + k_t (u − (u·a)a)·(v − (v·a)a) ds
* pressure load  L_p(v)    = −∫ p (v·n) ds
* rotation       G₁(u, v)  = ∫ρ [(L u)·v − u·(L v)],  K_L(u, v) = ∫ρ (L u)·(L v),  L = x ∂_y − y ∂_x
  (transport form; rotating frame: G_c = 2∫ρ (e_z × u)·v, M_r; centrifugal load f_c; see below)
* geometric      K_σ(u, v) = ∫ σ₀_ij ∂_i u_k ∂_j v_k dx   (stress stiffening by an initial stress σ₀)

The friction *traction* on the body is t_f = μ k_n (u·n) s: a closure u·n > 0 into the plate raises
the pressure by k_n u·n and the friction force by μ times that, along the direction in which the
plate slides relative to the body.  Moving it to the left-hand side gives the operator

    M ü + C u̇ + (K + K_c − a_f) u = 0.

The assembly stores the friction stiffness as it enters the operator (``Operators.Kf`` = −a_f,
the same sign as the interface operator's μ G_sᵀ k_n G_n).

For a disc about the z axis s = ±e_θ: +1 for a plate sliding in +θ relative to the disc (forward).

Tangential penalty k_t (the industrial codes' elastic slip: CalculiX's stick slope λ per unit
pressure-area, ANSYS FKT, Abaqus's elastic-slip stiffness).  In the sliding state the tangential
traction along s is the friction force μ p (above: no stiffness along s), while across the sliding
direction the penalty spring k_t (u·t₂) stays, t₂ = n × s: a sideways relative displacement is
resisted elastically and does not turn the slip.  a_t is symmetric and μ-independent: it belongs to
the closed-contact stiffness K (with a_c), not to K_f.  k_t = 0 is the seed 001 model.
"""
from __future__ import annotations

import numpy as np
import ufl

from fem_squeal.util.errors import ModelError


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lamé parameters (λ, G) of an isotropic material."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def strain(u):
    """ε(u) = sym(∇u)."""
    return ufl.sym(ufl.grad(u))


def stress(u, E, nu):
    """σ(u) = λ tr ε(u) I + 2G ε(u)."""
    lmbda, G = lame(E, nu)
    eps = strain(u)
    return lmbda * ufl.tr(eps) * ufl.Identity(len(u)) + 2 * G * eps


def stiffness_form(u, v, E, nu, dx):
    """a_K(u, v) = ∫ σ(u) : ε(v) dx."""
    return ufl.inner(stress(u, E, nu), strain(v)) * dx


def mass_form(u, v, rho, dx):
    """a_M(u, v) = ∫ ρ u·v dx."""
    return rho * ufl.inner(u, v) * dx


def axial_mass_form(u, v, rho, dx, axis):
    """∫ ρ (u·a)(v·a) dx: the mass of the motion along the unit rotation axis a (out-of-plane)."""
    return rho * ufl.dot(u, axis) * ufl.dot(v, axis) * dx


def contact_form(u, v, kn, n, ds):
    """a_c(u, v) = ∫ k_n (u·n)(v·n) ds."""
    return kn * ufl.dot(u, n) * ufl.dot(v, n) * ds


def friction_form(u, v, kn, mu, n, s, ds):
    """a_f(u, v) = ∫ μ k_n (u·n)(s·v) ds  (enters the operator with a minus sign)."""
    return mu * kn * ufl.dot(u, n) * ufl.dot(s, v) * ds


def tangential_penalty_form(u, v, kt, n, s, ds):
    """a_t(u, v) = ∫ k_t (u·t₂)(v·t₂) ds with t₂ = n × s/|n × s| (sliding along s: the penalty acts
    across the sliding direction only); ``s`` None: ∫ k_t (u − (u·n)n)·(v − (v·n)n) ds (sticking)."""
    if s is None:
        ut, vt = u - ufl.dot(u, n) * n, v - ufl.dot(v, n) * n
        return kt * ufl.dot(ut, vt) * ds
    c = ufl.cross(n, s)
    t2 = c / ufl.sqrt(ufl.dot(c, c))
    return kt * ufl.dot(u, t2) * ufl.dot(v, t2) * ds


def friction_damping_form(u, v, p, mu, dmu, speed_V, n, s, ds):
    """a_d(u, v) = ∫ p [μ/V (u·t₂)(v·t₂) + dμ/dV (u·s)(v·s)] ds, t₂ = n × s/|n × s| (the friction
    damping of a body under a plate sliding at V s; derivation: :func:`fem_squeal.fe.preload.friction_damping`).
    ``p`` the preload pressure, ``mu``, ``dmu`` μ(V) and dμ/dV, ``speed_V`` = V = Ω r (UFL expressions)."""
    c = ufl.cross(n, s)
    t2 = c / ufl.sqrt(ufl.dot(c, c))
    return p * (mu / speed_V * ufl.dot(u, t2) * ufl.dot(v, t2) + dmu * ufl.dot(u, s) * ufl.dot(v, s)) * ds


def circumferential_direction(x, sign: float = 1.0, axis: str = "z"):
    """Unit field sign·e_θ about the z axis: e_θ = (−y, x, 0)/r."""
    if axis != "z":
        raise ModelError(f"axis: only 'z' is supported (got {axis!r})")
    r = ufl.sqrt(x[0] ** 2 + x[1] ** 2)
    return ufl.as_vector((-sign * x[1] / r, sign * x[0] / r, 0.0))


def ground_spring_form(u, v, k_axial, k_transverse, axis, ds):
    """a_g(u, v) = ∫ k_a (u·a)(v·a) + k_t (u − (u·a)a)·(v − (v·a)a) ds (springs to ground)."""
    ua, va = ufl.dot(u, axis), ufl.dot(v, axis)
    return (k_axial * ua * va + k_transverse * ufl.dot(u - ua * axis, v - va * axis)) * ds


def pressure_load_form(v, p, n, ds):
    """L_p(v) = −∫ p (v·n) ds: a pressure pushes the face inwards."""
    return -p * ufl.dot(v, n) * ds


def voigt_strain(u):
    """Engineering strains (ε_xx, ε_yy, ε_zz, γ_yz, γ_xz, γ_xy)."""
    e = strain(u)
    return ufl.as_vector([e[0, 0], e[1, 1], e[2, 2], 2 * e[1, 2], 2 * e[0, 2], 2 * e[0, 1]])


def voigt(e):
    """Engineering Voigt vector (e_xx, e_yy, e_zz, 2e_yz, 2e_xz, 2e_xy) of a symmetric tensor."""
    return ufl.as_vector([e[0, 0], e[1, 1], e[2, 2], 2 * e[1, 2], 2 * e[0, 2], 2 * e[0, 1]])


def tensor_of_voigt(s):
    """The symmetric tensor of a Voigt stress vector (s_xx, s_yy, s_zz, s_yz, s_xz, s_xy)."""
    return ufl.as_matrix([[s[0], s[5], s[4]], [s[5], s[1], s[3]], [s[4], s[3], s[2]]])


def rotated_voigt(C: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The 6×6 stiffness in global axes of C (6×6, the material frame whose unit vectors are the rows of Q):
    C_ijkl = Q_pi Q_qj Q_rk Q_sl C'_pqrs (ε' = Q ε Qᵀ; with engineering shear strains the Voigt entries are
    the tensor components)."""
    pairs = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
    T = np.zeros((3, 3, 3, 3))
    for r, (i, j) in enumerate(pairs):
        for c_, (k, m) in enumerate(pairs):
            for a, b in {(i, j), (j, i)}:
                for c, d in {(k, m), (m, k)}:
                    T[a, b, c, d] = C[r, c_]
    G = np.einsum("pi,qj,rk,sl,pqrs->ijkl", Q, Q, Q, Q, T)
    return np.array([[G[i, j, k, m] for (k, m) in pairs] for (i, j) in pairs])


def cylindrical_frame(x, point, axis):
    """Q(x): rows e₁ = radial (from the axis through ``point`` along the unit ``axis``), e₂ = e₃ × e₁
    (tangential), e₃ = axis, at the spatial coordinate x."""
    a = ufl.as_vector([float(c) for c in axis])
    d = x - ufl.as_vector([float(c) for c in point])
    r = d - ufl.dot(d, a) * a
    e1 = r / ufl.sqrt(ufl.dot(r, r))
    e2 = ufl.cross(a, e1)
    return ufl.as_matrix([[e1[i] for i in range(3)], [e2[i] for i in range(3)], [a[i] for i in range(3)]])


def _anisotropic_parts(u, mat):
    """(C, Q): the Voigt stiffness and the frame of an anisotropic material for ``u``'s mesh: C global and
    Q None when the frame is constant (no orientation, or rectangular: C rotated here), else C in the
    material frame and Q(x) (cylindrical)."""
    C, o = mat.local_stiffness(), mat.orientation
    if o is None:
        return C, None
    if o.system == "rectangular":
        return rotated_voigt(C, o.frame()), None
    return C, cylindrical_frame(ufl.SpatialCoordinate(u.ufl_function_space().mesh), *o.axis())


def varying_frame_measure(dx, u, mat, quadrature_degree: int | None = None):
    """``dx`` for a form of ``mat``: with a cylindrical material frame on simplices and no
    ``quadrature_degree`` set, the rule of degree 2p + 2 (p the degree of ``u``'s element, as the interface
    forms; UFL's estimate of the rational Q(x) is about 22, 1728 points per cell); hexahedra keep the
    element's Gauss rule (:func:`fem_squeal.fe.hexahedra.with_cell_rule`, CalculiX's points), a set degree
    goes in as always."""
    o = getattr(mat, "orientation", None)
    if o is None or o.system != "cylindrical" or quadrature_degree is not None:
        return dx
    if u.ufl_function_space().mesh.ufl_cell().cellname() == "hexahedron":
        return dx
    return dx.reconstruct(metadata={"quadrature_degree": 2 * u.ufl_element().degree() + 2})


def material_stiffness_form(u, v, mat, dx, quadrature_degree: int | None = None):
    """a_K(u, v) = ∫ (C ε(u))·ε(v) dx: isotropic form, or Voigt form of an anisotropic C (6×6); in a
    cylindrical material frame Q(x) (rows e_r, e_θ, e_z): ∫ (C ε'(u))·ε'(v) dx with ε' = Q ε Qᵀ
    (``quadrature_degree``: :func:`varying_frame_measure`)."""
    if getattr(mat, "anisotropic", False):
        C, Q = _anisotropic_parts(u, mat)
        Cu = ufl.as_matrix(C.tolist())
        if Q is None:
            return ufl.dot(Cu * voigt_strain(u), voigt_strain(v)) * dx
        return ufl.dot(Cu * voigt(Q * strain(u) * Q.T), voigt(Q * strain(v) * Q.T)) * \
            varying_frame_measure(dx, u, mat, quadrature_degree)
    if not getattr(mat, "transversely_isotropic", False):
        return stiffness_form(u, v, mat.E, mat.nu, dx)
    C = ufl.as_matrix(mat.voigt_stiffness().tolist())
    return ufl.dot(C * voigt_strain(u), voigt_strain(v)) * dx


# --- rotation of a part about the z axis (issue 20 item 4) and stress stiffening (item 5) -------------
#
# Transport (space-fixed) form: a part spinning at Ω about e_z carries a displacement field u(x, t) in
# fixed Cartesian components; a particle's velocity is Ω e_z × x + Du/Dt with D/Dt = ∂/∂t + Ω L and
# L u = (e_z × x)·∇u = x ∂_y u − y ∂_x u (each Cartesian component differentiated along the circle).
# The kinetic energy ½∫ρ|u̇ + Ω L u|² gives, by Lagrange's equations and without integration by parts,
#     M ü + Ω G₁ u̇ + (K − Ω² K_L) u = Ω² f_c,
#     G₁(u, v) = ∫ρ [(L u)·v − u·(L v)]   (exactly skew; = 2∫ρ (L u)·v on an axisymmetric domain),
#     K_L(u, v) = ∫ρ (L u)·(L v)            (symmetric, positive semi-definite: −Ω²K_L softens),
#     f_c(v)    = ∫ρ (x − (x·e_z)e_z)·v     (the centrifugal load, from the cross term of ½∫ρ|Ω e_z × x|²).
# Rotating (co-rotating Cartesian) frame, for comparison: M ü + Ω G_c u̇ + (K − Ω² M_r) u = Ω² f_c with
#     G_c(u, v) = 2∫ρ (e_z × u)·v and M_r(u, v) = ∫ρ (u − (u·e_z)e_z)·(v − (v·e_z)e_z).
# L acting on Cartesian components is ∂_θ on cylindrical components plus e_z ×, so for a k-diameter
# mode the two frames' eigenvalues differ by ∓ikΩ (λ_fixed = λ_rot − ikΩ for the harmonic e^{ikθ}).

def circumferential_derivative(u, x):
    """L u = (e_z × x)·∇u = x ∂_y u − y ∂_x u (Cartesian components): ∂u/∂θ at fixed Cartesian basis."""
    w = ufl.as_vector((-x[1], x[0], 0.0))
    return ufl.grad(u) * w


def gyroscopic_form(u, v, rho, x, dx):
    """G₁(u, v) = ∫ρ [(L u)·v − u·(L v)] per unit Ω (transport form; exactly skew, G = Ω G₁ multiplies u̇)."""
    return rho * (ufl.dot(circumferential_derivative(u, x), v) - ufl.dot(u, circumferential_derivative(v, x))) * dx


def convective_form(u, v, rho, x, dx):
    """K_L(u, v) = ∫ρ (L u)·(L v) per unit Ω² (enters the stiffness as −Ω² K_L)."""
    return rho * ufl.dot(circumferential_derivative(u, x), circumferential_derivative(v, x)) * dx


def coriolis_form(u, v, rho, axis, dx):
    """G_c(u, v) = 2∫ρ (a × u)·v per unit Ω (rotating frame; multiplies u̇)."""
    return 2 * rho * ufl.dot(ufl.cross(axis, u), v) * dx


def spin_softening_form(u, v, rho, axis, dx):
    """M_r(u, v) = ∫ρ (u − (u·a)a)·(v − (v·a)a) per unit Ω² (rotating frame; enters as −Ω² M_r)."""
    return rho * ufl.dot(u - ufl.dot(u, axis) * axis, v - ufl.dot(v, axis) * axis) * dx


def centrifugal_load_form(v, rho, x, axis, dx):
    """f_c(v) = ∫ρ (x − (x·a)a)·v per unit Ω² (the axis a through the origin)."""
    return rho * ufl.dot(x - ufl.dot(x, axis) * axis, v) * dx


def material_stress(u, mat):
    """σ(u) = C ε(u) as a tensor: isotropic, the Voigt stiffness of a transversely isotropic material, or of
    an anisotropic one (cylindrical frame Q(x): σ = Qᵀ σ'(Q ε Qᵀ) Q)."""
    if getattr(mat, "anisotropic", False):
        C, Q = _anisotropic_parts(u, mat)
        Cu = ufl.as_matrix(C.tolist())
        if Q is None:
            return tensor_of_voigt(Cu * voigt_strain(u))
        return Q.T * tensor_of_voigt(Cu * voigt(Q * strain(u) * Q.T)) * Q
    if not getattr(mat, "transversely_isotropic", False):
        return stress(u, mat.E, mat.nu)
    s = ufl.as_matrix(mat.voigt_stiffness().tolist()) * voigt_strain(u)
    return ufl.as_matrix([[s[0], s[5], s[4]], [s[5], s[1], s[3]], [s[4], s[3], s[2]]])


def geometric_stiffness_form(u, v, sigma0, dx):
    """K_σ(u, v) = ∫ σ₀_ij ∂_i u_k ∂_j v_k dx = ∫ (∇u σ₀) : ∇v dx (initial-stress stiffness; symmetric
    for a symmetric σ₀, zero for σ₀ = 0)."""
    return ufl.inner(ufl.grad(u) * sigma0, ufl.grad(v)) * dx
