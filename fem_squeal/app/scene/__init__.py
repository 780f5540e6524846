"""Scenes: TOML in, validated typed sections out in one pass, and the model description they give.

- :mod:`~fem_squeal.app.scene.files`: the raw table of a scene file (``extends`` resolved, ``--set
  a.b.c=value`` overrides applied; the value is parsed as TOML, ``0.3``, ``[1, 2]``, ``"top"``, and
  falls back to a bare string);
- :mod:`~fem_squeal.app.scene.schema`: the fields of the model sections (types, defaults, bounds and
  their documentation; each analysis's section is declared by its module in
  :mod:`fem_squeal.app.analyses`): the one place where a scene's keys are defined;
- :mod:`~fem_squeal.app.scene.validation`: :func:`validate`, the one pass from the raw table to the
  :class:`Scene` of frozen typed sections (:class:`fem_squeal.app.fields.Section`) with every default
  filled in, the checks between sections made on the typed values, and the model description built
  once (:func:`model_spec`);
- :mod:`~fem_squeal.app.scene.model`: the model description
  (:class:`~fem_squeal.fe.model.ModelSpec`) of the typed sections.

A validated scene reads ``scene.preload.tol`` (or ``scene["preload"]["tol"]``, the same value);
``scene.materials``, ``scene.interfaces`` and ``scene.analyses`` map names to their sections.  A field
that is not set reads ``None`` and its documented fallback applies.  Errors name the key path and the
reason (``SceneError("geometry.width: must be > 0 (got -0.1)")``); nothing is computed before a scene
validates.

Sections
--------
extends          another scene file (relative path) whose tables this one's are merged onto (a
                 geometry with another builder replaces the base's geometry table)
title            free text
geometry         builder = "mesh_file": file (relative to the scene file), format, scale, center, axis,
                 id_field, max_aspect_ratio, parts.<part> = [sets], faces.<face> = [sets]: a mesh from
                 gmsh/Abaqus/Nastran/VTU (see geometry.mesh_file); Abaqus decks: skip_sets (element
                 sets left out: rigid parts), deck (the scene translates the deck's model keywords:
                 fem-squeal convert model.inp scene.toml, fem_squeal.app.deck)
                 builder = "annular_disc": mean_radius, width, thickness [m], mesh_size [m],
                 order (1 or 2; 2 = curved second-order tetrahedra)
                 builder = "brake_corner": every field of ``geometry.brake_corner.BrakeCornerParams``
                 (dimensions [m], angles [deg], mesh sizes [m], matching) plus order
materials.<part> E [Pa], nu, rho [kg/m³], rayleigh_alpha [1/s], rayleigh_beta [s];
                 E_axial [Pa], nu_axial, G_axial [Pa] (all three: transversely isotropic about the axis);
                 E1 E2 E3 nu12 nu13 nu23 G12 G13 G23 (orthotropic) or D (9 or 21 Abaqus D_ijkl) in the
                 frame of orientation = {system = rectangular | cylindrical, a, b[, c]} (E, nu optional)
interfaces.<name> type = "rigid_plate": face, kn [N/m³], mu, sliding (+1 forward: the plate
                 slides in +e_θ relative to the body; −1 backward; 0 none), kt [N/m³]
                 type = "contact": slave, master (faces), kn [N/m³], mu, sliding (+1: the master
                 slides in +e_θ relative to the slave, i.e. the disc turns forward), kt [N/m³]
                 kt (contact, rigid_plate): tangential penalty on the closed contact, across the
                 sliding direction only (t₂ = n × s; sliding = 0: both tangents); default 0 (seed
                 001).  CalculiX: kt = λ/F (stick slope λ, F = μ_static/μ); ANSYS: FKT × kn;
                 Abaqus: the elastic-slip stiffness of the penalty friction law
                 friction (contact, rigid_plate): "constant" (mu) or "stribeck" (μ(V) of seed 004
                 eq. 4 with mu_s, mu_d, v_s [m/s], v_d [m/s], as analyses.transient; the law of
                 reduced.laws.friction) at V = operating.speed·r, used by the preload and K_f too;
                 the interface's nominal μ (a μ sweep scales it) is then mu_d
                 friction_damping (contact, rigid_plate; default false): the velocity terms of the
                 linearised friction force (Abaqus FRICTION DAMPING=YES) in C about the preload:
                 p μ/V t₂t₂ᵀ + p dμ/dV ssᵀ per area (p the preload pressure; a plate's is k_n (u·n)
                 of the static displacement); needs operating.speed > 0, sliding ≠ 0, mu > 0 or a
                 μ(V) law, preload.mode = "nonlinear" (contact) or loads.pressure (plate)
                 type = "spring": slave, master, kn, kt [N/m³];  type = "bonded": slave, master, kn
boundary         clamped = [face names] (all displacement components fixed);
                 fixed.<name>: face, components = subset of ["x", "y", "z"] (global axes fixed);
                 ground_springs.<name>: face, k_axial, k_transverse [N/m³]
loads            pressure.<name>: face, p [Pa] (pushes the face inwards)
preload          mode ("nonlinear": active-set Newton then linearise about the closed points;
                 "all_closed": every contact point closed, no static solve), friction (sliding
                 friction in the static step), tol, max_iterations, geometric_stiffness (default
                 false: the CEA adds K_σ = ∫ σ₀_ij ∂_i u_k ∂_j v_k of the static stress σ₀ of the
                 preload, plus the centrifugal prestress with operating.gyroscopic)
operating        speed [rad/s] (default 0: the disc speed Ω; V = Ω r at each contact point for the μ(V)
                 laws and friction_damping of the interfaces; > 0 with nothing using it is an error),
                 gyroscopic (default false: the rotating_parts turn at speed Ω about z under fixed
                 observers; the CEA gains Ω G₁ in C and −Ω² K_L in K, transport form, see
                 fem_squeal.fe.forms), rotating_parts = [part names] (default ["disc"]); gyroscopic
                 and preload.geometric_stiffness enter analyses.cea and the reduced model (reduced,
                 sweep, map, sensitivity, robustness; real_modes: at rest; the nonlinear studies
                 transient and masa are refused with them).  The reduced model has the parameter
                 "speed" (analyses.sweep.parameter = "speed", analyses.map.second = "speed") when
                 speed > 0, gyroscopic or a friction_damping uses it and no μ(V) law is set:
                 Ω G₁ in C, Ω² (K_σc − K_L) in K, the friction damping as (|μ|/|μ⁰|)(Ω₀/Ω)
discretisation   degree (1 or 2), quadrature_degree (not set: automatic), interface_quadrature_degree,
                 hexahedra ("auto", "native", "split": how a hexahedral mesh file runs)
analyses.<name>  one section per analysis, declared by its module in fem_squeal.app.analyses (the
                 registry): fields, defaults and cross-checks.  The full reference of every key, model
                 and analyses alike, is generated from these tables:
                 ``python -m fem_squeal.app.schema_reference`` (docs/reference/scene.md in the guide).
solver           petsc_options = { key = value } (given with their prefix, e.g. "cea_st_type")
"""
from __future__ import annotations

from pathlib import Path

from fem_squeal.app.scene.files import apply_overrides, merge, parse_value, read_scene
from fem_squeal.app.scene.model import build_model_spec, material
from fem_squeal.app.scene.schema import (
    FIXED,
    GEOMETRY,
    GROUND_SPRING,
    INTERFACES,
    MATERIAL,
    PRESSURE,
    SECTIONS,
    SUBTABLES,
    geometry_tags,
)
from fem_squeal.app.scene.validation import Scene, cross_check, model_spec, validate
from fem_squeal.util.errors import SceneError

__all__ = ["FIXED", "GEOMETRY", "GROUND_SPRING", "INTERFACES", "MATERIAL", "PRESSURE", "SECTIONS", "SUBTABLES",
           "Scene", "SceneError", "apply_overrides", "build_model_spec", "cross_check", "geometry_tags",
           "load_scene", "material", "merge", "model_spec", "parse_value", "read_scene", "validate"]


def load_scene(path: str | Path, overrides: list[str] | None = None) -> Scene:
    """Read a scene file (resolving ``extends``), apply the ``--set`` overrides and validate it in one
    pass: the :class:`Scene` (typed sections, and its model description :func:`model_spec`)."""
    return validate(apply_overrides(read_scene(path), overrides or []))
