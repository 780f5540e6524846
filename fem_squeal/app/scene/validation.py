"""One pass from a raw scene table to the validated scene (:class:`Scene`): typed sections with every
default filled in, the checks between sections made on those typed values, and the model description.

1. Each table is checked against its fields (:mod:`fem_squeal.app.scene.schema`; an analysis's section
   from its module in :mod:`fem_squeal.app.analyses`) and frozen as its typed section as it is read
   (:func:`fem_squeal.app.fields.section`): unknown keys, types, finite numbers, bounds, defaults, and
   what a table can check alone (a mesh file's sets, a brake corner's dimensions, a part's material, an
   interface's faces, a face's boundary conditions).
2. What no table checks alone is checked next, on the typed sections (:func:`cross_check`): contact
   needs a preload pressure, the disc speed against the friction laws and the rotation against the
   studies, then each analysis's cross-checks (its ``Stage.check``, in the registry's order).
3. The model description (:class:`~fem_squeal.fe.model.ModelSpec`) is built once, from the typed
   sections and the parts' materials made in step 1, and travels with the scene (:func:`model_spec`).

Errors name the key path and the reason (:class:`~fem_squeal.util.errors.SceneError`, exit 2); nothing
is computed before a scene validates.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from fem_squeal.app.analyses import ANALYSES, STAGES
from fem_squeal.app.fields import Field, Section, check_fields, freeze, section
from fem_squeal.app.scene.matrices import matrices_section
from fem_squeal.app.scene.model import build_model_spec, material
from fem_squeal.app.scene.schema import (
    FIXED,
    GEOMETRY,
    GROUND_SPRING,
    INTERFACES,
    MATERIAL,
    POINT_LOAD,
    PRESSURE,
    SECTIONS,
    geometry_tags,
)
from fem_squeal.fe.model import Material, ModelSpec
from fem_squeal.util.errors import SceneError
from geometry.brake_corner import BrakeCornerParams
from geometry.mesh_file import MeshImportError, file_format

#: the analyses that include the rotation terms (operating.gyroscopic, preload.geometric_stiffness)
ROTATION_ANALYSES = ("cea", "real_modes", "reduced", "sweep", "map", "sensitivity", "robustness",
                     "operating_matrix")


class Scene(Section):
    """The validated scene: its sections are its fields (``title``, ``geometry``, ``materials``,
    ``interfaces``, the sections of :data:`~fem_squeal.app.scene.schema.SECTIONS` and ``analyses``; a
    scene of lumped analyses only has ``title``, ``solver`` and ``analyses``), read as attributes or as
    the mapping they replace.  ``spec`` is its model description (:func:`model_spec`: built by the
    validation pass; None for a lumped scene), not a section: results.json and the cache keys see the
    sections only."""

    __slots__ = ()

    @property
    def spec(self) -> ModelSpec | None:
        return self.__dict__.get("_spec")


def model_spec(scene: Mapping) -> ModelSpec:
    """The physics description of a validated finite-element scene: the one its validation pass built,
    the same object for the plan's cache keys and every stage of a run.  A scene changed with
    ``replace`` gets its own, built from its sections on the first call and kept with it."""
    if not isinstance(scene, Scene):
        return build_model_spec(scene)
    if scene.spec is None:
        object.__setattr__(scene, "_spec", build_model_spec(scene))     # frozen: its one model, kept
    return scene.spec


def validate(raw: Any) -> Scene:
    """The scene of the raw table ``raw`` (a scene file's, with ``extends`` and ``--set`` applied),
    validated in one pass (see the module docstring); raises :class:`SceneError` naming the key."""
    if not isinstance(raw, dict):
        raise SceneError("scene: must be a table")
    allowed = {"title", "geometry", "materials", "interfaces", "analyses", "matrices", *SECTIONS}
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise SceneError(f"{unknown[0]}: unknown section; allowed: {sorted(allowed)}")
    title = raw.get("title", "")
    if not isinstance(title, str):
        raise SceneError("title: must be a string")
    ana = raw.get("analyses")
    if not isinstance(ana, dict) or not ana:
        raise SceneError(f"analyses: required, at least one of {sorted(ANALYSES)}")
    if "matrices" in raw:
        return _matrix_scene(raw, title)
    if all(name in STAGES and STAGES[name].lumped for name in ana) and "geometry" not in raw:
        return _lumped(raw, title)

    geometry = _geometry(raw.get("geometry"))
    volumes, faces = geometry_tags(geometry)

    def known_face(face: str, key: str) -> None:
        if face not in faces:
            raise SceneError(f"{key}: unknown face {face!r}; faces: {sorted(faces)}")

    materials, made = _materials(raw.get("materials"), volumes, geometry.builder)
    out: dict[str, Any] = {"title": title, "geometry": geometry, "materials": materials,
                           "interfaces": _interfaces(raw.get("interfaces", {}), known_face)}
    for sec in SECTIONS:
        out[sec] = _SECTION_READERS.get(sec, _plain_section)(raw.get(sec, {}), sec, known_face)
    out["analyses"] = _analyses(ana)
    scene = freeze(out, None, "scene", base=Scene)
    cross_check(scene, volumes)
    object.__setattr__(scene, "_spec", build_model_spec(scene, made))   # frozen: set once, here
    return scene


def _lumped(raw: dict, title: str) -> Scene:
    """A scene of lumped analyses only: no geometry, materials, interfaces or loads."""
    extra = sorted(set(raw) - {"title", "analyses", "solver"})
    if extra:
        raise SceneError(f"{extra[0]}: not used by the analyses {sorted(raw['analyses'])} (they need no "
                         "finite-element model); remove it")
    scene = freeze({"title": title, "solver": section(raw.get("solver", {}), SECTIONS["solver"], "solver"),
                    "analyses": _analyses(raw["analyses"])}, None, "scene", base=Scene)
    cross_check(scene, {})
    return scene


def _matrix_scene(raw: dict, title: str) -> Scene:
    """A scene whose model is given as matrices (:mod:`fem_squeal.app.scene.matrices`): no geometry,
    materials, interfaces or loads, and only the analyses that run on matrices (``Stage.on_matrices``)."""
    extra = sorted(set(raw) - {"title", "matrices", "analyses", "solver"})
    if extra:
        raise SceneError(f"{extra[0]}: not used by a model given as matrices ([matrices]); remove it")
    on_matrices = sorted(n for n, st in ANALYSES.items() if st.on_matrices is not None)
    for name in raw["analyses"]:
        if name in ANALYSES and name not in on_matrices:
            raise SceneError(f"analyses.{name}: not available for a model given as matrices; available: "
                             f"{on_matrices}")
    matrices = matrices_section(raw["matrices"])
    scene = freeze({"title": title, "matrices": matrices,
                    "solver": section(raw.get("solver", {}), SECTIONS["solver"], "solver"),
                    "analyses": _analyses(raw["analyses"], on_matrices=True)}, None, "scene", base=Scene)
    cross_check(scene, {})
    return scene


# -- step 1: each table checked and typed as it is read --------------------------------------------

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



def _geometry(geo: Any) -> Section:
    """The geometry section of its builder; a mesh file's sets as lists of names, its file there and
    readable; an annular disc narrower than its diameter; a brake corner's dimensions consistent."""
    if not isinstance(geo, dict):
        raise SceneError("geometry: required table")
    if "builder" not in geo:
        raise SceneError("geometry.builder: required; one of " + str(sorted(GEOMETRY)))
    builder = geo["builder"]
    if not isinstance(builder, str) or builder not in GEOMETRY:
        raise SceneError(f"geometry.builder: must be one of {sorted(GEOMETRY)} (got {builder!r})")
    g = check_fields(geo, GEOMETRY[builder], "geometry")
    if builder == "mesh_file":
        _mesh_file(g)
    if builder == "annular_disc" and g["width"] >= 2 * g["mean_radius"]:
        raise SceneError("geometry.width: must be < 2 * mean_radius")
    if builder == "brake_corner":
        try:
            BrakeCornerParams(**{k: v for k, v in g.items() if k not in ("builder", "order")})
        except (ValueError, TypeError) as e:
            msg = str(e)
            raise SceneError(msg if msg.startswith("geometry.") else f"geometry: {msg}") from None
    return freeze(g, GEOMETRY[builder], f"geometry.{builder}")


def _mesh_file(geo: dict) -> None:
    """A mesh file's checked table: center and axis as points, parts and faces as lists of set names
    (in place), distinct part and face names, the file there and of a known format."""
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



def _materials(mats: Any, volumes: Mapping[str, int], builder: str) -> tuple[dict[str, Section],
                                                                             dict[str, Material]]:
    """``materials.<part>`` for every part of the geometry, and each part's :class:`Material` (made
    here: what the physics refuses is an error naming the part's key)."""
    if not isinstance(mats, dict) or not mats:
        raise SceneError(f"materials: required, one table per part {sorted(volumes)}")
    typed: dict[str, Section] = {}
    made: dict[str, Material] = {}
    for part, table in mats.items():
        if part not in volumes:
            raise SceneError(f"materials.{part}: unknown part; parts of {builder}: {sorted(volumes)}")
        typed[part] = section(table, MATERIAL, f"materials.{part}", "material")
        made[part] = material(part, typed[part])
    missing = sorted(set(volumes) - set(mats))
    if missing:
        raise SceneError(f"materials.{missing[0]}: required (no material for this part)")
    return typed, made


def _interfaces(interfaces: Any, known_face: Callable[[str, str], None]) -> dict[str, Section]:
    """``interfaces.<name>`` of its type, on faces of the geometry (a pair: two different faces)."""
    if not isinstance(interfaces, dict):
        raise SceneError(f"interfaces: must be a table of interfaces (got {type(interfaces).__name__})")
    out = {}
    for name, table in interfaces.items():
        key = f"interfaces.{name}"
        if not isinstance(table, dict):
            raise SceneError(f"{key}: must be a table (got {type(table).__name__})")
        kind = table.get("type", "rigid_plate")
        if not isinstance(kind, str) or kind not in INTERFACES:
            raise SceneError(f"{key}.type: must be one of {sorted(INTERFACES)} (got {kind!r})")
        t = section(table, INTERFACES[kind], key, f"interface.{kind}")
        for side in ("face", "slave", "master"):
            if side in t:
                known_face(t[side], f"{key}.{side}")
        if "slave" in t and t.slave == t.master:
            raise SceneError(f"{key}.master: must differ from the slave face ({t.slave!r})")
        out[name] = t
    return out


def _on_face(table: Any, fields: dict[str, Field], key: str, kind: str,
             known_face: Callable[[str, str], None]) -> Section:
    """An entry of a name -> table map of a model section (``boundary.fixed.<name>``, ...): typed, its
    face one of the geometry's."""
    t = section(table, fields, key, kind)
    known_face(t.face, f"{key}.face")
    return t


def _boundary(table: Any, sec: str, known_face: Callable[[str, str], None]) -> Section:
    """boundary: clamped faces, fixed components and ground springs on faces of the geometry; a face
    must not have a component fixed twice (clamped and fixed, a face listed twice in clamped, or two
    fixed entries with overlapping components); a ground spring has a stiffness."""
    b = check_fields(table, SECTIONS[sec], sec)
    for i, f in enumerate(b["clamped"]):
        if not isinstance(f, str):
            raise SceneError(f"boundary.clamped[{i}]: must be a face name (got {f!r})")
        known_face(f, f"boundary.clamped[{i}]")
    held: dict[str, tuple[str, set]] = {}
    for face in b["clamped"]:
        if face in held:
            raise SceneError(f"boundary.clamped: face {face!r} listed twice")
        held[face] = ("boundary.clamped", {"x", "y", "z"})
    fixed = {}
    for name, entry in b["fixed"].items():
        key = f"boundary.fixed.{name}"
        t = _on_face(entry, FIXED, key, "boundary.fixed", known_face)
        where, comps = held.get(t.face, ("", set()))
        twice = comps & set(t.components)
        if twice:
            raise SceneError(f"{key}: face {t.face!r} has {sorted(twice)} fixed already in {where}")
        held[t.face] = (f"{where} and {key}" if where else key, comps | set(t.components))
        fixed[name] = t
    springs = {}
    for name, entry in b["ground_springs"].items():
        key = f"boundary.ground_springs.{name}"
        t = _on_face(entry, GROUND_SPRING, key, "boundary.ground_springs", known_face)
        if t.k_axial + t.k_transverse <= 0:
            raise SceneError(f"{key}: k_axial and k_transverse must not both be 0")
        springs[name] = t
    return freeze({**b, "fixed": fixed, "ground_springs": springs}, SECTIONS[sec], sec)


def _loads(table: Any, sec: str, known_face: Callable[[str, str], None]) -> Section:
    """loads: pressures on faces of the geometry, concentrated forces at nodes."""
    t = check_fields(table, SECTIONS[sec], sec)
    pressure = {name: _on_face(entry, PRESSURE, f"loads.pressure.{name}", "loads.pressure", known_face)
                for name, entry in t["pressure"].items()}
    point = {name: section(entry, POINT_LOAD, f"loads.point.{name}") for name, entry in t["point"].items()}
    return freeze({**t, "pressure": pressure, "point": point}, SECTIONS[sec], sec)


def _plain_section(table: Any, sec: str, known_face: Callable[[str, str], None]) -> Section:
    """A model section of plain fields (preload, discretisation, operating, solver)."""
    return section(table, SECTIONS[sec], sec)


#: the model sections with name -> table maps of their own (the others: :func:`_plain_section`)
_SECTION_READERS = {"boundary": _boundary, "loads": _loads}


def _analyses(ana: dict, on_matrices: bool = False) -> dict[str, Section]:
    """Each requested analysis checked against its section (from the registry
    :mod:`fem_squeal.app.analyses`; ``on_matrices``: a model given as matrices, ``Stage.section_on_matrices``
    where a stage has one, and no needed analyses: they need the ``matrices`` stage alone); the analyses
    they need added with their defaults where the needed one says so (``Stage.pulled``: analyses.reduced),
    else required."""
    out = {}
    for name, table in ana.items():
        if name not in ANALYSES:
            raise SceneError(f"analyses.{name}: unknown analysis; available: {sorted(ANALYSES)}")
        fields = (on_matrices and ANALYSES[name].section_on_matrices) or ANALYSES[name].section
        out[name] = section(table, fields, f"analyses.{name}")
    if on_matrices:
        return out
    pending = list(out)
    while pending:
        for dep in STAGES[pending.pop()].needs:
            if dep not in ANALYSES or dep in out:
                continue
            if not ANALYSES[dep].pulled:
                needer = next(n for n in out if dep in STAGES[n].needs)
                raise SceneError(f"analyses.{needer}: needs analyses.{dep} ({ANALYSES[dep].doc})")
            out[dep] = section({}, ANALYSES[dep].section, f"analyses.{dep}")
            pending.append(dep)
    return out


# -- step 2: what no table checks alone, on the typed sections -------------------------------------

def cross_check(scene: Scene, volumes: Mapping[str, int]) -> None:
    """The checks between sections of a typed scene (``volumes``: its parts): contact interfaces with
    a nonlinear preload need a pressure, :func:`check_speed_terms`, :func:`check_rotation`, then each
    analysis's cross-checks in the registry's order."""
    if "geometry" in scene:
        has_contact = any(t.type == "contact" for t in scene.interfaces.values())
        if has_contact and scene.preload.mode == "nonlinear" and not (scene.loads.pressure or
                                                                       scene.loads.get("point")):
            raise SceneError("loads.pressure: required for preload.mode = 'nonlinear' with contact interfaces "
                             "(or loads.point) "
                             "(or set preload.mode = 'all_closed')")
        check_speed_terms(scene)
        check_rotation(scene, volumes)
    for name in scene.analyses:
        if ANALYSES[name].check is not None:
            ANALYSES[name].check(scene, volumes)


def check_speed_terms(scene: Scene) -> None:
    """operating.speed against the friction laws and friction damping of the interfaces: a μ(V) law and
    friction damping need speed > 0, a sliding interface with μ, the preload pressure they scale with,
    and no nonlinear study (transient, masa: their friction laws carry the velocity terms themselves);
    a speed > 0 that nothing uses is an error."""
    speed = scene.operating.speed
    used = bool(scene.operating.gyroscopic)
    for name, t in scene.interfaces.items():
        if "friction" not in t:
            continue
        key = f"interfaces.{name}"
        law = t.friction != "constant"
        if law:
            if not speed > 0:
                raise SceneError(f"operating.speed: must be > 0 when {key}.friction = {t.friction!r} "
                                 f"(μ(V) at V = speed·r; got {speed})")
            if not (t.mu_d or t.mu) > 0:
                raise SceneError(f"{key}.mu_d: must be > 0 with friction = {t.friction!r} (or give mu)")
            if t.v_d <= t.v_s:
                raise SceneError(f"{key}.v_d: must be > v_s = {t.v_s} (got {t.v_d})")
            used = True
        if not t.friction_damping:
            continue
        if not speed > 0:
            raise SceneError(f"operating.speed: must be > 0 when {key}.friction_damping is true (got {speed})")
        if t.sliding == 0:
            raise SceneError(f"{key}.friction_damping: needs sliding = +1 or -1 (got 0: nothing slides)")
        if t.mu == 0 and not law:
            raise SceneError(f"{key}.friction_damping: needs mu > 0 or a μ(V) law (friction = 'stribeck')")
        if t.type == "contact" and scene.preload.mode != "nonlinear":
            raise SceneError(f"{key}.friction_damping: needs preload.mode = 'nonlinear' (the damping scales "
                             "with the preload contact pressure)")
        if t.type == "rigid_plate" and not scene.loads.pressure:
            raise SceneError(f"{key}.friction_damping: needs loads.pressure (a plate's pressure k_n (u·n) "
                             "comes from the static preload)")
        for study in ("transient", "masa"):
            if study in scene.analyses:
                raise SceneError(f"{key}.friction_damping: not with analyses.{study} (its friction law and "
                                 "contact state carry the velocity terms themselves)")
        used = True
    if speed > 0 and not used:
        raise SceneError(f"operating.speed: {speed} but nothing uses it: set interfaces.<name>.friction_damping "
                         "= true, a friction = 'stribeck' law or operating.gyroscopic = true (or speed = 0)")


def check_rotation(scene: Scene, volumes: Mapping[str, int]) -> None:
    """operating.gyroscopic = true needs speed > 0 and operating.rotating_parts naming at least one part
    of the geometry.  The rotation and the stress stiffening (preload.geometric_stiffness) enter the CEA
    and the reduced model (real_modes stay the modes at rest); the nonlinear studies (transient, masa
    and those built on them) are refused with them."""
    op = scene.operating
    terms = [k for k, on in (("operating.gyroscopic", op.gyroscopic),
                             ("preload.geometric_stiffness", scene.preload.geometric_stiffness)) if on]
    studies = sorted(set(scene.analyses) - set(ROTATION_ANALYSES))
    if terms and studies:
        raise SceneError(f"{terms[0]}: the nonlinear study analyses.{studies[0]} does not include it "
                         f"(remove that analysis or set {terms[0]} = false)")
    if not op.gyroscopic:
        return
    if not op.rotating_parts:
        raise SceneError("operating.rotating_parts: must name at least one part when operating.gyroscopic "
                         f"is true; parts: {sorted(volumes)}")
    for i, p in enumerate(op.rotating_parts):
        if p not in volumes:
            raise SceneError(f"operating.rotating_parts[{i}]: unknown part {p!r}; parts: {sorted(volumes)}")
    if not op.speed > 0:
        raise SceneError(f"operating.speed: must be > 0 when operating.gyroscopic is true (got {op.speed})")
