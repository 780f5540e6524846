"""Scene files: TOML → validated, defaulted, typed sections → model description.

:func:`validate` returns the scene as frozen sections (:class:`fem_squeal.app.fields.Section`), made
from the field tables below: ``scene.preload.tol`` (or ``scene["preload"]["tol"]``, the same value);
``scene.materials``, ``scene.interfaces`` and ``scene.analyses`` map names to their sections.  A field
that is not set reads ``None`` and its documented fallback applies.

The model sections' schema below and the analyses' sections (``fem_squeal.app.analyses``) are the one
place where keys, types, bounds and defaults are defined.  Errors
name the key path and the reason (``SceneError("geometry.width: must be > 0 (got -0.1)")``);
nothing is computed before a scene validates.  ``--set a.b.c=value`` overrides any key; the
value is parsed as TOML (``0.3``, ``[1, 2]``, ``"top"``) and falls back to a bare string.

Sections
--------
extends          another scene file (relative path) whose tables this one's are merged onto (a
                 geometry with another builder replaces the base's geometry table)
title            free text
geometry         builder = "mesh_file": file (relative to the scene file), format, scale, center, axis,
                 id_field, max_aspect_ratio, parts.<part> = [sets], faces.<face> = [sets]: a mesh from
                 gmsh/Abaqus/Nastran/VTU (see geometry.mesh_file)
                 builder = "annular_disc": mean_radius, width, thickness [m], mesh_size [m],
                 order (1 or 2; 2 = curved second-order tetrahedra)
                 builder = "brake_corner": every field of ``geometry.brake_corner.BrakeCornerParams``
                 (dimensions [m], angles [deg], mesh sizes [m], matching) plus order
materials.<part> E [Pa], nu, rho [kg/m³], rayleigh_alpha [1/s], rayleigh_beta [s];
                 E_axial [Pa], nu_axial, G_axial [Pa] (all three: transversely isotropic about the axis)
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
discretisation   degree (1 or 2), quadrature_degree (not set: automatic), interface_quadrature_degree
analyses.<name>  one section per analysis, declared by its module in fem_squeal.app.analyses (the
                 registry): fields, defaults and cross-checks.  The full reference of every key, model
                 and analyses alike, is generated from these tables:
                 ``python -m fem_squeal.app.schema_reference`` (docs/reference/scene.md in the guide).
solver           petsc_options = { key = value } (given with their prefix, e.g. "cea_st_type")
"""
from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path
from typing import Any

from fem_squeal.app.analyses import ANALYSES, STAGES
from fem_squeal.app.fields import (
    REAL,
    Field,
    Section,
    at_least,
    check_fields,
    dataclass_fields,
    freeze,
    non_negative,
    nonempty_str,
    one_of,
    poisson,
    positive,
)
from fem_squeal.fe.model import FixedFace, GroundSpring, Interface, Material, ModelSpec, Pressure, RigidPlate
from fem_squeal.reduced.laws.friction import FRICTION_LAWS
from fem_squeal.util.errors import SceneError
from geometry.brake_corner import BrakeCornerParams
from geometry.mesh_file import MeshImportError, file_format
from geometry.tags import GEOMETRY_TAGS, mesh_file_tags


def _brake_corner_fields() -> dict[str, Field]:

    return {"builder": Field(str), **dataclass_fields(BrakeCornerParams),
            "order": Field(int, 2, one_of(1, 2), "geometry order: 2 = curved tetrahedra")}


