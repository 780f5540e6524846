"""The reduced (modal projection) layer: plain NumPy/SciPy, no dolfinx, no PETSc.

A :class:`~fem_squeal.reduced.model.ReducedModel` holds the matrices of a full model projected on
a mass-orthonormal basis Φ (seed 001 eq. 5, generalised): (λ²I + λC(p) + K(p))y = 0 with
K(p) = K₀ + Σᵢ(θᵢ − 1)Kᵢ + sign(v)μ K_f¹, θᵢ = Eᵢ/Eᵢ⁰.  On top of it: batched quadratic
eigen-solves (:mod:`.eigensolve`), parameter grids evaluated over MPI ranks (:mod:`.sweep`),
MAC-based mode tracking with coalescence detection (:mod:`.tracking`) and stability maps
(:mod:`.stability_map`).  The full-order side that builds the model is
:mod:`fem_squeal.fe.projection`.
"""
