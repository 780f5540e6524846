"""An Abaqus/CalculiX squeal deck as a scene: ``fem-squeal run model.inp`` and ``fem-squeal convert model.inp
scene.toml``.

The deck's model (:func:`geometry.abaqus_model.read_model`) becomes the raw table of a scene whose mesh is
the deck itself (``geometry.builder = "mesh_file"``, ``deck = true``), each value with the keyword and line
it came from:

- ``*SOLID SECTION`` of a part that is not rigid -> ``geometry.parts.<elset>`` and ``materials.<elset>``
  (``*ELASTIC`` E, ν; engineering constants transversely isotropic about z without an orientation as
  E_axial, ν_axial, G_axial; other engineering constants as E1 … G23, ``TYPE=ORTHOTROPIC``/``ANISOTROPIC``
  as D; the section's ``*ORIENTATION`` as ``orientation``; ``*DENSITY``; ``*DAMPING`` α, β);
- a part whose every node has all three displacements prescribed is rigid: left out of the mesh
  (``geometry.skip_sets``);
- ``*BOUNDARY`` of zero values on a node set of a deformable part -> ``boundary.fixed.<set>`` (all three:
  ``boundary.clamped``); on a rigid part it defines the part (press, rotation);
- ``*DLOAD`` surface, P, p -> ``loads.pressure.<surface>``; ``*CLOAD`` in a static step (or the model) ->
  ``loads.point.n<node>``, the node's force components summed;
- ``*TIE`` -> a ``bonded`` interface; ``*CONTACT PAIR`` -> a ``contact`` interface, or a ``rigid_plate``
  on the slave face when the master surface lies on a rigid part: kn = the LINEAR overclosure slope,
  μ = the perturbation step's ``*CHANGE FRICTION`` μ (else ``*FRICTION``'s), kt = λ μ/μ_static (CalculiX's
  slip-state tangent across the sliding direction: λ/F with F = μ_static/μ, benchmarks/cea_calculix.py),
  sliding = the sign of the master part's prescribed rigid rotation about z in a static step, or of its
  ``*MOTION, ROTATION, TYPE=VELOCITY`` rate about the z axis, or of its ``*TRANSPORT VELOCITY`` ω in a
  ``*STEADY STATE TRANSPORT`` step (about the disc axis z; the same direction: u = θ e_z × x); ω goes into
  the comment only: the scene's operating.speed is read by friction damping, μ(V) laws and the gyroscopic
  terms, none of which a deck gives (``FRICTION DAMPING``, ``INERTIA=YES`` are refused);
- a ``*STATIC`` or ``*STEADY STATE TRANSPORT`` step -> ``preload`` (NLGEOM: ``geometric_stiffness``);
  ``*STEP, PERTURBATION`` with ``*COMPLEX FREQUENCY``, or with ``*FREQUENCY`` on a sliding frictional
  contact (CalculiX then solves the non-symmetric problem), -> ``analyses.cea``; ``*FREQUENCY`` otherwise
  -> ``analyses.real_modes``.
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem_squeal.fe.model import ENGINEERING_CONSTANTS, Material
from fem_squeal.util.atomic import atomic_path
from fem_squeal.util.errors import MeshError
from geometry.abaqus import AbaqusError
from geometry.abaqus_model import DeckModel, read_model, rigid_sets, rotation

#: the lowest modes (CalculiX's and Abaqus's default without a frequency range): the shift [Hz]
LOWEST_TARGET_HZ = 1.0
#: the band when the deck gives no upper frequency [Hz]
OPEN_BAND_TOP_HZ = 1e9


@dataclass
class DeckScene:
    """The raw scene table of a deck, where each value came from (dotted key -> ``file line n: *KEYWORD``)
    and the notes (ignored output requests, choices made)."""

    raw: dict
    origin: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


def deck_scene(path: str | Path) -> DeckScene:
    """The scene of the deck ``path``; raises :class:`~fem_squeal.util.errors.MeshError` (exit 2) naming the
    keyword, the file and the line of what it cannot translate."""
    try:
        return _scene(read_model(path))
    except AbaqusError as e:
        raise MeshError(str(e)) from None


def _scene(m: DeckModel) -> DeckScene:
    out = DeckScene({"title": f"{m.path.name} (Abaqus/CalculiX deck)"})
    origin, names = out.origin, m.mesh.names
    out.notes += m.notes
    rigid = rigid_sets(m)
    parts = {names.get(k, k): k for k in m.sections if k not in rigid}
    if not parts:
        raise AbaqusError(f"{m.path.name}: no *SOLID SECTION of a deformable part")
    faces: dict[str, list] = {}
    geo = {"builder": "mesh_file", "file": str(m.path.resolve()), "parts": {p: [p] for p in parts}, "faces": faces,
           "skip_sets": [names.get(k, k) for k in rigid], "deck": True}
    out.raw["geometry"] = geo
    for p, k in parts.items():
        origin[f"geometry.parts.{p}"] = f"{m.sections[k].where}: *SOLID SECTION"
    for w in rigid.values():
        origin.setdefault("geometry.skip_sets", f"{w}: *SOLID SECTION of a rigid part (every node prescribed)")

    mats = {}
    for p, k in parts.items():
        sec = m.sections[k]
        mat = m.materials.get(sec.value.upper())
        if mat is None:
            raise AbaqusError(f"{sec.where}: *SOLID SECTION, MATERIAL={sec.value}: no such *MATERIAL")
        for need, kw in (("E", "*ELASTIC"), ("rho", "*DENSITY")):
            if need not in mat and not (need == "E" and ("engineering" in mat or "D" in mat)):
                raise AbaqusError(f"{mat['name'].where}: *MATERIAL {sec.value}: no {kw}")
        mats[p] = {}
        orient = m.section_orientation.get(k)
        general = orient is not None or "D" in mat or ("engineering" in mat and "E_axial" not in mat)
        keys = ["rho", "rayleigh_alpha", "rayleigh_beta"] + (["E", "nu", "E_axial", "nu_axial", "G_axial"]
                                                            if not general else [])
        for key in keys:
            if key in mat:
                mats[p][key] = mat[key].value
                kw = {"rho": "DENSITY", "rayleigh_alpha": "DAMPING",
                      "rayleigh_beta": "DAMPING"}.get(key, "ELASTIC")
                origin[f"materials.{p}.{key}"] = f"{mat[key].where}: *{kw} of *MATERIAL {sec.value}"
        if general:
            _general_material(m, mats[p], origin, p, mat, orient, sec.value)
    out.raw["materials"] = mats

    def part_of_surface(surf: str, where: str) -> str:
        key = surf.upper()
        if key in m.mesh.surfaces:
            elems = {e for e, _, _ in m.mesh.surfaces[key]}
            for k in list(m.sections):
                if elems <= set(m.mesh.elsets.get(k, [])):
                    return k
            raise AbaqusError(f"{where}: surface {surf}: its elements are not all in one *SOLID SECTION")
        if key in m.mesh.nsets or key in m.mesh.node_surfaces:
            return ""
        raise AbaqusError(f"{where}: no surface {surf!r}")

    def face(surf: str, where: str, kw: str) -> str:
        if part_of_surface(surf, where) in rigid:
            raise AbaqusError(f"{where}: *{kw}: surface {surf} lies on a rigid part; only a contact's master may")
        name = names.get(surf.upper(), surf.strip())
        faces[name] = [name]
        origin.setdefault(f"geometry.faces.{name}", f"{where}: *{kw}")
        return name

    # boundary conditions: on rigid parts they define the part; on deformable ones zero values fix components
    rigid_nodes = set()
    for k in rigid:
        rigid_nodes |= set(m.elset_nodes(k).tolist())
    fixed: dict[str, set] = {}
    for rows in [m.boundary] + [s.boundary for s in m.steps]:
        for name, first, last, value, w in rows:
            nodes = set(m.set_nodes(name, w).tolist())
            if nodes <= rigid_nodes:
                continue
            if nodes & rigid_nodes:
                raise AbaqusError(f"{w}: *BOUNDARY {name}: holds nodes of a rigid and of a deformable part")
            if value != 0.0:
                raise AbaqusError(f"{w}: *BOUNDARY {name}, {first}, {last}, {value:g}: a nonzero prescribed "
                                  "displacement of a deformable part is not supported (only of rigid parts)")
            if name.strip().upper() not in m.mesh.nsets:
                raise AbaqusError(f"{w}: *BOUNDARY {name}: a single node; use a node set covering boundary faces")
            face(name, w, "BOUNDARY")
            setname = names.get(name.strip().upper(), name.strip())
            fixed.setdefault(setname, set()).update(range(first, last + 1))
            origin.setdefault(f"boundary.fixed.{setname}", f"{w}: *BOUNDARY")
    boundary = {"clamped": sorted(s for s, c in fixed.items() if c == {1, 2, 3}),
                "fixed": {s: {"face": s, "components": ["xyz"[c - 1] for c in sorted(c)]}
                          for s, c in fixed.items() if c != {1, 2, 3}}}
    for s in boundary["clamped"]:
        origin["boundary.clamped"] = origin.pop(f"boundary.fixed.{s}")
    out.raw["boundary"] = boundary

    pressure = {}
    for st in m.steps:
        if not st.static and st.dload:
            out.notes.append(f"{st.dload[0][3]}: *DLOAD in a *{st.procedure} step ignored (an eigenvalue step "
                             "takes no loads)")
    for name, label, p, w in list(m.dload) + [r for s in m.steps if s.static for r in s.dload]:
        if label != "P":
            raise AbaqusError(f"{w}: *DLOAD {name}, {label}: element-face pressure; define a *SURFACE and "
                              "write surface, P, pressure")
        f = face(name, w, "DLOAD")
        pressure[f] = {"face": f, "p": p}
        origin[f"loads.pressure.{f}"] = f"{w}: *DLOAD"
    out.raw["loads"] = {"pressure": pressure}
    points = _point_loads(m, origin, out.notes)
    if points:
        out.raw["loads"]["point"] = points

    # the eigenvalue steps (one of each kind) and the friction in force in each step
    eig = [s for s in m.steps if s.procedure in ("FREQUENCY", "COMPLEX FREQUENCY")]
    if not eig:
        raise AbaqusError(f"{m.path.name}: no *FREQUENCY or *COMPLEX FREQUENCY step: nothing to compute")
    for i, st in enumerate(m.steps):
        if st.procedure in ("FREQUENCY", "COMPLEX FREQUENCY") and any(
                o.procedure == st.procedure for o in m.steps[:i]):
            raise AbaqusError(f"{st.procedure_where}: *{st.procedure}: a second one (one eigenvalue step of each "
                              "kind)")
        if st.static and any(not o.static for o in m.steps[:i]):
            raise AbaqusError(f"{st.procedure_where}: *{st.procedure} after an eigenvalue step is not supported")
    last = next((s for s in eig if s.procedure == "COMPLEX FREQUENCY"), eig[-1])

    def friction_at(name: str, upto) -> tuple:
        """(μ, λ) of interaction ``name`` in force in step ``upto`` (None: before the first step)."""
        inter = m.interactions[name]
        mu, lam = inter.mu, inter.stick
        for st in m.steps:
            if upto is None:
                break
            if name in st.friction:
                mu, lam = st.friction[name][0], st.friction[name][1] or lam
            if st is upto:
                break
        return mu, lam
    interfaces = {}
    for name, slave, master, w in m.ties:
        s, ma = face(slave, w, "TIE"), face(master, w, "TIE")
        interfaces[name] = {"type": "bonded", "slave": s, "master": ma}
        origin[f"interfaces.{name}"] = f"{w}: *TIE (a penalty tie, kn the bonded default)"
    sliding_friction = False
    for name, slave, master, w in m.pairs:
        inter = m.interactions[name]
        if inter.kn is None:
            raise AbaqusError(f"{inter.where}: *SURFACE INTERACTION: needs *SURFACE BEHAVIOR, "
                              "PRESSURE-OVERCLOSURE=LINEAR (the penalty slope)")
        mu_v, lam = friction_at(name, last)
        mu = float(mu_v.value) if mu_v is not None else 0.0
        slid = [s for s in m.steps if s.static]
        static_v = friction_at(name, slid[-1] if slid else None)[0]
        static_mu = float(static_v.value) if static_v is not None else mu
        kt = float(lam.value) * mu / static_mu if lam is not None and static_mu > 0 else 0.0
        mpart = part_of_surface(master, w)
        turn = rotation(m, m.elset_nodes(mpart)) if mpart else []
        turn = turn or (_motion(m, m.elset_nodes(mpart)) if mpart else [])
        sliding = int(np.sign(turn[-1][0])) if turn else 0
        sl = face(slave, w, "CONTACT PAIR")
        key = f"{sl}_{names.get(master.upper(), master)}"
        if mpart in rigid:
            t = {"type": "rigid_plate", "face": sl}
        else:
            t = {"type": "contact", "slave": sl, "master": face(master, w, "CONTACT PAIR")}
        t.update(kn=float(inter.kn.value), mu=mu, sliding=sliding, kt=kt)
        interfaces[key] = t
        origin[f"interfaces.{key}"] = f"{w}: *CONTACT PAIR" + (" (master on a rigid part)" if mpart in rigid
                                                                else "")
        origin[f"interfaces.{key}.kn"] = f"{inter.kn.where}: *SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR"
        origin[f"interfaces.{key}.mu"] = f"{mu_v.where}: *FRICTION" if mu_v is not None else "no *FRICTION"
        origin[f"interfaces.{key}.kt"] = (f"{lam.where}: *FRICTION stick slope λ = {float(lam.value):g} "
                                          "× μ/μ_static "
                                          f"= {mu:g}/{static_mu:g} (CalculiX's slip-state tangent λ/F)"
                                          if lam is not None else "no stick slope: 0")
        origin[f"interfaces.{key}.sliding"] = (f"{turn[-1][1]}: *BOUNDARY, rigid rotation θ = "
                                               f"{turn[-1][0]:.4g} rad "
                                               "about z of the master part" if turn and len(turn[-1]) == 2 else
                                               f"{turn[-1][1]}: *{turn[-1][2]}, ω = {turn[-1][0]:.4g} rad/s "
                                               "about z of the master part" if turn else
                                               "no prescribed rotation of the master part: no sliding")
        sliding_friction |= mu > 0 and sliding != 0
        if not turn and mu > 0:
            out.notes.append(f"{w}: *CONTACT PAIR {slave}, {master}: μ = {mu:g} but no prescribed rotation of the "
                             f"master part: sliding = 0 (set interfaces.{key}.sliding)")
    out.raw["interfaces"] = interfaces

    statics = [s for s in m.steps if s.static]
    if statics:
        contact = any(t["type"] == "contact" for t in interfaces.values())
        out.raw["preload"] = {"mode": "nonlinear" if contact else "all_closed"}
        origin["preload.mode"] = (f"{statics[0].where}: *{statics[0].procedure}" + ("" if contact else
                                  " (rigid plates on a linear penalty: every point closed)"))
        if any(s.nlgeom for s in statics):
            out.raw["preload"]["geometric_stiffness"] = True
            origin["preload.geometric_stiffness"] = f"{statics[0].where}: *STEP, NLGEOM"
    has_quadratic = any(t in ("tetra10", "hexahedron20", "hexahedron27", "wedge15", "pyramid13")
                        for t, _, _ in m.mesh.blocks)
    out.raw["discretisation"] = {"degree": 2 if has_quadratic else 1}
    origin["discretisation.degree"] = "the deck's element types"

    complex_step = any(s.procedure == "COMPLEX FREQUENCY" for s in eig)
    out.raw["analyses"] = {}
    for st in eig:
        # *FREQUENCY alone on a sliding frictional contact: CalculiX solves the non-symmetric problem (complex)
        cea = st.procedure == "COMPLEX FREQUENCY" or (sliding_friction and not complex_step)
        name = "cea" if cea else "real_modes"
        n = int(st.data[0])
        lo = float(st.data[1]) if len(st.data) > 1 and st.data[1] > 0 else 0.0
        hi = float(st.data[2]) if len(st.data) > 2 and st.data[2] > 0 else OPEN_BAND_TOP_HZ
        if not st.perturbation:
            out.notes.append(f"{st.where}: *STEP without PERTURBATION: run as a perturbation about the preload")
        a = {"n_modes": n,
             "target_hz": max(lo, LOWEST_TARGET_HZ) if hi == OPEN_BAND_TOP_HZ else 0.5 * (lo + hi)}
        if cea:
            a["band_hz"] = [lo, hi]
        out.raw["analyses"][name] = a
        origin[f"analyses.{name}"] = (f"{st.procedure_where}: *{st.procedure}"
                                      + (" on a sliding frictional contact (CalculiX: complex frequencies)"
                                         if st.procedure == "FREQUENCY" and cea else "")
                                      + ("; no frequency range: the lowest modes" if hi == OPEN_BAND_TOP_HZ
                                         else ""))
    return out


def _general_material(m: DeckModel, out: dict, origin: dict, p: str, mat: dict, orient, name: str) -> None:
    """``materials.<p>`` of an orthotropic or anisotropic ``*ELASTIC`` (E1 … G23 or D) with the section's
    ``*ORIENTATION``; constants the physics refuses (not positive definite) name the ``*ELASTIC`` line."""
    if "D" in mat:
        src = mat["D"]
        out["D"] = list(src.value)
        origin[f"materials.{p}.D"] = f"{src.where}: *ELASTIC, TYPE=ORTHOTROPIC/ANISOTROPIC of *MATERIAL {name}"
    elif "engineering" in mat:
        src = mat["engineering"]
        out.update(zip(ENGINEERING_CONSTANTS, src.value))
        origin[f"materials.{p}.E1"] = f"{src.where}: *ELASTIC, TYPE=ENGINEERING CONSTANTS of *MATERIAL {name}"
    else:
        src = mat["E"]
        e, nu = mat["E"].value, mat["nu"].value
        out.update(E1=e, E2=e, E3=e, nu12=nu, nu13=nu, nu23=nu, G12=e / (2 * (1 + nu)), G13=e / (2 * (1 + nu)),
                   G23=e / (2 * (1 + nu)))
        origin[f"materials.{p}.E1"] = f"{src.where}: *ELASTIC (isotropic, written as engineering constants)"
    if orient is not None:
        o = m.orientations[orient.value.upper()]
        out["orientation"] = {k: o.value[k] for k in ("system", "a", "b", "c")}
        origin[f"materials.{p}.orientation"] = (f"{o.where}: *ORIENTATION {o.value['name']} "
                                                f"(*SOLID SECTION at {orient.where})")
    try:
        Material(**{"E": None, "nu": None, **out})
    except ValueError as e:
        raise AbaqusError(f"{src.where}: *ELASTIC of *MATERIAL {name}: {e}") from None


def _point_loads(m: DeckModel, origin: dict, notes: list) -> dict:
    """``loads.point.n<node>`` of the ``*CLOAD`` rows of the model and of its static steps (the force
    components of each node summed, in the node's coordinates)."""
    rows = list(m.cload) + [r for s in m.steps if s.static for r in s.cload]
    for s in m.steps:
        if not s.static and s.cload:
            notes.append(f"{s.cload[0][3]}: *CLOAD in a *{s.procedure} step ignored (an eigenvalue step takes "
                         "no loads)")
    force: dict[int, np.ndarray] = {}
    where: dict[int, str] = {}
    for name, dof, value, w in rows:
        for n in m.set_nodes(name, f"{w}: *CLOAD").tolist():
            force.setdefault(n, np.zeros(3))[dof - 1] += value
            where.setdefault(n, w)
    out = {}
    for n, fv in force.items():
        key = f"n{int(m.mesh.node_ids[n])}"
        out[key] = {"point": [float(c) for c in m.mesh.points[n]], "force": [float(c) for c in fv]}
        origin[f"loads.point.{key}"] = f"{where[n]}: *CLOAD"
    return out


def _motion(m: DeckModel, nodes: np.ndarray) -> list[tuple[float, str, str]]:
    """(ω about +z, where, keyword) of the ``*MOTION, ROTATION, TYPE=VELOCITY`` rows of static steps and
    the ``*TRANSPORT VELOCITY`` rows of steady-state transport steps on ``nodes`` (a rate about the z
    axis: the sliding direction of a rigid rotation of the same sign).  The transport velocity turns
    the material about the axis of Abaqus's ``*SYMMETRIC MODEL GENERATION``, which a deck here does
    not have: the disc axis z of the scene."""
    out = []
    node_set = set(nodes.tolist())
    for s in m.steps:
        if not s.static:
            continue
        for name, omega, w in s.transport:
            if omega != 0.0 and node_set & set(m.set_nodes(name, f"{w}: *TRANSPORT VELOCITY").tolist()):
                out.append((float(omega), w, "TRANSPORT VELOCITY"))
        for name, omega, a, b, w in s.motion:
            if not node_set & set(m.set_nodes(name, f"{w}: *MOTION").tolist()):
                continue
            pa, d = np.asarray(a), np.asarray(b) - np.asarray(a)
            if not np.linalg.norm(d) > 0:
                raise AbaqusError(f"{w}: *MOTION, ROTATION: the axis points a and b coincide")
            d = d / np.linalg.norm(d)
            if np.linalg.norm(d[:2]) > 1e-9 or np.linalg.norm(pa[:2]) > 1e-9 * max(1.0, np.linalg.norm(pa)):
                raise AbaqusError(f"{w}: *MOTION, ROTATION: the axis must be the z axis (the disc axis; got "
                                  f"{list(a)} -> {list(b)})")
            if omega != 0.0:
                out.append((float(omega * np.sign(d[2])), w, "MOTION, ROTATION, TYPE=VELOCITY"))
    return out


# ---------------------------------------------------------------------------------------------- writing TOML


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v))