GEOMETRY = {
    "annular_disc": {
        "builder": Field(str),
        "mean_radius": Field(REAL, check=positive, doc="mean radius R [m]"),
        "width": Field(REAL, check=positive, doc="radial width b [m]"),
        "thickness": Field(REAL, check=positive, doc="axial thickness h [m]"),
        "mesh_size": Field(REAL, check=positive, doc="target element size [m]"),
        "order": Field(int, 2, one_of(1, 2), "geometry order: 2 = curved tetrahedra"),
    },
    "brake_corner": _brake_corner_fields(),
    "mesh_file": {
        "builder": Field(str),
        "file": Field(str, check=nonempty_str,
                      doc="mesh file (.msh, .inp, .bdf/.nas, .vtu), relative to the scene"),
        "format": Field(str, "", None, "meshio format name; '' = from the extension"),
        "scale": Field(REAL, 1.0, positive, "length factor to metres (0.001 for a mesh in mm)"),
        "center": Field(list, [0.0, 0.0, 0.0], None, "a point of the disc axis, after scaling [m]"),
        "axis": Field(list, [0.0, 0.0, 1.0], None, "disc axis; the mesh is turned so that it becomes +z"),
        "id_field": Field(str, "", None, "integer cell data holding set numbers; '' = automatic"),
        "max_aspect_ratio": Field(REAL, 10.0, at_least(1), "warn about elements of larger aspect ratio"),
        "parts": Field(dict, check=lambda v: None if v else "must map at least one part",
                       doc="part -> [element sets / PSOLID IDs / physical groups / cell-data values]"),
        "faces": Field(dict, {}, None, "face -> [surfaces / node sets / surface PIDs / physical groups]"),
    },
}


def _set_lists(table: dict, key: str) -> dict[str, list]:
    """geometry.parts / geometry.faces: name -> non-empty list of set names or numbers."""
    out = {}
    for name, sets in table.items():
        sets = sets if isinstance(sets, list) else [sets]
        if not sets or not all(isinstance(x, (str, int)) and not isinstance(x, bool) for x in sets):
            raise SceneError(f"geometry.{key}.{name}: must be a set name or number, or a non-empty list of them "
                             f"(got {table[name]!r})")
        out[name] = [str(x) for x in sets]
    return out


def _check_mesh_file(geo: dict) -> None:
    for key in ("center", "axis"):
        v = geo[key]
        if len(v) != 3 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            raise SceneError(f"geometry.{key}: must be [x, y, z] (got {v!r})")
    if math.hypot(*geo["axis"]) == 0:
        raise SceneError("geometry.axis: must not be zero")
    if len(geo["parts"]) > 100:
        raise SceneError(f"geometry.parts: at most 100 parts (got {len(geo['parts'])})")
    geo["parts"] = _set_lists(geo["parts"], "parts")
    geo["faces"] = _set_lists(geo["faces"], "faces")
    clash = sorted(set(geo["parts"]) & set(geo["faces"]))
    if clash:
        raise SceneError(f"geometry.faces.{clash[0]}: also a part name; use distinct names")

    if not Path(geo["file"]).is_file():
        raise SceneError(f"geometry.file: {geo['file']} does not exist (a relative path in a scene file is "
                         "taken from its folder, in --set from the current folder)")
    try:
        file_format(Path(geo["file"]), geo["format"])
    except MeshImportError as e:
        raise SceneError(str(e)) from None


def geometry_tags(geo: dict) -> tuple[dict[str, int], dict[str, int]]:
    """Part and face tags of a validated geometry section."""
    if geo["builder"] == "mesh_file":

        return mesh_file_tags(list(geo["parts"]), list(geo["faces"]))
    return dict(GEOMETRY_TAGS[geo["builder"]][0]), dict(GEOMETRY_TAGS[geo["builder"]][1])
MATERIAL = {
    "E": Field(REAL, check=positive, doc="Young's modulus [Pa]"),
    "nu": Field(REAL, check=poisson, doc="Poisson's ratio"),
    "rho": Field(REAL, check=positive, doc="density [kg/m³]"),
    "rayleigh_alpha": Field(REAL, 0.0, non_negative, "mass-proportional damping [1/s]"),
    "rayleigh_beta": Field(REAL, 0.0, non_negative, "stiffness-proportional damping [s]"),
    "E_axial": Field(REAL, None, positive, "transversely isotropic: modulus along the axis [Pa]"),
    "nu_axial": Field(REAL, None, None, "transversely isotropic: in-plane contraction under axial stress"),
    "G_axial": Field(REAL, None, positive, "transversely isotropic: shear modulus of axial planes [Pa]"),
    "eta": Field(REAL, 0.0, non_negative, "loss factor η: structural damping K(1 + iη) of the part, in the "
                 "reduced model (whose basis then carries the part's stiffness) and its full-order checks (the "
                 "real problem of twice the size); analyses.cea, with real arithmetic, leaves it out"),
}
_TYPE = Field(str, "rigid_plate", one_of("rigid_plate", "contact", "spring", "bonded"))
_PAIR = {"slave": Field(str, check=nonempty_str, doc="slave face (quadrature side: the lining)"),
         "master": Field(str, check=nonempty_str, doc="master face (the disc)")}
