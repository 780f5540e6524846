"""UFL forms of 3D elastodynamics with penalty contact and friction (no PETSc here).

Notation: u trial, v test, n outward unit normal of the body's face, s unit sliding direction.

* stiffness      a_K(u, v) = ∫ σ(u) : ε(v) dx,  σ = λ tr ε I + 2G ε            (isotropic)
* mass           a_M(u, v) = ∫ ρ u·v dx     (axial part ∫ ρ (u·a)(v·a) dx for energy shares)
* contact        a_c(u, v) = ∫ k_n (u·n)(v·n) ds        (penalty to a rigid plate, symmetric)
* friction       a_f(u, v) = ∫ μ k_n (u·n)(s·v) ds      (asymmetric)
* tangential     a_t(u, v) = ∫ k_t (u·t₂)(v·t₂) ds,  t₂ = n × s/|n × s|   (sliding: across s only)
  penalty                  = ∫ k_t (u − (u·n)n)·(v − (v·n)n) ds            (sticking, no sliding)
* ground spring  a_g(u, v) = ∫ k_a (u·a)(v·a) + k_t (u − (u·a)a)·(v − (v·a)a) ds
* pressure load  L_p(v)    = −∫ p (v·n) ds

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


def material_stiffness_form(u, v, mat, dx):
    """a_K(u, v) = ∫ (C ε(u))·ε(v) dx: isotropic form, or Voigt form of an anisotropic C (6×6)."""
    if not getattr(mat, "transversely_isotropic", False):
        return stiffness_form(u, v, mat.E, mat.nu, dx)
    C = ufl.as_matrix(mat.voigt_stiffness().tolist())
    return ufl.dot(C * voigt_strain(u), voigt_strain(v)) * dx
