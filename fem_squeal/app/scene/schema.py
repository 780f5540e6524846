"""The scene schema: the fields of every model section (types, defaults, bounds and their documentation)
and the parts and faces a geometry has.  With each analysis's section (declared by its module in
:mod:`fem_squeal.app.analyses`) this is the one place where a scene's keys are defined: the loader
(:mod:`fem_squeal.app.scene.validation`) checks against these tables and the user guide's reference
(:mod:`fem_squeal.app.schema_reference`) is rendered from them.  A field without a default (``...``)
is required; a default of ``None`` means "not set" (the documented fallback applies)."""
from __future__ import annotations

from collections.abc import Mapping

from fem_squeal.app.fields import (
    REAL,
    Field,
    at_least,
    dataclass_fields,
    non_negative,
    nonempty_str,
    one_of,
    poisson,
    positive,
)
from fem_squeal.reduced.laws.loss_factor import loss_table
from fem_squeal.util.errors import ModelError
from fem_squeal.util.matrix_files import FORMATS
from geometry.brake_corner import BrakeCornerParams
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
        "skip_sets": Field(list, [], lambda v: None if all(isinstance(x, str) for x in v) else
                           f"must be a list of element set names (got {v!r})",
                           "Abaqus decks: element sets left out of the mesh (rigid parts given as "
                           "rigid_plate interfaces), with their nodes and the surfaces on them"),
        "deck": Field(bool, False, None, "Abaqus decks: this scene translates the deck's model keywords "
                      "(fem-squeal convert), so the mesh reader skips *TIE instead of refusing it"),
    },
}



def geometry_tags(geo: Mapping) -> tuple[dict[str, int], dict[str, int]]:
    """Part and face tags of a validated geometry section (``volumes``, ``faces``: name -> tag)."""
    if geo["builder"] == "mesh_file":
        return mesh_file_tags(list(geo["parts"]), list(geo["faces"]))
    return dict(GEOMETRY_TAGS[geo["builder"]][0]), dict(GEOMETRY_TAGS[geo["builder"]][1])


def _loss_table(v: dict) -> str | None:
    """A valid η(f, T) table (:class:`fem_squeal.reduced.laws.loss_factor.LossTable`)."""
    try:
        loss_table(v, "")
    except ModelError as e:
        return str(e).lstrip(".: ")
    return None


MATERIAL = {
    "E": Field(REAL, None, positive, "Young's modulus [Pa] (required unless orthotropic or anisotropic: then the "
               "nominal modulus a parameter scales; not set: 1/S11 of the material frame)"),
    "nu": Field(REAL, None, poisson, "Poisson's ratio (required unless orthotropic or anisotropic)"),
    "rho": Field(REAL, check=positive, doc="density [kg/m³]"),
    "rayleigh_alpha": Field(REAL, 0.0, non_negative, "mass-proportional damping [1/s]"),
    "rayleigh_beta": Field(REAL, 0.0, non_negative, "stiffness-proportional damping [s]"),
    "E_axial": Field(REAL, None, positive, "transversely isotropic: modulus along the axis [Pa]"),
    "nu_axial": Field(REAL, None, None, "transversely isotropic: in-plane contraction under axial stress"),
    "G_axial": Field(REAL, None, positive, "transversely isotropic: shear modulus of axial planes [Pa]"),
    "eta": Field(REAL, 0.0, non_negative, "loss factor η: structural damping K(1 + iη) of the part, in the "
                 "reduced model (whose basis then carries the part's stiffness) and its full-order checks (the "
                 "real problem of twice the size); analyses.cea, with real arithmetic, leaves it out"),
    "eta_table": Field(dict, None, _loss_table,
                       "loss factor as a table η(f, T) (a shim, an insulator): {frequency = [Hz...], "
                       "temperature = [°C...], eta = [[one row per temperature, one column per frequency]], "
                       "reference_frequency, reference_temperature}, interpolated bilinearly; an axis of one "
                       "value (or left out): independent of it.  Constant-η analyses use η at the reference "
                       "point (a constant table: its value, exactly as eta); the reduced stage and "
                       "analyses.operating_matrix solve each mode at its own frequency (fixed point) and "
                       "temperature.  Not with eta"),
}
_ENG = {"E1": "E1 [Pa]", "E2": "E2 [Pa]", "E3": "E3 [Pa]", "nu12": "ν12 (= −ε2/ε1 under σ1)", "nu13": "ν13",
        "nu23": "ν23", "G12": "G12 [Pa]", "G13": "G13 [Pa]", "G23": "G23 [Pa]"}
MATERIAL.update({k: Field(REAL, None, positive if k[0] in "EG" else None,
                          f"orthotropic (all nine, in the orientation's frame): {d}") for k, d in _ENG.items()})


def _numbers(n: tuple[int, ...]):
    def check(v):
        ok = len(v) in n and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        return None if ok else f"must be {' or '.join(map(str, n))} numbers (got {v!r})"
    return check