_FRICTION = {"mu": Field(REAL, 0.0, non_negative, "friction coefficient"),
             "sliding": Field(int, 1, one_of(-1, 0, 1), "+1 forward (+e_θ), -1 backward, 0 none")}
_KT = Field(REAL, 0.0, non_negative, "tangential penalty across the sliding direction [N/m³] (0: seed 001)")
#: the friction law of a sliding contact or plate and its velocity terms (names as in analyses.transient)
_SPEED_LAWS = ("constant", "stribeck")
_FRICTION_LAW = {
    "friction": Field(str, "constant", one_of(*_SPEED_LAWS),
                      "constant: mu; stribeck: μ(V) of seed 004 eq. 4 at V = operating.speed·r (mu_s, mu_d, "
                      "v_s, v_d), in the preload and K_f too"),
    "mu_s": Field(REAL, None, positive, "static μ (stribeck); not set: mu", unset=0),
    "mu_d": Field(REAL, None, positive, "dynamic μ (stribeck; the nominal μ a μ sweep scales); not set: mu",
                  unset=0),
    "v_s": Field(REAL, 1e-3, positive, "Stribeck static transition velocity [m/s]"),
    "v_d": Field(REAL, 1e-2, positive, "Stribeck dynamic transition velocity [m/s]"),
    "friction_damping": Field(bool, False, None, "velocity terms of the linearised friction force (Abaqus "
                              "FRICTION DAMPING=YES): p μ/V t₂t₂ᵀ + p dμ/dV ssᵀ in C; needs operating.speed > 0"),
}
INTERFACES = {
    "rigid_plate": {"type": _TYPE, "face": Field(str, check=nonempty_str, doc="face name of the geometry"),
                    "kn": Field(REAL, check=non_negative, doc="penalty stiffness per area [N/m³]"), **_FRICTION,
                    "kt": _KT, **_FRICTION_LAW},
    "contact": {"type": _TYPE, **_PAIR, "kn": Field(REAL, check=positive, doc="penalty [N/m³]"), **_FRICTION,
                "kt": _KT, **_FRICTION_LAW},
    "spring": {"type": _TYPE, **_PAIR, "kn": Field(REAL, check=positive, doc="normal stiffness [N/m³]"),
               "kt": Field(REAL, 0.0, non_negative, "tangential stiffness [N/m³]")},
    "bonded": {"type": _TYPE, **_PAIR, "kn": Field(REAL, 1e14, positive, "tie penalty [N/m³]")},
}
FIXED = {
    "face": Field(str, check=nonempty_str),
    "components": Field(list, check=lambda v: None if v and all(c in ("x", "y", "z") for c in v) and
                        len(set(v)) == len(v) else f"must be a non-empty subset of ['x', 'y', 'z'] (got {v!r})",
                        doc="global displacement components held at 0"),
}
GROUND_SPRING = {
    "face": Field(str, check=nonempty_str),
    "k_axial": Field(REAL, 0.0, non_negative, "stiffness along the axis [N/m³]"),
    "k_transverse": Field(REAL, 0.0, non_negative, "stiffness across the axis [N/m³]"),
}
PRESSURE = {"face": Field(str, check=nonempty_str), "p": Field(REAL, check=None, doc="pressure [Pa]")}
SECTIONS = {
    "boundary": {"clamped": Field(list, [], None, "faces with all displacements fixed"),
                 "fixed": Field(dict, {}, None, "name -> {face, components}: global components fixed"),
                 "ground_springs": Field(dict, {}, None, "name -> {face, k_axial, k_transverse}")},
    "loads": {"pressure": Field(dict, {}, None, "name -> {face, p}")},
    "preload": {
        "mode": Field(str, "nonlinear", one_of("nonlinear", "all_closed")),
        "friction": Field(bool, True, None, "sliding friction in the static step"),
        "tol": Field(REAL, 1e-9, positive, "Newton tolerance on ‖R‖/‖f‖"),
        "max_iterations": Field(int, 25, positive),
        "geometric_stiffness": Field(bool, False, None, "stress stiffening K_σ(σ₀) of the static stress in the "
                                     "CEA (preload, and the centrifugal prestress with operating.gyroscopic)"),
    },
    "discretisation": {
        "degree": Field(int, 2, one_of(1, 2), "Lagrange degree (P1 locks in bending)"),
        "quadrature_degree": Field(int, None, positive, "not set: estimated by the form compiler", unset=0),
        "interface_quadrature_degree": Field(int, 4, positive, "slave-surface quadrature of interfaces"),
    },
    "operating": {
        "speed": Field(REAL, 0.0, non_negative, "disc speed Ω [rad/s] (sliding speed V = Ω r at each contact "
                       "point); 0 = no velocity terms"),
        "gyroscopic": Field(bool, False, None, "the disc's rotation in the space-fixed frame (gyroscopic and "
                            "convective terms; needs speed > 0)"),
        "rotating_parts": Field(list, ["disc"], None, "parts that turn at operating.speed about z (with "
                                "gyroscopic = true)"),
    },
    "solver": {"petsc_options": Field(dict, {}, None, "PETSc options, with their solver prefix")},
}


