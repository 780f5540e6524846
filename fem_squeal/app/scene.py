"""Scene files: TOML → validated, defaulted dictionary → model description.

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
                 type = "spring": slave, master, kn, kt [N/m³];  type = "bonded": slave, master, kn
boundary         clamped = [face names] (all displacement components fixed);
                 fixed.<name>: face, components = subset of ["x", "y", "z"] (global axes fixed);
                 ground_springs.<name>: face, k_axial, k_transverse [N/m³]
loads            pressure.<name>: face, p [Pa] (pushes the face inwards)
preload          mode ("nonlinear": active-set Newton then linearise about the closed points;
                 "all_closed": every contact point closed, no static solve), friction (sliding
                 friction in the static step), tol, max_iterations
discretisation   degree (1 or 2), quadrature_degree (0 = automatic), interface_quadrature_degree
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
    at_least,
    check_fields,
    dataclass_fields,
    non_negative,
    nonempty_str,
    one_of,
    poisson,
    positive,
)
from fem_squeal.fe.model import FixedFace, GroundSpring, Interface, Material, ModelSpec, Pressure, RigidPlate
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
}
_TYPE = Field(str, "rigid_plate", one_of("rigid_plate", "contact", "spring", "bonded"))
_PAIR = {"slave": Field(str, check=nonempty_str, doc="slave face (quadrature side: the lining)"),
         "master": Field(str, check=nonempty_str, doc="master face (the disc)")}
_FRICTION = {"mu": Field(REAL, 0.0, non_negative, "friction coefficient"),
             "sliding": Field(int, 1, one_of(-1, 0, 1), "+1 forward (+e_θ), -1 backward, 0 none")}
_KT = Field(REAL, 0.0, non_negative, "tangential penalty across the sliding direction [N/m³] (0: seed 001)")
INTERFACES = {
    "rigid_plate": {"type": _TYPE, "face": Field(str, check=nonempty_str, doc="face name of the geometry"),
                    "kn": Field(REAL, check=non_negative, doc="penalty stiffness per area [N/m³]"), **_FRICTION,
                    "kt": _KT},
    "contact": {"type": _TYPE, **_PAIR, "kn": Field(REAL, check=positive, doc="penalty [N/m³]"), **_FRICTION,
                "kt": _KT},
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
    },
    "discretisation": {
        "degree": Field(int, 2, one_of(1, 2), "Lagrange degree (P1 locks in bending)"),
        "quadrature_degree": Field(int, 0, non_negative, "0 = estimated by the form compiler"),
        "interface_quadrature_degree": Field(int, 4, positive, "slave-surface quadrature of interfaces"),
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
    _cross_check(scene, volumes)
    return scene


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


def _cross_check(scene: dict, volumes) -> None:
    """Each analysis's cross-checks against the rest of the scene, in the registry's order."""
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
    _cross_check(scene, {})
    return scene


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


def model_spec(scene: dict) -> ModelSpec:
    """The physics description of a validated scene."""
    mats = {p: Material(**m) for p, m in scene["materials"].items()}
    plates = tuple(RigidPlate(t["face"], float(t["kn"]), float(t["mu"]), int(t["sliding"]), float(t["kt"]))
                   for t in scene["interfaces"].values() if t["type"] == "rigid_plate")
    interfaces = tuple(
        Interface(name, t["slave"], t["master"], t["type"], float(t["kn"]), float(t.get("kt", 0.0)),
                  float(t.get("mu", 0.0)), int(t.get("sliding", 0)))
        for name, t in scene["interfaces"].items() if t["type"] != "rigid_plate")
    springs = tuple(GroundSpring(t["face"], float(t["k_axial"]), float(t["k_transverse"]))
                    for t in scene["boundary"]["ground_springs"].values())
    pressures = tuple(Pressure(t["face"], float(t["p"])) for t in scene["loads"]["pressure"].values())
    d = scene["discretisation"]
    fixed = tuple(FixedFace(t["face"], tuple(t["components"]))
                  for t in scene["boundary"].get("fixed", {}).values())
    return ModelSpec(mats, plates, tuple(scene["boundary"]["clamped"]), d["degree"],
                     d["quadrature_degree"] or None, interfaces=interfaces, ground_springs=springs,
                     pressures=pressures, interface_quadrature_degree=d["interface_quadrature_degree"],
                     fixed=fixed)
