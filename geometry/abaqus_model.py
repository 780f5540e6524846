"""The model of an Abaqus/CalculiX squeal deck: materials, sections, boundary conditions, loads, ties,
contact pairs with their interaction, and the steps, each value with the keyword and line it came from.

:func:`read_model` reads the keywords below (``*INCLUDE`` followed relative to the including file, as
:mod:`geometry.abaqus` does; the mesh keywords ``*NODE``, ``*ELEMENT``, ``*NSET``, ``*ELSET``, ``*SURFACE``
are that module's).  Any other keyword is an :class:`AbaqusError` naming it, the file and the line;
output requests are kept as notes.  The translation into a scene is the application's
(:mod:`fem_squeal.app.deck`); here the deck is only read and its rigid parts and motions recognised.

- ``*MATERIAL, NAME=`` with ``*ELASTIC`` (``TYPE=ISOTROPIC``: E, ν; ``TYPE=ENGINEERING CONSTANTS``: E1 E2
  E3 ν12 ν13 ν23 G12 G13 G23; ``TYPE=ORTHOTROPIC``: D1111 D1122 D2222 D1133 D2233 D3333 D1212 D1313 D2323;
  ``TYPE=ANISOTROPIC``: the 21 D_ijkl), ``*DENSITY``, ``*DAMPING, ALPHA=, BETA=``;
- ``*ORIENTATION, NAME=, SYSTEM=RECTANGULAR|CYLINDRICAL`` (a, b[, c]; an optional second line of a
  zero additional rotation);
- ``*SOLID SECTION, ELSET=, MATERIAL=[, ORIENTATION=]``;
- ``*BOUNDARY`` (node or node set, first, last[, value]) in the model or a step;
- ``*DLOAD`` (element set, Pn, p; or surface, P, p), ``*CLOAD`` (node or node set, degree of freedom 1-3,
  force);
- ``*MOTION, ROTATION, TYPE=VELOCITY`` (node set, ω, a, b: a rigid rotation rate about the axis a → b) in
  a static step: the disc's sliding motion, as a prescribed rotation gives it;
- ``*TRANSPORT VELOCITY`` (node set or node, ω: the angular velocity of the material transported through the
  mesh, Abaqus's keyword manual) in a ``*STEADY STATE TRANSPORT`` step: the same sliding motion, about the
  axis Abaqus takes from ``*SYMMETRIC MODEL GENERATION`` (a keyword not read here): the disc axis z of
  fem_squeal's scenes.  The step is a static step otherwise (``*BOUNDARY``, ``*DLOAD``, ``*CLOAD``,
  ``NLGEOM``); ``INERTIA=YES`` and a ``*MOTION`` in it (which moves the reference frame there) are refused,
  and ``ELSET=`` (the Eulerian element set) must hold the transported nodes;
- ``*TIE, NAME=`` (slave, master), ``*SURFACE INTERACTION, NAME=`` with ``*SURFACE BEHAVIOR,
  PRESSURE-OVERCLOSURE=LINEAR`` (slope, σ∞) and ``*FRICTION`` (μ, stick slope λ), ``*CONTACT PAIR,
  INTERACTION=`` (slave, master);
- ``*STEP`` [``PERTURBATION``, ``NLGEOM``] with ``*STATIC``, ``*FREQUENCY`` (n[, tol, f_min, f_max]),
  ``*COMPLEX FREQUENCY`` (n[, f_min, f_max]), ``*STEADY STATE TRANSPORT``, ``*CHANGE FRICTION, INTERACTION=``
  + ``*FRICTION``, ``*END STEP``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from geometry.abaqus import AbaqusError, Deck, _blocks, read_deck

MESH = {"NODE", "ELEMENT", "NSET", "ELSET", "SURFACE"}
#: The procedures of a static step (the preload): a steady-state transport step is one where the disc turns.
STATIC_PROCEDURES = ("STATIC", "STEADY STATE TRANSPORT")
#: Output requests: ignored, with a note.
OUTPUT = {"NODE PRINT", "EL PRINT", "NODE FILE", "EL FILE", "OUTPUT", "NODE OUTPUT", "ELEMENT OUTPUT",
          "CONTACT PRINT", "CONTACT FILE", "CONTACT OUTPUT", "ENERGY PRINT", "SECTION PRINT", "NODE RESPONSE",
          "FACE PRINT", "RESTART", "PRINT", "MONITOR"}
#: Keywords whose data belong to the keyword above them.
OPTIONS = {"ELASTIC": "MATERIAL", "DENSITY": "MATERIAL", "DAMPING": "MATERIAL",
           "SURFACE BEHAVIOR": "SURFACE INTERACTION", "FRICTION": "SURFACE INTERACTION"}
#: The parameters each model keyword may have (any other is refused: it would change what the keyword means).
PARAMETERS = {
    "MATERIAL": {"NAME"}, "ELASTIC": {"TYPE"}, "DENSITY": set(), "DAMPING": {"ALPHA", "BETA"},
    "SOLID SECTION": {"ELSET", "MATERIAL", "ORIENTATION"},
    "ORIENTATION": {"NAME", "SYSTEM", "DEFINITION"}, "MOTION": {"ROTATION", "TYPE"},
    "BOUNDARY": {"OP", "TYPE"}, "DLOAD": {"OP"}, "CLOAD": {"OP"},
    "TIE": {"NAME", "POSITION TOLERANCE", "ADJUST"}, "SURFACE INTERACTION": {"NAME"},
    "SURFACE BEHAVIOR": {"PRESSURE-OVERCLOSURE"}, "FRICTION": set(),
    "CONTACT PAIR": {"INTERACTION", "TYPE", "SMALL SLIDING", "ADJUST"},
    "STEP": {"PERTURBATION", "NLGEOM", "INC", "NAME", "UNSYMM"}, "STATIC": {"SOLVER", "DIRECT"},
    "FREQUENCY": {"SOLVER", "STORAGE", "EIGENSOLVER", "NORMALIZATION"}, "COMPLEX FREQUENCY": set(),
    "STEADY STATE TRANSPORT": {"DIRECT", "ELSET", "INERTIA", "LONG TERM"}, "TRANSPORT VELOCITY": set(),
    "CHANGE FRICTION": {"INTERACTION"}, "END STEP": set(), "HEADING": set(),
}
SUPPORTED = sorted(MESH | set(OPTIONS) | {"MATERIAL", "SOLID SECTION", "BOUNDARY", "DLOAD", "CLOAD", "TIE",
                                          "ORIENTATION", "MOTION", "STEADY STATE TRANSPORT",
                                          "TRANSPORT VELOCITY",
                                          "SURFACE INTERACTION", "CONTACT PAIR", "STEP", "STATIC", "FREQUENCY",
                                          "COMPLEX FREQUENCY", "CHANGE FRICTION", "END STEP", "HEADING"})


@dataclass
class Value:
    """A number or name of the deck and where it was written (``file line n: *KEYWORD``)."""

    value: object
    where: str


@dataclass
class Interaction:
    kn: Value | None = None             # LINEAR overclosure slope [N/m³]
    sigma_inf: float = 0.0
    mu: Value | None = None             # *FRICTION μ
    stick: Value | None = None          # *FRICTION stick slope λ [N/m³]
    where: str = ""


@dataclass
class Step:
    where: str
    perturbation: bool = False
    nlgeom: bool = False
    procedure: str = ""                 # STATIC, STEADY STATE TRANSPORT, FREQUENCY, COMPLEX FREQUENCY
    procedure_where: str = ""
    data: list = field(default_factory=list)       # the procedure's data line (numbers)
    boundary: list = field(default_factory=list)   # (node or set, first, last, value, where)
    dload: list = field(default_factory=list)      # (element set or surface, label, p, where)
    cload: list = field(default_factory=list)      # (node or set, degree of freedom 1-3, force, where)
    motion: list = field(default_factory=list)     # (node or set, ω [rad/s], a, b, where)
    transport: list = field(default_factory=list)  # *TRANSPORT VELOCITY (node or set, ω [rad/s], where)
    eulerian: Value | None = None                  # *STEADY STATE TRANSPORT, ELSET= (None: the whole model)
    friction: dict = field(default_factory=dict)   # interaction -> (μ Value, λ Value | None)

    @property
    def static(self) -> bool:
        """A static step: ``*STATIC`` or ``*STEADY STATE TRANSPORT`` (the preload of the eigenvalue steps)."""
        return self.procedure in STATIC_PROCEDURES


@dataclass
class DeckModel:
    """The model keywords of a deck (see the module text) and its mesh (:class:`geometry.abaqus.Deck`)."""

    path: Path
    mesh: Deck
    materials: dict = field(default_factory=dict)    # name -> {key: Value}
    sections: dict = field(default_factory=dict)     # element set (upper) -> Value(material)
    section_orientation: dict = field(default_factory=dict)  # element set (upper) -> Value(orientation name)
    orientations: dict = field(default_factory=dict)  # name (upper) -> Value({system, a, b, c})
    cload: list = field(default_factory=list)         # model-level (node or set, dof, force, where)
    boundary: list = field(default_factory=list)     # model-level (node or set, first, last, value, where)
    dload: list = field(default_factory=list)
    ties: list = field(default_factory=list)         # (name, slave, master, where)
    interactions: dict = field(default_factory=dict)  # name (upper) -> Interaction
    pairs: list = field(default_factory=list)        # (interaction, slave, master, where)
    steps: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def set_nodes(self, name: str, where: str) -> np.ndarray:
        """Node indices of a node set or of one node number."""
        key = name.strip().upper()
        if key in self.mesh.nsets:
            return np.asarray(self.mesh.nsets[key])
        if key.isdigit():
            hit = np.flatnonzero(self.mesh.node_ids == int(key))
            if len(hit):
                return hit
        raise AbaqusError(f"{where}: no node set or node {name.strip()!r}")

    def elset_nodes(self, name: str) -> np.ndarray:
        """Node indices of the elements of an element set."""
        members = set(self.mesh.elsets.get(name.upper(), []))
        out = [c[np.isin(ids, list(members))].ravel() for _, c, ids in self.mesh.blocks]
        return np.unique(np.concatenate(out)) if out else np.zeros(0, np.int64)


def _floats(lines, n: int, where: str, what: str) -> list[float]:
    vals = [v.strip() for ln, _ in lines for v in ln.split(",") if v.strip()]
    try:
        out = [float(v) for v in vals]
    except ValueError:
        raise AbaqusError(f"{where}: {what}: expected numbers (got {', '.join(vals)!r})") from None
    if len(out) < n:
        raise AbaqusError(f"{where}: {what}: needs {n} values (got {len(out)})")
    return out


def _fields(ln: str) -> list[str]:
    return [v.strip() for v in ln.split(",")]


def _boundary_rows(lines, where: str) -> list:
    rows = []
    for ln, w in lines:
        f = [v for v in _fields(ln) if v != ""]
        try:
            first = int(f[1])
            last = int(f[2]) if len(f) > 2 else first
            value = float(f[3]) if len(f) > 3 else 0.0
        except (ValueError, IndexError):
            raise AbaqusError(f"{w}: *BOUNDARY: expected node or set, first, last[, value] (got {ln.strip()!r})"
                              ) from None
        if not 1 <= first <= last <= 3:
            raise AbaqusError(f"{w}: *BOUNDARY: degrees of freedom {first}-{last}: only 1-3 (displacements) "
                              "are supported")
        rows.append((f[0], first, last, value, w))
    return rows


def read_model(path: str | Path) -> DeckModel:
    """The model of the deck ``path`` (see the module text); raises :class:`AbaqusError` naming the keyword,
    the file and the line of what it cannot translate."""
    path = Path(path)
    model = DeckModel(path, read_deck(path, model=True))
    owner = ""              # the keyword (MATERIAL, SURFACE INTERACTION) that options belong to
    material = interaction = None
    step: Step | None = None
    change: str | None = None
    for kw, params, lines, where in _blocks(path):
        at = f"{where}: *{kw}"
        if kw in MESH or kw == "HEADING":
            owner, change = "", None
            continue
        if kw in OUTPUT:
            model.notes.append(f"{at}: output request ignored")
            continue
        extra = sorted(set(params) - PARAMETERS.get(kw, set(params)))
        if extra:
            raise AbaqusError(f"{at}, {extra[0]}: parameter not supported (allowed: "
                              f"{', '.join(sorted(PARAMETERS[kw])) or 'none'})")
        if params.get("OP", "MOD").upper() != "MOD":
            raise AbaqusError(f"{at}, OP={params['OP']}: only OP=MOD (conditions kept from step to step)")
        if kw in OPTIONS and not (kw == "FRICTION" and change):
            if owner != OPTIONS[kw]:
                raise AbaqusError(f"{at}: must follow *{OPTIONS[kw]}")
        elif kw not in OPTIONS:
            owner, change = kw, None
        if kw == "MATERIAL":
            name = params.get("NAME", "")
            if not name:
                raise AbaqusError(f"{at}: NAME= is required")
            material = model.materials.setdefault(name.upper(), {"name": Value(name, where)})
        elif kw == "ELASTIC":
            kind = params.get("TYPE", "ISOTROPIC").upper().replace("_", " ")
            name = material["name"].value
            n_lines = {"ISOTROPIC": 1, "ENGINEERING CONSTANTS": 2, "ORTHOTROPIC": 2, "ORTHO": 2,
                       "ANISOTROPIC": 3, "ANISO": 3}.get(kind)
            if n_lines is None:
                raise AbaqusError(f"{at}, TYPE={params['TYPE']}: not supported (ISOTROPIC, ENGINEERING CONSTANTS, "
                                  "ORTHOTROPIC, ANISOTROPIC)")
            if "DEPENDENCIES" in params or len(lines) > n_lines:
                raise AbaqusError(f"{at}: temperature or field dependent constants are not supported")
            if kind == "ISOTROPIC":
                e, nu = _floats(lines, 2, where, f"*ELASTIC of {name}")[:2]
                material.update(E=Value(e, where), nu=Value(nu, where))
            elif kind == "ENGINEERING CONSTANTS":
                c = _floats(lines, 9, where, f"*ELASTIC, TYPE=ENGINEERING CONSTANTS of {name}")[:9]
                material["engineering"] = Value(c, where)
                material.update(_transversely_isotropic(c, at) or {})
            else:
                n = 9 if kind.startswith("ORTHO") else 21
                d = _floats(lines, n, where, f"*ELASTIC, TYPE={params['TYPE']} of {name}")[:n]
                material["D"] = Value(d, where)
        elif kw == "DENSITY":
            material["rho"] = Value(_floats(lines, 1, where, "*DENSITY")[0], where)
        elif kw == "DAMPING":
            for key, name in (("ALPHA", "rayleigh_alpha"), ("BETA", "rayleigh_beta")):
                if key in params:
                    try:
                        material[name] = Value(float(params[key]), where)
                    except ValueError:
                        raise AbaqusError(f"{at}, {key}={params[key]}: not a number") from None
            other = sorted(set(params) - {"ALPHA", "BETA"})
            if other:
                raise AbaqusError(f"{at}, {other[0]}: not supported (Rayleigh ALPHA, BETA only)")
        elif kw == "SOLID SECTION":
            if "ELSET" not in params or "MATERIAL" not in params:
                raise AbaqusError(f"{at}: ELSET= and MATERIAL= are required")
            model.sections[params["ELSET"].upper()] = Value(params["MATERIAL"], where)
            if params.get("ORIENTATION"):
                model.section_orientation[params["ELSET"].upper()] = Value(params["ORIENTATION"], where)
        elif kw == "ORIENTATION":
            model.orientations[_orientation_name(params, at)] = Value(_orientation(params, lines, at), where)
        elif kw == "CLOAD":
            rows = []
            for ln, w in lines:
                f = [v for v in _fields(ln) if v != ""]
                try:
                    row = (f[0], int(f[1]), float(f[2]), w)
                except (ValueError, IndexError):
                    raise AbaqusError(f"{w}: *CLOAD: expected node or node set, degree of freedom, force "
                                      f"(got {ln.strip()!r})") from None
                if row[1] not in (1, 2, 3):
                    raise AbaqusError(f"{w}: *CLOAD, {f[1]}: only forces (degrees of freedom 1-3)")
                rows.append(row)
            (step.cload if step else model.cload).extend(rows)
        elif kw == "MOTION":
            if step is None:
                raise AbaqusError(f"{at}: must be in a *STEP (history data)")
            if "ROTATION" not in params or params.get("TYPE", "").upper() != "VELOCITY":
                raise AbaqusError(f"{at}: only ROTATION, TYPE=VELOCITY (the disc's rotation rate) is supported")
            for ln, w in lines:
                f = [v for v in _fields(ln) if v != ""]
                try:
                    vals = [float(v) for v in f[1:8]]
                except ValueError:
                    vals = []
                if len(f) < 8 or len(vals) != 7:
                    raise AbaqusError(f"{w}: *MOTION, ROTATION: expected node set, ω, a_x, a_y, a_z, b_x, b_y, "
                                      f"b_z (got {ln.strip()!r})")
                step.motion.append((f[0], vals[0], tuple(vals[1:4]), tuple(vals[4:7]), w))
        elif kw == "TRANSPORT VELOCITY":
            if step is None:
                raise AbaqusError(f"{at}: must be in a *STEP (history data)")
            for ln, w in lines:
                f = [v for v in _fields(ln) if v != ""]
                try:
                    omega = float(f[1]) if len(f) == 2 else None
                except ValueError:
                    omega = None
                if omega is None:
                    raise AbaqusError(f"{w}: *TRANSPORT VELOCITY: expected node set or node, ω (the axis is "
                                      "*SYMMETRIC MODEL GENERATION's: here the disc axis z; got "
                                      f"{ln.strip()!r})")
                step.transport.append((f[0], omega, w))
        elif kw == "BOUNDARY":
            if params.get("TYPE", "DISPLACEMENT").upper() != "DISPLACEMENT" or "AMPLITUDE" in params:
                raise AbaqusError(f"{at}: only displacement boundary conditions without amplitude are supported")
            (step.boundary if step else model.boundary).extend(_boundary_rows(lines, where))
        elif kw == "DLOAD":
            for ln, w in lines:
                f = _fields(ln)
                try:
                    row = (f[0], f[1].upper(), float(f[2]), w)
                except (ValueError, IndexError):
                    raise AbaqusError(f"{w}: *DLOAD: expected element set or surface, Pn, pressure") from None
                if row[1] != "P" and not (len(row[1]) == 2 and row[1][0] == "P" and row[1][1] in "123456"):
                    raise AbaqusError(f"{w}: *DLOAD, {f[1]}: only pressure (P, P1-P6) is supported")
                (step.dload if step else model.dload).append(row)
        elif kw == "CLOAD":
            raise AbaqusError(f"{at}: concentrated forces are not supported (fem_squeal has face pressures "
                              "only: use *DLOAD)")
        elif kw == "TIE":
            for ln, w in lines:
                f = _fields(ln)
                if len(f) < 2 or not f[0] or not f[1]:
                    raise AbaqusError(f"{w}: *TIE: expected slave surface, master surface")
                model.ties.append((params.get("NAME", f"tie{len(model.ties) + 1}"), f[0], f[1], w))
        elif kw == "SURFACE INTERACTION":
            name = params.get("NAME", "")
            if not name:
                raise AbaqusError(f"{at}: NAME= is required")
            interaction = model.interactions.setdefault(name.upper(), Interaction(where=where))
        elif kw == "SURFACE BEHAVIOR":
            law = params.get("PRESSURE-OVERCLOSURE", "HARD").upper()
            if law != "LINEAR":
                raise AbaqusError(f"{at}, PRESSURE-OVERCLOSURE={law}: only LINEAR (a penalty slope) is supported")
            v = _floats(lines, 1, where, "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR")
            interaction.kn = Value(v[0], where)
            interaction.sigma_inf = v[1] if len(v) > 1 else 0.0
        elif kw == "FRICTION":
            v = _floats(lines, 1, where, "*FRICTION")
            mu, stick = Value(v[0], where), (Value(v[1], where) if len(v) > 1 else None)
            if change:
                step.friction[change] = (mu, stick)
            else:
                interaction.mu, interaction.stick = mu, stick
        elif kw == "CONTACT PAIR":
            name = params.get("INTERACTION", "").upper()
            if name not in model.interactions:
                raise AbaqusError(f"{at}: INTERACTION={params.get('INTERACTION', '')}: no such "
                                  "*SURFACE INTERACTION")
            for ln, w in lines:
                f = _fields(ln)
                if len(f) < 2 or not f[0] or not f[1]:
                    raise AbaqusError(f"{w}: *CONTACT PAIR: expected slave surface, master surface")
                model.pairs.append((name, f[0], f[1], w))
        elif kw == "STEP":
            if step is not None:
                raise AbaqusError(f"{at}: *STEP inside the step of {step.where} (missing *END STEP)")
            step = Step(where, "PERTURBATION" in params,
                        params.get("NLGEOM", "NO" if "NLGEOM" not in params else "YES").upper() != "NO")
        elif kw in ("STATIC", "FREQUENCY", "COMPLEX FREQUENCY", "STEADY STATE TRANSPORT"):
            if step is None or step.procedure:
                raise AbaqusError(f"{at}: must be the procedure of a *STEP")
            if kw in STATIC_PROCEDURES and step.perturbation:
                raise AbaqusError(f"{at}: a static perturbation step is not supported")
            if kw == "STEADY STATE TRANSPORT":
                if params.get("INERTIA", "NO").upper() != "NO":
                    raise AbaqusError(f"{at}, INERTIA={params['INERTIA']}: not supported (the centrifugal and "
                                      "gyroscopic terms of the turning disc: operating.gyroscopic of a scene)")
                if "ELSET" in params:
                    step.eulerian = Value(params["ELSET"], where)
            if kw != "STATIC" and "SOLVER" in params and params["SOLVER"].upper() == "MATRIXSTORAGE":
                raise AbaqusError(f"{at}, SOLVER=MATRIXSTORAGE: not supported")
            step.procedure, step.procedure_where = kw, where
            step.data = _floats(lines[:1], 1, where, f"*{kw}") if kw not in STATIC_PROCEDURES else \
                (_floats(lines[:1], 0, where, f"*{kw}") if lines else [])
        elif kw == "CHANGE FRICTION":
            name = params.get("INTERACTION", "").upper()
            if step is None or name not in model.interactions:
                raise AbaqusError(f"{at}: must be in a *STEP and name a *SURFACE INTERACTION with INTERACTION=")
            change = name
        elif kw == "END STEP":
            if step is None:
                raise AbaqusError(f"{at}: no *STEP to end")
            if not step.procedure:
                raise AbaqusError(f"{at}: the step of {step.where} has no procedure (*STATIC, *FREQUENCY, "
                                  "*COMPLEX FREQUENCY, *STEADY STATE TRANSPORT)")
            _check_transport(model, step)
            model.steps.append(step)
            step = None
        elif kw not in OPTIONS:
            raise AbaqusError(f"{at}: not supported in a squeal deck; supported: *{', *'.join(SUPPORTED)} "
                              "and output requests (ignored)")
    if step is not None:
        raise AbaqusError(f"{step.where}: *STEP without *END STEP")
    for o in model.section_orientation.values():
        if o.value.upper() not in model.orientations:
            raise AbaqusError(f"{o.where}: *SOLID SECTION, ORIENTATION={o.value}: no such *ORIENTATION (defined: "
                              f"{', '.join(v.value['name'] for v in model.orientations.values()) or 'none'})")
    return model


def _check_transport(model: DeckModel, step: Step) -> None:
    """``*TRANSPORT VELOCITY`` only in a ``*STEADY STATE TRANSPORT`` step and on nodes of its Eulerian
    element set (``ELSET=``, where given); ``*MOTION`` not in one (there it moves the reference frame)."""
    sst = step.procedure == "STEADY STATE TRANSPORT"
    if step.transport and not sst:
        raise AbaqusError(f"{step.transport[0][2]}: *TRANSPORT VELOCITY: only in a *STEADY STATE TRANSPORT step "
                          f"(the step of {step.where} is *{step.procedure}; there the disc's rotation is "
                          "*MOTION, ROTATION, TYPE=VELOCITY)")
    if step.motion and sst:
        raise AbaqusError(f"{step.motion[0][4]}: *MOTION in a *STEADY STATE TRANSPORT step (the motion of the "
                          "reference frame) is not supported; the disc's rotation there is *TRANSPORT VELOCITY")
    if step.eulerian is None:
        return
    name = step.eulerian.value.strip().upper()
    if name not in model.mesh.elsets:
        raise AbaqusError(f"{step.eulerian.where}: *STEADY STATE TRANSPORT, ELSET={step.eulerian.value}: no such "
                          "element set")
    inside = set(model.elset_nodes(name).tolist())
    for node_set, _, w in step.transport:
        if not set(model.set_nodes(node_set, f"{w}: *TRANSPORT VELOCITY").tolist()) <= inside:
            raise AbaqusError(f"{w}: *TRANSPORT VELOCITY {node_set}: nodes outside the Eulerian element set "
                              f"ELSET={step.eulerian.value} of *STEADY STATE TRANSPORT ({step.eulerian.where})")


def _orientation_name(params: dict, at: str) -> str:
    if not params.get("NAME"):
        raise AbaqusError(f"{at}: NAME= is required")
    return params["NAME"].upper()


def _orientation(params: dict, lines, at: str) -> dict:
    """{name, system, a, b, c} of an ``*ORIENTATION`` (``DEFINITION=COORDINATES``)."""
    system = params.get("SYSTEM", "RECTANGULAR").upper()
    if system not in ("RECTANGULAR", "CYLINDRICAL"):
        raise AbaqusError(f"{at}, SYSTEM={params['SYSTEM']}: only RECTANGULAR and CYLINDRICAL")
    if params.get("DEFINITION", "COORDINATES").upper() != "COORDINATES":
        raise AbaqusError(f"{at}, DEFINITION={params['DEFINITION']}: only COORDINATES (points a, b[, c])")
    if not lines:
        raise AbaqusError(f"{at}: needs a data line (a_x, a_y, a_z, b_x, b_y, b_z[, c_x, c_y, c_z])")
    v = _floats(lines[:1], 6, lines[0][1], f"*ORIENTATION {params['NAME']}")
    if len(v) not in (6, 9):
        raise AbaqusError(f"{lines[0][1]}: *ORIENTATION {params['NAME']}: 6 or 9 coordinates (got {len(v)})")
    for ln, w in lines[1:]:
        f = [x for x in _fields(ln) if x != ""]
        try:
            angle = float(f[1]) if len(f) > 1 else 0.0
        except ValueError:
            raise AbaqusError(f"{w}: *ORIENTATION: expected local axis, angle (got {ln.strip()!r})") from None
        if angle != 0.0 or len(lines) > 2:
            raise AbaqusError(f"{w}: *ORIENTATION {params['NAME']}: an additional rotation ({angle:g} degrees) "
                              "is not supported; give the rotated points a, b")
    a, b = v[0:3], v[3:6]
    c = v[6:9] if len(v) == 9 else [0.0, 0.0, 0.0]
    pa, pb, pc = (np.asarray(p) for p in (a, b, c))
    if system == "RECTANGULAR" and (np.linalg.norm(pa - pc) == 0 or np.linalg.norm(np.cross(pa - pc, pb - pc))
                                    <= 1e-12 * np.linalg.norm(pa - pc) * np.linalg.norm(pb - pc)):
        raise AbaqusError(f"{lines[0][1]}: *ORIENTATION {params['NAME']}: point a must differ from the origin and "
                          "b must not lie on the local 1 axis")
    if system == "CYLINDRICAL" and np.linalg.norm(pb - pa) == 0:
        raise AbaqusError(f"{lines[0][1]}: *ORIENTATION {params['NAME']}: a and b (two points of the axis) "
                          "coincide")
    return {"name": params["NAME"], "system": system.lower(), "a": a, "b": b, "c": c}


def _transversely_isotropic(c: list[float], at: str) -> dict | None:
    """E, ν, E_axial, ν_axial, G_axial of engineering constants transversely isotropic about z:
    E1 = E2, ν13 = ν23, G13 = G23 and G12 = E1/(2(1 + ν12)); ν_axial = ν31 = ν13 E3/E1.  None when they are
    not (orthotropic: the scene's E1 … G23)."""
    e1, e2, e3, n12, n13, n23, g12, g13, g23 = c
    where = at.split(": *")[0]

    def close(a, b):
        return abs(a - b) <= 1e-6 * max(abs(a), abs(b), 1e-300)

    if not (close(e1, e2) and close(n13, n23) and close(g13, g23) and close(g12, e1 / (2 * (1 + n12)))):
        return None
    return {"E": Value(e1, where), "nu": Value(n12, where), "E_axial": Value(e3, where),
            "nu_axial": Value(n13 * e3 / e1, where), "G_axial": Value(g13, where)}


def rigid_sets(model: DeckModel) -> dict[str, str]:
    """Element sets of sections whose every node has all three displacements prescribed (in the model or
    a static step): rigid parts.  Name (upper) -> where the section is."""
    held: dict[int, set] = {}
    rows = list(model.boundary) + [r for s in model.steps if s.static for r in s.boundary]
    for name, first, last, _, w in rows:
        for n in model.set_nodes(name, w).tolist():
            held.setdefault(n, set()).update(range(first, last + 1))
    out = {}
    for elset, sec in model.sections.items():
        nodes = model.elset_nodes(elset)
        if len(nodes) and all(held.get(int(n), set()) >= {1, 2, 3} for n in nodes):
            out[elset] = sec.where
    return out


def rotation(model: DeckModel, nodes: np.ndarray) -> list[tuple[float, str]]:
    """The rigid rotation θ about z of ``nodes`` prescribed in each static step (``*STATIC``, ``*STEADY STATE
    TRANSPORT``) where it changes:
    θ = Σ (x u_y − y u_x) / Σ (x² + y²) over the nodes with both in-plane values (u = θ e_z × x)."""
    pts = model.mesh.points
    out = []
    node_set = set(nodes.tolist())
    for s in model.steps:
        if not s.static:
            continue
        u: dict[int, list] = {}
        where = ""
        for name, first, last, value, w in s.boundary:
            for n in model.set_nodes(name, w).tolist():
                if n in node_set:
                    for c in range(first, last + 1):
                        if c in (1, 2):
                            u.setdefault(n, [0.0, 0.0, 0])
                            u[n][c - 1] = value
                            u[n][2] += 1
                            where = where or w
        both = [(n, v) for n, v in u.items() if v[2] >= 2]
        if not both:
            continue
        x = pts[[n for n, _ in both]]
        ux = np.array([v[0] for _, v in both])
        uy = np.array([v[1] for _, v in both])
        den = float(np.sum(x[:, 0] ** 2 + x[:, 1] ** 2))
        theta = float(np.sum(x[:, 0] * uy - x[:, 1] * ux)) / den if den > 0 else 0.0
        if theta != 0.0:
            out.append((theta, where))
    return out