def validate(raw: dict) -> dict:
    """Validated scene with defaults filled in; raises :class:`SceneError`."""
    if not isinstance(raw, dict):
        raise SceneError("scene: must be a table")
    allowed = {"title", "geometry", "materials", "interfaces", "analyses", *SECTIONS}
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise SceneError(f"{unknown[0]}: unknown section; allowed: {sorted(allowed)}")
    scene: dict[str, Any] = {"title": raw.get("title", "")}
    if not isinstance(scene["title"], str):
        raise SceneError("title: must be a string")
    ana = raw.get("analyses")
    if not isinstance(ana, dict) or not ana:
        raise SceneError(f"analyses: required, at least one of {sorted(ANALYSES)}")
    if all(name in STAGES and STAGES[name].lumped for name in ana) and "geometry" not in raw:
        return _validate_lumped(raw, scene)
    geo = raw.get("geometry")
    if not isinstance(geo, dict):
        raise SceneError("geometry: required table")
    if "builder" not in geo:
        raise SceneError("geometry.builder: required; one of " + str(sorted(GEOMETRY)))
    if not isinstance(geo["builder"], str) or geo["builder"] not in GEOMETRY:
        raise SceneError(f"geometry.builder: must be one of {sorted(GEOMETRY)} (got {geo['builder']!r})")
    scene["geometry"] = check_fields(geo, GEOMETRY[geo["builder"]], "geometry")
    builder = geo["builder"]
    if builder == "mesh_file":
        _check_mesh_file(scene["geometry"])
    volumes, faces = geometry_tags(scene["geometry"])
    if builder == "annular_disc" and scene["geometry"]["width"] >= 2 * scene["geometry"]["mean_radius"]:
        raise SceneError("geometry.width: must be < 2 * mean_radius")
    if builder == "brake_corner":

        params = {k: v for k, v in scene["geometry"].items() if k not in ("builder", "order")}
        try:
            BrakeCornerParams(**params)
        except (ValueError, TypeError) as e:
            msg = str(e)
            raise SceneError(msg if msg.startswith("geometry.") else f"geometry: {msg}") from None

    mats = raw.get("materials")
    if not isinstance(mats, dict) or not mats:
        raise SceneError(f"materials: required, one table per part {sorted(volumes)}")
    scene["materials"] = {}
    for part, table in mats.items():
        if part not in volumes:
            raise SceneError(f"materials.{part}: unknown part; parts of {builder}: {sorted(volumes)}")
        scene["materials"][part] = m = check_fields(table, MATERIAL, f"materials.{part}")
        try:
            Material(**m)
        except ValueError as e:
            raise SceneError(f"materials.{part}.{e}") from None
    missing = sorted(set(volumes) - set(mats))
    if missing:
        raise SceneError(f"materials.{missing[0]}: required (no material for this part)")

    scene["interfaces"] = {}
    interfaces = raw.get("interfaces", {})
    if not isinstance(interfaces, dict):
        raise SceneError(f"interfaces: must be a table of interfaces (got {type(interfaces).__name__})")
    def known_face(face, key):
        if face not in faces:
            raise SceneError(f"{key}: unknown face {face!r}; faces: {sorted(faces)}")

    for name, table in interfaces.items():
        key = f"interfaces.{name}"
        if not isinstance(table, dict):
            raise SceneError(f"{key}: must be a table (got {type(table).__name__})")
        kind = table.get("type", "rigid_plate")
        if not isinstance(kind, str) or kind not in INTERFACES:
            raise SceneError(f"{key}.type: must be one of {sorted(INTERFACES)} (got {kind!r})")
        t = check_fields(table, INTERFACES[kind], key)
        for side in ("face", "slave", "master"):
            if side in t:
                known_face(t[side], f"{key}.{side}")
        if "slave" in t and t["slave"] == t["master"]:
            raise SceneError(f"{key}.master: must differ from the slave face ({t['slave']!r})")
        scene["interfaces"][name] = t

    for sec, fields in SECTIONS.items():
        scene[sec] = check_fields(raw.get(sec, {}), fields, sec)
    for i, f in enumerate(scene["boundary"]["clamped"]):
        if not isinstance(f, str):
            raise SceneError(f"boundary.clamped[{i}]: must be a face name (got {f!r})")
        known_face(f, f"boundary.clamped[{i}]")
    _check_fixed(scene["boundary"], known_face)
    for sec, sub, fields in (("boundary", "ground_springs", GROUND_SPRING), ("loads", "pressure", PRESSURE)):
        checked = {}
        for name, table in scene[sec][sub].items():
            key = f"{sec}.{sub}.{name}"
            t = check_fields(table, fields, key)
            known_face(t["face"], f"{key}.face")
            if sub == "ground_springs" and t["k_axial"] + t["k_transverse"] <= 0:
                raise SceneError(f"{key}: k_axial and k_transverse must not both be 0")
            checked[name] = t
        scene[sec][sub] = checked
    has_contact = any(t["type"] == "contact" for t in scene["interfaces"].values())
    if has_contact and scene["preload"]["mode"] == "nonlinear" and not scene["loads"]["pressure"]:
        raise SceneError("loads.pressure: required for preload.mode = 'nonlinear' with contact interfaces "
                         "(or set preload.mode = 'all_closed')")

    scene["analyses"] = _check_analyses(ana)
    _check_speed_terms(scene)
    _check_rotation(scene, volumes)
    typed = _typed(scene)
    _cross_check(typed, volumes)
    return typed