def scene_toml(ds: DeckScene, scene_path: Path) -> str:
    """The scene as TOML, each value commented with the keyword and line it came from; the deck named
    relative to the scene's folder."""
    raw = json.loads(json.dumps(ds.raw))
    deck = Path(raw["geometry"]["file"])
    try:
        raw["geometry"]["file"] = str(Path(_relative(deck, scene_path.resolve().parent)))
    except ValueError:
        pass
    lines = [f"# Written by fem-squeal convert from {deck.name}: edit freely; each value says where it came from.",
             *[f"# note: {n}" for n in ds.notes], ""]

    def emit(table: dict, path: list[str]) -> None:
        plain = {k: v for k, v in table.items() if not (isinstance(v, dict) and v and _is_section(path + [k], v))}
        note = ds.origin.get(".".join(path))
        if path and (plain or note):
            lines.append(f"[{'.'.join(_key(p) for p in path)}]" + (f"    # {note}" if note else ""))
        for k, v in plain.items():
            note = ds.origin.get(".".join(path + [k]))
            if isinstance(v, dict) and k in ("parts", "faces"):
                lines.append(f"{_key(k)} = {_value(v)}")
                for name in v:
                    n2 = ds.origin.get(".".join(path + [k, name]))
                    if n2:
                        lines.append(f"#   {k}.{name}: {n2}")
                continue
            lines.append(f"{_key(k)} = {_value(v)}" + (f"    # {note}" if note else ""))
        if path and (plain or note):
            lines.append("")
        for k, v in table.items():
            if k not in plain:
                emit(v, path + [k])

    emit(raw, [])
    return "\n".join(lines).rstrip() + "\n"


def _is_section(path: list[str], v: dict) -> bool:
    """A table written as its own [section] (else inline): every table but geometry's parts and faces."""
    return not (len(path) == 2 and path[0] == "geometry")


def _relative(target: Path, folder: Path) -> str:
    return os.path.relpath(target, folder)


def write_scene(deck: str | Path, scene_path: str | Path) -> DeckScene:
    """``fem-squeal convert model.inp scene.toml``: the deck's scene, written (atomically) with its comments."""
    ds = deck_scene(deck)
    scene_path = Path(scene_path)
    with atomic_path(scene_path) as tmp:
        Path(tmp).write_text(scene_toml(ds, scene_path))
    return ds