def _orientation(v: dict) -> str | None:
    unknown = sorted(set(v) - {"system", "a", "b", "c"})
    if unknown:
        return f"unknown key {unknown[0]!r}; allowed: system, a, b, c"
    if v.get("system", "rectangular") not in ("rectangular", "cylindrical"):
        return f"system: must be 'rectangular' or 'cylindrical' (got {v.get('system')!r})"
    for k in ("a", "b", "c"):
        if k in v and _numbers((3,))(v[k]):
            return f"{k}: {_numbers((3,))(v[k])}"
    return None if "a" in v and "b" in v else "needs a and b (points: rectangular a on axis 1, b in the 1-2 " \
        "plane; cylindrical a, b on the axis)"


MATERIAL["D"] = Field(list, None, _numbers((9, 21)), "anisotropic stiffness in the orientation's frame [Pa]: "
                      "Abaqus/CalculiX's D1111 D1122 D2222 D1133 D2233 D3333 D1212 D1313 D2323 (9, orthotropic)"
                      " or the 21 of TYPE=ANISO")
MATERIAL["orientation"] = Field(dict, None, _orientation, "material frame of E1 … G23 or D (*ORIENTATION): "
                                "{system = 'rectangular' | 'cylindrical', a = [x, y, z], b = [x, y, z], c = "
                                "origin (rectangular)} [m, in the model's frame: after geometry's scaling]; "
                                "cylindrical: 1 radial, 2 tangential, 3 along a → b")
def _gap_profile(v: dict) -> str | None:
    unknown = sorted(set(v) - {"offset", "gradient", "at"})
    if unknown:
        return f"unknown key {unknown[0]!r}; allowed: offset, gradient, at"
    if "offset" in v and not (isinstance(v["offset"], (int, float)) and not isinstance(v["offset"], bool)):
        return f"offset: must be a number [m] (got {v['offset']!r})"
    for k in ("gradient", "at"):
        if k in v and (why := _numbers((3,))(v[k])):
            return f"{k}: {why}"
    return None


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
                "kt": _KT, **_FRICTION_LAW,
                "initial_gap": Field(dict, None, _gap_profile, "the surfaces' own gap beyond the mesh's, affine "
                                     "over the slave face: {offset = g [m], gradient = [gx, gy, gz] [m/m], at = "
                                     "[x, y, z] [m] (default: the face's centroid)}, g₀ += offset + "
                                     "gradient·(x − at): a pad's taper wear, a lining standing proud (offset < 0: "
                                     "interference); with it the closed points change with the brake pressure")},
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
POINT_LOAD = {"point": Field(list, check=_numbers((3,)), doc="a node of the mesh [m] (after geometry's scaling)"),
              "force": Field(list, check=_numbers((3,)), doc="force [N] (global x, y, z) at that node")}


def _part_names(v: list) -> str | None:
    """Part names, each at most once.  (Checked against the geometry's parts when operating.gyroscopic
    is true: :func:`fem_squeal.app.scene.validation.check_rotation`.)"""
    if not all(isinstance(p, str) for p in v):
        return f"must be a list of part names (got {v!r})"
    return None if len(set(v)) == len(v) else f"a part is listed twice (got {v!r})"