def _check_rotation(scene: dict, volumes) -> None:
    """operating.rotating_parts: a list of part names (checked against the geometry's parts when
    gyroscopic is true; then it must not be empty) and gyroscopic = true needs speed > 0.  The rotation
    and the stress stiffening enter the CEA and the reduced model (real_modes stay the modes at rest);
    the nonlinear studies (transient, masa and those built on them) are refused with them."""
    op = scene["operating"]
    parts = op["rotating_parts"]
    if not isinstance(parts, list) or not all(isinstance(p, str) for p in parts):
        raise SceneError(f"operating.rotating_parts: must be a list of part names (got {parts!r})")
    if len(set(parts)) != len(parts):
        raise SceneError(f"operating.rotating_parts: a part is listed twice (got {parts!r})")
    terms = [k for k, on in (("operating.gyroscopic", op["gyroscopic"]),
                             ("preload.geometric_stiffness", scene["preload"]["geometric_stiffness"])) if on]
    studies = sorted(set(scene["analyses"]) - {"cea", "real_modes", "reduced", "sweep", "map", "sensitivity",
                                               "robustness"})
    if terms and studies:
        raise SceneError(f"{terms[0]}: the nonlinear study analyses.{studies[0]} does not include it "
                         f"(remove that analysis or set {terms[0]} = false)")
    if not op["gyroscopic"]:
        return
    if not parts:
        raise SceneError("operating.rotating_parts: must name at least one part when operating.gyroscopic "
                         f"is true; parts: {sorted(volumes)}")
    for i, p in enumerate(parts):
        if p not in volumes:
            raise SceneError(f"operating.rotating_parts[{i}]: unknown part {p!r}; parts: {sorted(volumes)}")
    if not op["speed"] > 0:
        raise SceneError(f"operating.speed: must be > 0 when operating.gyroscopic is true (got {op['speed']})")


