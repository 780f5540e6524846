"""A minimal mode-coupling friction oscillator for MASA (Hoffmann-type two-DOF model).

A unit point mass (x tangential, y normal) hangs on two inclined springs; it is pressed by the
load N₀ onto a belt that slides in +x.  The contact is one element with the unilateral cubic law
(closure δ = δ₀ − y), the friction force μF(δ) acts along +x.  In the notation of
:mod:`fem_squeal.reduced.masa`: D = [0, −1], T = [1, 0], B = D − μT = [−μ, −1], so the CEA
stiffness is

    K + J_nl = [[k₁₁, k₁₂ + μk_t], [k₁₂, k₂₂ + k_t]],     k_t = ∂F(δ_s)

which flutters (mode coupling) once 4k₁₂(k₁₂ + μk_t) < −(k₁₁ − k₂₂ − k_t)².  The load f is the one
that holds the mass at x = 0 with the contact carrying the preload N₀ at the closure δ_s where its
tangent is k_contact (the springs are pre-stressed by the mounting).
"""
from __future__ import annotations

import numpy as np

from fem_squeal.reduced.laws.contact import UnilateralLaw, tune_cubic
from fem_squeal.reduced.masa import ContactSet, MasaModel


def two_dof_model(*, mu: float = 0.4, k11: float = 4.2e7, k22: float = 3.0e7, k12: float = -2.0e6,
                  k_contact: float = 1.0e7, preload: float = 100.0, cubic_share: float = 0.3,
                  zeta: float = 0.0, c_max: float = 0.0, depth: float = np.inf) -> MasaModel:
    """The model of the module docstring.  ``k_contact`` is the contact's tangent stiffness at
    the preload (split into k_l and k_nl by :func:`tune_cubic`), ``zeta`` a modal damping ratio
    of the contact-free structure (C = 2ζ√K), ``c_max``/``depth`` the contact damping of seed 004."""
    K = np.array([[k11, k12], [k12, k22]])
    k_l, k_nl, d_s = tune_cubic(k_contact, preload, cubic_share)
    law = UnilateralLaw(k_l=np.array([k_l]), k_nl=np.array([k_nl]), c_max=np.array([c_max]),
                        depth=np.array([depth]))
    w, V = np.linalg.eigh(K)
    C = (V * (2 * zeta * np.sqrt(w))) @ V.T if zeta > 0 else None
    contact = ContactSet(D=np.array([[0.0, -1.0]]), T=np.array([[1.0, 0.0]]), d0=np.zeros(1), law=law, mu=mu,
                         weight=np.ones(1), x=np.zeros((1, 3)), name="belt")
    # the load that holds the mass at x = 0 with the contact carrying the preload at closure δ_s
    q_s = np.array([0.0, -float(d_s)])
    f = K @ q_s + contact.B[0] * preload
    return MasaModel(K=K, contacts=[contact], C=C, f=f)