SECTIONS = {
    "boundary": {"clamped": Field(list, [], None, "faces with all displacements fixed"),
                 "fixed": Field(dict, {}, None, "name -> {face, components}: global components fixed"),
                 "ground_springs": Field(dict, {}, None, "name -> {face, k_axial, k_transverse}")},
    "loads": {"pressure": Field(dict, {}, None, "name -> {face, p}"),
              "point": Field(dict, {}, None, "name -> {point, force}: a concentrated force at a mesh node")},
    "preload": {
        "mode": Field(str, "nonlinear", one_of("nonlinear", "all_closed")),
        "friction": Field(bool, True, None, "sliding friction in the static step"),
        "tol": Field(REAL, 1e-9, positive, "Newton tolerance on ‖R‖/‖f‖"),
        "max_iterations": Field(int, 25, positive),
        "jacobian": Field(str, "auto", one_of("auto", "update", "refactorise", "symmetric"),
                          "Newton's linear solves: 'update' keeps a factorisation and solves later steps by "
                          "low-rank (Woodbury) updates for the points that opened or closed, or by GMRES "
                          "preconditioned by the kept factorisation (PETSc options under preload_krylov_), "
                          "refactorising when the measured cost says so (fem_squeal.fe.kept_factorisation); "
                          "'refactorise' factorises every step; 'symmetric' factorises the frictionless "
                          "Jacobian by Cholesky (CHOLMOD on one rank, MUMPS LDLᵀ on more: half an LU's "
                          "factor) and solves every step by GMRES on the Jacobian preconditioned by it; "
                          "'auto': 'symmetric' where the LU's factors would go out of core (the memory "
                          "model's choice, where the Cholesky fits in core and no pressure continuation "
                          "follows; a preload_mat_mumps_icntl_22 of the user's decides instead), else 'update' "
                          "(fem_squeal.app.resources.preload_jacobian).  All exact Newton steps: the same state "
                          "to round-off (GMRES: to its 1e-11 relative residual)"),
        "max_factorisations": Field(int, 2, positive, "at most this many factorisations with 'update' "
                                    "(more only when an update fails its residual check or GMRES does not "
                                    "converge)"),
        "geometric_stiffness": Field(bool, False, None, "stress stiffening K_σ(σ₀) of the static stress in the "
                                     "CEA (preload, and the centrifugal prestress with operating.gyroscopic)"),
    },
    "discretisation": {
        "degree": Field(int, 2, one_of(1, 2), "Lagrange degree (P1 locks in bending)"),
        "quadrature_degree": Field(int, None, positive, "not set: estimated by the form compiler", unset=0),
        "interface_quadrature_degree": Field(int, 4, positive, "slave-surface quadrature of interfaces"),
        "hexahedra": Field(str, "auto", one_of("auto", "native", "split"),
                           "hexahedral mesh files: 'native' runs hexahedra as they are (degree 2: serendipity S2 "
                           "with 2x2x2 Gauss points = C3D20R; degree 1: Q1 2x2x2 = C3D8, on a C3D8R deck C3D8R's "
                           "one point with hourglass control), 'split' cuts them into "
                           "curved tetrahedra; 'auto' (default): native when every element is a hexahedron of one "
                           "order (interfaces of every type run on both), else split; "
                           "results.json mesh.import.hexahedra says which ran and why"),
    },
    "operating": {
        "speed": Field(REAL, 0.0, non_negative, "disc speed Ω [rad/s] (sliding speed V = Ω r at each contact "
                       "point); 0 = no velocity terms"),
        "gyroscopic": Field(bool, False, None, "the disc's rotation in the space-fixed frame (gyroscopic and "
                            "convective terms; needs speed > 0)"),
        "rotating_parts": Field(list, ["disc"], _part_names, "parts that turn at operating.speed about z (with "
                                "gyroscopic = true)"),
    },
    "solver": {"petsc_options": Field(dict, {}, None, "PETSc options, with their solver prefix")},
}
#: the name -> table maps inside model sections, with the fields of their tables
SUBTABLES = {("boundary", "fixed"): FIXED, ("boundary", "ground_springs"): GROUND_SPRING,
             ("loads", "pressure"): PRESSURE, ("loads", "point"): POINT_LOAD}


def _range(v: list) -> str | None:
    """[low, high], low < high."""
    if len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        return f"must be [low, high] (got {v!r})"
    return None if v[0] < v[1] else f"must be increasing (got {v!r})"


def _some_matrix(v: dict) -> str | None:
    """At least one named matrix."""
    return None if v else "must name at least one matrix"


#: ``matrices.files.<name>``: one named matrix (a string is the file alone)
MATRIX_FILE = {
    "file": Field(str, check=nonempty_str, doc="the file, relative to the scene: Matrix Market (.mtx, .mm), "
                  "MATLAB (.mat) or Harwell-Boeing (.hb, .rb, .rua, .rsa, .hbmat)"),
    "format": Field(str, "", one_of("", *FORMATS), "'' = from the extension"),
    "variable": Field(str, "", None, "MATLAB: the variable holding the matrix; '' = the matrix's name where the "
                      "file has it, else the file's only variable"),
}
#: ``matrices.parameters.<name>``: one parameter of the operators (a number is the value alone)
MATRIX_PARAMETER = {
    "value": Field(REAL, doc="nominal value (the point real_modes and cea solve at)"),
    "range": Field(list, None, _range, "[low, high]: the range studies of the parameter cover"),
}
#: ``[matrices]``: a model given as matrices (no geometry, materials or interfaces then)
MATRICES = {
    "files": Field(dict, check=_some_matrix,
                   doc="name -> file, or {file, format, variable}: the named matrices (square, all of one size)"),
    "M": Field(str, check=nonempty_str, doc="mass operator: an expression of the named matrices and parameters"),
    "C": Field(str, None, nonempty_str, "damping operator (not set: undamped)"),
    "K": Field(str, check=nonempty_str, doc="stiffness operator, e.g. \"K1 + KR + (W**2 - 1)*KGEO\""),
    "parameters": Field(dict, {}, None, "name -> {value, range}, or name -> value"),
    "dofs": Field(int, None, positive, "the size n every matrix must have (not set: not checked)"),
    "block_size": Field(int, 1, positive, "degrees of freedom per node, numbered node by node (3 for a solid "
                        "model): the factorisations order nodes, and the ranks get whole nodes; n must be a "
                        "multiple"),
}