def _check_speed_terms(scene: dict) -> None:
    """operating.speed against the friction laws and friction damping of the interfaces: a μ(V) law and
    friction damping need speed > 0, a sliding interface with μ, the preload pressure they scale with,
    and no nonlinear study (transient, masa: their friction laws carry the velocity terms themselves);
    a speed > 0 that nothing uses is an error."""
    speed = scene["operating"]["speed"]
    used = bool(scene["operating"].get("gyroscopic", False))
    for name, t in scene["interfaces"].items():
        if "friction" not in t:
            continue
        key = f"interfaces.{name}"
        law = t["friction"] != "constant"
        if law:
            if not speed > 0:
                raise SceneError(f"operating.speed: must be > 0 when {key}.friction = {t['friction']!r} "
                                 f"(μ(V) at V = speed·r; got {speed})")
            if not (t["mu_d"] or t["mu"]) > 0:
                raise SceneError(f"{key}.mu_d: must be > 0 with friction = {t['friction']!r} (or give mu)")
            if t["v_d"] <= t["v_s"]:
                raise SceneError(f"{key}.v_d: must be > v_s = {t['v_s']} (got {t['v_d']})")
            used = True
        if not t["friction_damping"]:
            continue
        if not speed > 0:
            raise SceneError(f"operating.speed: must be > 0 when {key}.friction_damping is true (got {speed})")
        if t["sliding"] == 0:
            raise SceneError(f"{key}.friction_damping: needs sliding = +1 or -1 (got 0: nothing slides)")
        if t["mu"] == 0 and not law:
            raise SceneError(f"{key}.friction_damping: needs mu > 0 or a μ(V) law (friction = 'stribeck')")
        if t["type"] == "contact" and scene["preload"]["mode"] != "nonlinear":
            raise SceneError(f"{key}.friction_damping: needs preload.mode = 'nonlinear' (the damping scales "
                             "with the preload contact pressure)")
        if t["type"] == "rigid_plate" and not scene["loads"]["pressure"]:
            raise SceneError(f"{key}.friction_damping: needs loads.pressure (a plate's pressure k_n (u·n) "
                             "comes from the static preload)")
        for study in ("transient", "masa"):
            if study in scene["analyses"]:
                raise SceneError(f"{key}.friction_damping: not with analyses.{study} (its friction law and "
                                 "contact state carry the velocity terms themselves)")
        used = True
    if speed > 0 and not used:
        raise SceneError(f"operating.speed: {speed} but nothing uses it: set interfaces.<name>.friction_damping "
                         "= true, a friction = 'stribeck' law or operating.gyroscopic = true (or speed = 0)")


def _check_analyses(ana: dict) -> dict:
    """Each requested analysis checked against its section (from the registry
    :mod:`fem_squeal.app.analyses`); the analyses they need added with their defaults where the
    needed one says so (``Stage.pulled``: analyses.reduced), else required."""
    out = {}
    for name, table in ana.items():
        if name not in ANALYSES:
            raise SceneError(f"analyses.{name}: unknown analysis; available: {sorted(ANALYSES)}")
        out[name] = check_fields(table, ANALYSES[name].section, f"analyses.{name}")
    pending = list(out)
    while pending:
        for dep in STAGES[pending.pop()].needs:
            if dep not in ANALYSES or dep in out:
                continue
            if not ANALYSES[dep].pulled:
                needer = next(n for n in out if dep in STAGES[n].needs)
                raise SceneError(f"analyses.{needer}: needs analyses.{dep} ({ANALYSES[dep].doc})")
            out[dep] = check_fields({}, ANALYSES[dep].section, f"analyses.{dep}")
            pending.append(dep)
    return out


def _cross_check(scene: Section, volumes) -> None:
    """Each analysis's cross-checks against the rest of the (typed) scene, in the registry's order."""
    for name in scene["analyses"]:
        if ANALYSES[name].check is not None:
            ANALYSES[name].check(scene, volumes)


def _validate_lumped(raw: dict, scene: dict) -> dict:
    """A scene of lumped analyses only: no geometry, materials, interfaces or loads."""
    extra = sorted(set(raw) - {"title", "analyses", "solver"})
    if extra:
        raise SceneError(f"{extra[0]}: not used by the analyses {sorted(raw['analyses'])} (they need no "
                         "finite-element model); remove it")
    scene["solver"] = check_fields(raw.get("solver", {}), SECTIONS["solver"], "solver")
    scene["analyses"] = _check_analyses(raw["analyses"])
    typed = _typed(scene)
    _cross_check(typed, {})
    return typed


#: the name -> table maps inside model sections, with the fields of their tables
_SUBTABLES = {("boundary", "fixed"): FIXED, ("boundary", "ground_springs"): GROUND_SPRING,
              ("loads", "pressure"): PRESSURE}


def _typed(scene: dict) -> Section:
    """The validated scene as typed, frozen sections (:func:`fem_squeal.app.fields.freeze`): the
    top level holds the sections present (a lumped scene has no geometry), ``materials``,
    ``interfaces`` and ``analyses`` map names to their sections."""
    out: dict[str, Any] = {"title": scene["title"]}
    if "geometry" in scene:
        geo = scene["geometry"]
        out["geometry"] = freeze(geo, GEOMETRY[geo["builder"]], f"geometry.{geo['builder']}")
        out["materials"] = {p: freeze(m, MATERIAL, "material") for p, m in scene["materials"].items()}
        out["interfaces"] = {n: freeze(t, INTERFACES[t["type"]], f"interface.{t['type']}")
                             for n, t in scene["interfaces"].items()}
    for sec, fields in SECTIONS.items():
        if sec in scene:
            table = dict(scene[sec])
            for (s, sub), sub_fields in _SUBTABLES.items():
                if s == sec:
                    table[sub] = {n: freeze(t, sub_fields, f"{sec}.{sub}") for n, t in table[sub].items()}
            out[sec] = freeze(table, fields, sec)
    out["analyses"] = {n: freeze(t, ANALYSES[n].section, f"analyses.{n}") for n, t in scene["analyses"].items()}
    return freeze(out, None, "scene")


def _check_fixed(boundary: dict, known_face) -> None:
    """boundary.fixed entries; a face must not have a component fixed twice (clamped and fixed, a face
    listed twice in clamped, or two fixed entries with overlapping components)."""
    held: dict[str, tuple[str, set]] = {}
    for face in boundary["clamped"]:
        if face in held:
            raise SceneError(f"boundary.clamped: face {face!r} listed twice")
        held[face] = ("boundary.clamped", {"x", "y", "z"})
    checked = {}
    for name, table in boundary["fixed"].items():
        key = f"boundary.fixed.{name}"
        t = check_fields(table, FIXED, key)
        known_face(t["face"], f"{key}.face")
        where, comps = held.get(t["face"], ("", set()))
        twice = comps & set(t["components"])
        if twice:
            raise SceneError(f"{key}: face {t['face']!r} has {sorted(twice)} fixed already in {where}")
        held[t["face"]] = (f"{where} and {key}" if where else key, comps | set(t["components"]))
        checked[name] = t
    boundary["fixed"] = checked


def parse_value(text: str) -> Any:
    """Parse a --set value as a TOML value, falling back to a bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply ``key.path=value`` overrides to a raw scene (a deep copy is returned)."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        if "=" not in item:
            raise SceneError(f"--set {item}: expected key.path=value")
        key, text = item.split("=", 1)
        parts = [p for p in key.strip().split(".")]
        if not all(parts):
            raise SceneError(f"--set {item}: empty key component")
        node = raw
        for i, p in enumerate(parts[:-1]):
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise SceneError(f"{'.'.join(parts[: i + 1])}: is not a table, cannot set {key}")
        node[parts[-1]] = parse_value(text.strip())
    return raw


def merge(base: dict, over: dict) -> dict:
    """``over`` on top of ``base``: tables merge key by key, any other value replaces."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


def read_scene(path: str | Path, _seen: tuple = ()) -> dict:
    """The raw table of a scene file, with ``extends = "other.toml"`` (relative to the file)
    resolved: the file's tables are merged on top of the other scene's."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except (FileNotFoundError, IsADirectoryError):
        raise SceneError(f"{path}: no such scene file") from None
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a text file") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: not valid TOML ({e})") from None
    geo = raw.get("geometry")
    if isinstance(geo, dict) and isinstance(geo.get("file"), str) and geo["file"].strip():
        geo["file"] = str((path.parent / geo["file"]).resolve())    # relative to the scene that names it
    base = raw.pop("extends", None)
    if base is None:
        return raw
    if not isinstance(base, str):
        raise SceneError(f"extends: must be a scene file name (got {base!r})")
    base_path = (path.parent / base).resolve()
    if base_path in _seen or base_path == path.resolve():
        raise SceneError(f"extends: {base} is extended in a cycle")
    base_raw = read_scene(base_path, (*_seen, path.resolve()))
    base_builder = base_raw.get("geometry", {}).get("builder")
    if isinstance(geo, dict) and "builder" in geo and geo["builder"] != base_builder:
        base_raw.pop("geometry", None)      # another builder: its parameters replace the base's
    return merge(base_raw, raw)


def load_scene(path: str | Path, overrides: list[str] | None = None) -> dict:
    """Read (resolving ``extends``), override and validate a scene file."""
    return validate(apply_overrides(read_scene(path), overrides or []))


def _friction_law(t):
    """The μ(V) law of an interface table (None: the constant mu), made by the registry of
    :mod:`fem_squeal.reduced.laws.friction` that the transient uses too."""
    if t.get("friction", "constant") == "constant":
        return None
    return FRICTION_LAWS[t["friction"]].make(float(t["mu"]), t["mu_s"], t["mu_d"], float(t["v_s"]),
                                             float(t["v_d"]), 1.0, 0.0)


def _nominal_mu(t) -> float:
    """The interface's μ: mu, or with a μ(V) law its dynamic level μ_d (what a μ sweep scales)."""
    law = _friction_law(t)
    return float(t.get("mu", 0.0)) if law is None else float(law.mu_d)


def _speed_terms(t, speed: float) -> dict:
    """The friction law, friction damping and disc speed of an interface table (fe.model fields)."""
    if "friction" not in t:
        return {}
    return {"law": _friction_law(t), "friction_damping": bool(t["friction_damping"]), "speed": speed}


def model_spec(scene: dict) -> ModelSpec:
    """The physics description of a validated scene."""
    mats = {p: Material(**m) for p, m in scene["materials"].items()}
    speed = float(scene["operating"]["speed"]) if "operating" in scene else 0.0
    plates = tuple(RigidPlate(t["face"], float(t["kn"]), _nominal_mu(t), int(t["sliding"]), float(t["kt"]),
                              **_speed_terms(t, speed), name=name)
                   for name, t in scene["interfaces"].items() if t["type"] == "rigid_plate")
    interfaces = tuple(
        Interface(name, t["slave"], t["master"], t["type"], float(t["kn"]), float(t.get("kt", 0.0)),
                  _nominal_mu(t), int(t.get("sliding", 0)), **_speed_terms(t, speed))
        for name, t in scene["interfaces"].items() if t["type"] != "rigid_plate")
    springs = tuple(GroundSpring(t["face"], float(t["k_axial"]), float(t["k_transverse"]))
                    for t in scene["boundary"]["ground_springs"].values())
    pressures = tuple(Pressure(t["face"], float(t["p"])) for t in scene["loads"]["pressure"].values())
    d = scene["discretisation"]
    fixed = tuple(FixedFace(t["face"], tuple(t["components"]))
                  for t in scene["boundary"].get("fixed", {}).values())
    return ModelSpec(mats, plates, tuple(scene["boundary"]["clamped"]), d["degree"],
                     d.quadrature_degree, interfaces=interfaces, ground_springs=springs,
                     pressures=pressures, interface_quadrature_degree=d["interface_quadrature_degree"],
                     fixed=fixed)
