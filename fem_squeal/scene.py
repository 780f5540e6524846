"""Scene files: TOML → validated, defaulted dictionary → model description.

The schema below is the one place where keys, types, bounds and defaults are defined.  Errors
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
                 slides in +e_θ relative to the body; −1 backward; 0 none)
                 type = "contact": slave, master (faces), kn [N/m³], mu, sliding (+1: the master
                 slides in +e_θ relative to the slave, i.e. the disc turns forward)
                 type = "spring": slave, master, kn, kt [N/m³];  type = "bonded": slave, master, kn
boundary         clamped = [face names] (all displacement components fixed);
                 ground_springs.<name>: face, k_axial, k_transverse [N/m³]
loads            pressure.<name>: face, p [Pa] (pushes the face inwards)
preload          mode ("nonlinear": active-set Newton then linearise about the closed points;
                 "all_closed": every contact point closed, no static solve), friction (sliding
                 friction in the static step), tol, max_iterations
discretisation   degree (1 or 2), quadrature_degree (0 = automatic), interface_quadrature_degree
analyses.real_modes  n_modes, target_hz, tol, max_residual
analyses.cea         n_modes, target_hz, band_hz = [lo, hi], method ("auto"|"linear"|"pep"),
                     tol, max_residual, describe_part (part whose nodal diameters are reported;
                     "" = "disc" if the model has one, else all)
analyses.reduced     band_hz, tol, cut_factors, static_correction, sigma_hz, growth_tol, enrich_rtol,
                     verify
                     (modal projection with error control; pulled in by sweep and map)
analyses.sweep       parameter ("mu" = sign(v)μ, or "E.<part>" [Pa]), range = [first, last], n:
                     one-parameter sweep on the reduced model with mode tracking
analyses.map         mu_max, n_mu, part, E_range = [E_min, E_max] [Pa], n_E, n_bands: unstable
                     modes per frequency band over the (sign(v)μ, E) design (seed 001 Figs. 17-19)
analyses.masa        mu (list of sign(v)μ values; [] = the scene's), amplitude_max, n_amplitudes,
                     amplitude_unit ("loss": multiples of the amplitude of first contact loss of each
                     instability, "modal": p of seed 000 eq. 25), cubic_share (k_l/k_nl tuning),
                     contact_damping = [c_max per area, depth], patches = [n_radial, n_angular]
                     (AFT elements per interface; [] = every contact point), attachments =
                     [n_radial, n_angular] (basis enrichment), n_samples, sweep_break, update_shape,
                     refine: modal amplitude stability analysis (seed 000; pulls in analyses.reduced)
analyses.transient   omega [rad/s], t_end, dt [s], alpha (HHT), rtol, tangent, adaptive, friction
                     ("constant" | "stribeck" | "coulomb") with mu_s, mu_d, v_s, v_d, k_t, c_t;
                     cubic_share, contact_damping, patches, attachments (as masa), f_cut_hz,
                     zeta_cut, amplitude (initial push [× static closure]), record_every,
                     checkpoint_every, snapshots, snapshot_window (displacement fields as VTU and
                     XDMF): nonlinear transient of the reduced brake (seed 002; pulls in
                     analyses.reduced)
analyses.limit_cycle cycles, svd_shapes, stability_samples, mode_cycle_amplitudes,
                     mode_cycle_samples: post-processing of the transient (seed 002 §3-4)
analyses.segmented_pad  speeds [m/s], velocity_pairs [[v_s, v_d]], pair_speeds, t_end, dt, alpha
                     and every field of fem_squeal.reduced.segmented_pad.SegmentedPad: the lumped
                     pad of seed 004.  A scene with only this analysis has no geometry section.
solver           petsc_options = { key = value } (given with their prefix, e.g. "cea_st_type")
"""
from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fem_squeal.model import GroundSpring, Interface, Material, ModelSpec, Pressure, RigidPlate
from fem_squeal.tags import GEOMETRY_TAGS


class SceneError(ValueError):
    """Invalid scene: the message starts with the key path."""


@dataclass(frozen=True)
class Field:
    kind: type | tuple[type, ...]
    default: Any = ...           # ... = required
    check: Callable[[Any], str | None] | None = None
    doc: str = ""


def positive(v):
    return None if v > 0 else f"must be > 0 (got {v})"


def non_negative(v):
    return None if v >= 0 else f"must be >= 0 (got {v})"


def one_of(*choices):
    return lambda v: None if v in choices else f"must be one of {list(choices)} (got {v!r})"


def poisson(v):
    return None if -1.0 < v < 0.5 else f"must be in (-1, 0.5) (got {v})"


def band(v):
    if len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        return f"must be [low, high] in Hz (got {v!r})"
    return None if 0 <= v[0] < v[1] else f"must be increasing and >= 0 (got {v!r})"


def increasing(min_len: int, low: float | None = None):
    def check(v):
        if len(v) < min_len or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            return f"must be a list of at least {min_len} numbers (got {v!r})"
        if any(b <= a for a, b in zip(v, v[1:])):
            return f"must be increasing (got {v!r})"
        if low is not None and v[0] <= low:
            return f"must be > {low} (got {v!r})"
        return None
    return check


def at_least(n):
    return lambda v: None if v >= n else f"must be >= {n} (got {v})"


def nonempty_str(v):
    return None if v.strip() else "must not be empty"


REAL = (int, float)


def _dataclass_fields(cls) -> dict[str, Field]:
    """Scene fields of a parameter dataclass: its defaults, its types (None = optional real)."""
    out = {}
    for f in dataclasses.fields(cls):
        d = f.default
        kind = bool if isinstance(d, bool) else REAL if isinstance(d, (int, float)) or d is None else type(d)
        out[f.name] = Field(kind, d, None, f.metadata.get("doc", ""))
    return out


def _brake_corner_fields() -> dict[str, Field]:
    from geometry.brake_corner import BrakeCornerParams

    return {"builder": Field(str), **_dataclass_fields(BrakeCornerParams),
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
    from geometry.mesh_file import MeshImportError, file_format

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
        from fem_squeal.tags import mesh_file_tags

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
INTERFACES = {
    "rigid_plate": {"type": _TYPE, "face": Field(str, check=nonempty_str, doc="face name of the geometry"),
                    "kn": Field(REAL, check=non_negative, doc="penalty stiffness per area [N/m³]"), **_FRICTION},
    "contact": {"type": _TYPE, **_PAIR, "kn": Field(REAL, check=positive, doc="penalty [N/m³]"), **_FRICTION},
    "spring": {"type": _TYPE, **_PAIR, "kn": Field(REAL, check=positive, doc="normal stiffness [N/m³]"),
               "kt": Field(REAL, 0.0, non_negative, "tangential stiffness [N/m³]")},
    "bonded": {"type": _TYPE, **_PAIR, "kn": Field(REAL, 1e14, positive, "tie penalty [N/m³]")},
}
GROUND_SPRING = {
    "face": Field(str, check=nonempty_str),
    "k_axial": Field(REAL, 0.0, non_negative, "stiffness along the axis [N/m³]"),
    "k_transverse": Field(REAL, 0.0, non_negative, "stiffness across the axis [N/m³]"),
}
PRESSURE = {"face": Field(str, check=nonempty_str), "p": Field(REAL, check=None, doc="pressure [Pa]")}
SECTIONS = {
    "boundary": {"clamped": Field(list, [], None, "faces with all displacements fixed"),
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
ANALYSES = {
    "real_modes": {
        "n_modes": Field(int, 20, positive), "target_hz": Field(REAL, 1000.0, non_negative),
        "tol": Field(REAL, 1e-10, positive), "max_residual": Field(REAL, 1e-8, positive),
    },
    "cea": {
        "n_modes": Field(int, 20, positive, "complex modes (Im λ > 0) to compute"),
        "target_hz": Field(REAL, 0.0, non_negative, "shift; 0 = centre of band_hz"),
        "band_hz": Field(list, [0.0, 10000.0], band, "frequency band kept in the results"),
        "method": Field(str, "auto", one_of("auto", "linear", "pep")),
        "tol": Field(REAL, 1e-10, positive), "max_residual": Field(REAL, 1e-8, positive),
        "describe_part": Field(str, "", None, "part for nodal diameters; '' = disc if present"),
    },
    "reduced": {
        "band_hz": Field(list, [0.0, 10000.0], band, "band of interest of the reduced model"),
        "tol": Field(REAL, 1e-3, positive, "allowed relative change of the unstable eigenvalues"),
        "cut_factors": Field(list, [1.25, 1.6, 2.0, 2.5], increasing(2, 1.0),
                             "modes up to factor × band top, one basis per factor until tol is met"),
        "static_correction": Field(bool, True, None, "add (K + σM)⁻¹ K_f Φ"),
        "sigma_hz": Field(REAL, 0.0, non_negative, "shift σ = (2π f)² of the correction; 0 = 0.1 × cut"),
        "growth_tol": Field(REAL, 1e-6, positive, "unstable: Re λ > growth_tol |λ|"),
        "enrich_rtol": Field(REAL, 1e-3, positive, "modes sampled at other parameter values keep only "
                             "directions whose new part exceeds this share of their norm"),
        "verify": Field(bool, False, None, "full CEA at the check points, compared with the reduced"),
    },
    "sweep": {
        "parameter": Field(str, "mu", None, "'mu' (sign(v)μ) or 'E.<part>' (Young's modulus [Pa])"),
        "range": Field(list, [-1.0, 1.0], increasing(2), "[first, last] value"),
        "n": Field(int, 101, at_least(2), "number of values"),
    },
    "masa": {
        "mu": Field(list, [], None, "sign(v)μ values, one equilibrium + CEA + MASA each; [] = the scene's"),
        "amplitude_max": Field(REAL, 5.0, positive, "last amplitude of the sweep"),
        "n_amplitudes": Field(int, 100, at_least(2), "amplitude steps (from 0)"),
        "amplitude_unit": Field(str, "loss", one_of("loss", "modal"),
                                "'loss': multiples of the first contact loss; 'modal': p of eq. 25"),
        "cubic_share": Field(REAL, 0.3, non_negative, "share of the preload tangent from k_nl (0 = linear)"),
        "contact_damping": Field(list, [], None, "[c_max per area N s/m³, depth m] (seed 004 eq. 3)"),
        "patches": Field(list, [], None, "[n_radial, n_angular] AFT elements per interface; [] = every "
                         "contact point (default: patches change the stationary amplitudes, see "
                         "benchmarks/README.md)"),
        "attachments": Field(list, [4, 8], None, "[n_radial, n_angular] patch attachment vectors in the "
                             "basis; [] = none"),
        "n_samples": Field(int, 64, at_least(8), "AFT samples per period"),
        "sweep_break": Field(bool, True, None, "stop once the instability's real part is <= 0"),
        "update_shape": Field(bool, False, None, "update ψ, ω from the state matrix along the sweep"),
        "refine": Field(int, 10, non_negative, "bisections of each stationary amplitude"),
    },
    "transient": {
        "omega": Field(REAL, 5.0, positive, "disc speed Ω [rad/s]; the counter-face of each element moves at Ωr"),
        "t_end": Field(REAL, 0.1, positive, "simulated time [s]"),
        "dt": Field(REAL, 1e-6, positive, "time step [s]"),
        "alpha": Field(REAL, 0.0, lambda v: None if -1 / 3 <= v <= 0 else f"must be in [-1/3, 0] (got {v})",
                       "HHT α (0: trapezoidal rule, energy conserving)"),
        "rtol": Field(REAL, 1e-9, positive, "Newton tolerance on the dynamic force scale"),
        "tangent": Field(str, "modified", one_of("modified", "full"), "Newton tangent reuse"),
        "adaptive": Field(bool, False, None, "halve the step around contact and stick/slip events"),
        "friction": Field(str, "constant", one_of("constant", "stribeck", "coulomb"),  # constant: never
                          # reverses (the CEA's sliding law), so it cannot bound a cycle by stick-slip
                          "constant μ (the CEA's), Stribeck μ(v) (seed 004 eq. 4), elastic Coulomb "
                          "(seed 002 eq. 3)"),
        "mu_s": Field(REAL, 0.0, non_negative, "static μ (stribeck, coulomb); 0 = the scene's μ"),
        "mu_d": Field(REAL, 0.0, non_negative, "dynamic μ (stribeck, coulomb); 0 = the scene's μ"),
        "v_s": Field(REAL, 1e-3, positive, "Stribeck static transition velocity [m/s]"),
        "v_d": Field(REAL, 1e-2, positive, "Stribeck dynamic transition velocity [m/s]"),
        "k_t": Field(REAL, 1e8, positive, "elastic Coulomb tangential stiffness per element [N/m]"),
        "c_t": Field(REAL, 0.0, non_negative, "elastic Coulomb stick damping per element [N s/m]"),
        "normal": Field(str, "cubic", one_of("cubic", "exponential"),
                        "normal law per element: cubic with contact damping (seed 000 eq. 3, seed 004 eq. 3) "
                        "or exponential p0 e^(-λg) (seed 002 eq. 2)"),
        "cubic_share": Field(REAL, 0.3, non_negative, "share of the preload tangent from the cubic term"),
        "contact_damping": Field(list, [2e5, 1e-6], None, "[c_max per area N s/m³, depth m] (seed 004 eq. 3); "
                                 "[] = none"),
        "patches": Field(list, [8, 16], None, "[n_radial, n_angular] contact elements per pad; [] = every point"),
        "attachments": Field(list, [4, 8], None, "[n_radial, n_angular] patch attachment vectors in the basis"),
        "f_cut_hz": Field(REAL, 18000.0, non_negative,
                          "modal damping of the basis above this frequency; 0 = none"),
        "zeta_cut": Field(REAL, 0.2, non_negative, "damping ratio above f_cut_hz"),
        "zeta": Field(REAL, 0.0, non_negative, "structural damping ratio on every mode of the basis"),
        "max_iterations": Field(int, 30, positive, "Newton iterations per step"),
        "event_limit": Field(int, 0, non_negative, "adaptive: contact/stick events a step may hold before it "
                             "is halved (a Newton failure always halves)"),
        "amplitude": Field(REAL, 1e-3, positive, "initial push along the most unstable mode [× static closure]"),
        "record_every": Field(int, 10, positive, "record every k steps"),
        "checkpoint_every": Field(int, 20000, non_negative, "checkpoint every k steps (0 = at the end only)"),
        "snapshots": Field(int, 0, non_negative, "displacement fields Φ(q − q_static) written to "
                           "transient_snapshots.vtu/.xdmf, evenly over the last snapshot_window (0 = none)"),
        "snapshot_window": Field(REAL, 0.0, non_negative, "time span of the snapshots [s] (0 = the whole run)"),
    },
    "limit_cycle": {
        "cycles": Field(REAL, 2.0, positive, "periods analysed at the end of the run (SVD window)"),
        "svd_shapes": Field(int, 4, positive, "SVD shapes reported and compared with the CEA modes"),
        "stability_samples": Field(int, 48, at_least(4), "tangent CEAs along the last cycle"),
        "mode_cycle_amplitudes": Field(list, [0.01, 0.1, 0.5, 1.0, 2.0], None,
                                       "α of the complex-mode cycles [× static closure]"),
        "mode_cycle_samples": Field(int, 64, at_least(8), "pseudo-time samples per mode cycle"),
    },
    "segmented_pad": {
        "speeds": Field(list, [0.005, 0.03, 0.1, 0.3], increasing(1, 0.0), "disc speeds at the mean radius [m/s]"),
        "velocity_pairs": Field(list, [], None, "[[v_s, v_d], ...] [m/s], each run at every pair_speeds"),
        "pair_speeds": Field(list, [0.05], increasing(1, 0.0), "disc speeds of the (v_s, v_d) study [m/s]"),
        "t_end": Field(REAL, 0.3, positive, "simulated time per run [s]"),
        "dt": Field(REAL, 4e-5, positive, "time step [s]"),
        "alpha": Field(REAL, -0.3, lambda v: None if -1 / 3 <= v <= 0 else f"must be in [-1/3, 0] (got {v})",
                       "HHT α (damps the stiff sub-v_s branch of the law)"),
        # + every field of fem_squeal.reduced.segmented_pad.SegmentedPad (added below)
    },
    "map": {
        "mu_max": Field(REAL, 1.0, positive, "sign(v)μ from -mu_max to mu_max"),
        "n_mu": Field(int, 101, at_least(2)),
        "part": Field(str, "disc", nonempty_str, "part whose Young's modulus is varied"),
        "E_range": Field(list, [], None, "[E_min, E_max] [Pa]; [] = nominal ± 20 %"),
        "n_E": Field(int, 21, at_least(2)),
        "n_bands": Field(int, 6, positive, "equal frequency ranges of analyses.reduced.band_hz"),
    },
}


def _segmented_pad_fields() -> dict[str, Field]:
    from fem_squeal.reduced.segmented_pad import SegmentedPad

    return _dataclass_fields(SegmentedPad)


ANALYSES["segmented_pad"].update(_segmented_pad_fields())
LUMPED = {"segmented_pad"}     # analyses without a finite-element model (no geometry, no materials)


def _check_fields(table: Any, fields: dict[str, Field], path: str) -> dict:
    if not isinstance(table, dict):
        raise SceneError(f"{path}: must be a table (got {type(table).__name__})")
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise SceneError(f"{path}.{unknown[0]}: unknown key; allowed: {sorted(fields)}")
    out = {}
    for name, f in fields.items():
        key = f"{path}.{name}"
        if name not in table:
            if f.default is ...:
                raise SceneError(f"{key}: required" + (f" ({f.doc})" if f.doc else ""))
            out[name] = copy.deepcopy(f.default)
            continue
        v = table[name]
        kinds = f.kind if isinstance(f.kind, tuple) else (f.kind,)
        if (isinstance(v, bool) and bool not in kinds) or not isinstance(v, kinds):
            want = " or ".join(k.__name__ for k in kinds)
            raise SceneError(f"{key}: must be {want} (got {v!r})")
        if isinstance(v, float) and not math.isfinite(v):
            raise SceneError(f"{key}: must be finite (got {v})")
        if f.check is not None:
            msg = f.check(v)
            if msg:
                raise SceneError(f"{key}: {msg}")
        out[name] = v
    return out


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
    if set(ana) <= LUMPED and "geometry" not in raw:
        return _validate_lumped(raw, scene)
    geo = raw.get("geometry")
    if not isinstance(geo, dict):
        raise SceneError("geometry: required table")
    if "builder" not in geo:
        raise SceneError("geometry.builder: required; one of " + str(sorted(GEOMETRY)))
    if not isinstance(geo["builder"], str) or geo["builder"] not in GEOMETRY:
        raise SceneError(f"geometry.builder: must be one of {sorted(GEOMETRY)} (got {geo['builder']!r})")
    scene["geometry"] = _check_fields(geo, GEOMETRY[geo["builder"]], "geometry")
    builder = geo["builder"]
    if builder == "mesh_file":
        _check_mesh_file(scene["geometry"])
    volumes, faces = geometry_tags(scene["geometry"])
    if builder == "annular_disc" and scene["geometry"]["width"] >= 2 * scene["geometry"]["mean_radius"]:
        raise SceneError("geometry.width: must be < 2 * mean_radius")
    if builder == "brake_corner":
        from geometry.brake_corner import BrakeCornerParams

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
        scene["materials"][part] = m = _check_fields(table, MATERIAL, f"materials.{part}")
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
        t = _check_fields(table, INTERFACES[kind], key)
        for side in ("face", "slave", "master"):
            if side in t:
                known_face(t[side], f"{key}.{side}")
        if "slave" in t and t["slave"] == t["master"]:
            raise SceneError(f"{key}.master: must differ from the slave face ({t['slave']!r})")
        scene["interfaces"][name] = t

    for sec, fields in SECTIONS.items():
        scene[sec] = _check_fields(raw.get(sec, {}), fields, sec)
    for i, f in enumerate(scene["boundary"]["clamped"]):
        if not isinstance(f, str):
            raise SceneError(f"boundary.clamped[{i}]: must be a face name (got {f!r})")
        known_face(f, f"boundary.clamped[{i}]")
    for sec, sub, fields in (("boundary", "ground_springs", GROUND_SPRING), ("loads", "pressure", PRESSURE)):
        checked = {}
        for name, table in scene[sec][sub].items():
            key = f"{sec}.{sub}.{name}"
            t = _check_fields(table, fields, key)
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
    part = scene["analyses"].get("cea", {}).get("describe_part", "")
    if part and part not in volumes:
        raise SceneError(f"analyses.cea.describe_part: unknown part {part!r}; parts: {sorted(volumes)}")
    _check_reduced(scene, volumes)
    return scene


def _check_analyses(ana: dict) -> dict:
    out = {}
    for name, table in ana.items():
        if name not in ANALYSES:
            raise SceneError(f"analyses.{name}: unknown analysis; available: {sorted(ANALYSES)}")
        out[name] = _check_fields(table, ANALYSES[name], f"analyses.{name}")
    if "limit_cycle" in out and "transient" not in out:
        raise SceneError("analyses.limit_cycle: needs analyses.transient (it analyses that run)")
    if "segmented_pad" in out:
        _check_segmented_pad(out["segmented_pad"])
    if "limit_cycle" in out:
        amps = out["limit_cycle"]["mode_cycle_amplitudes"]
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 for v in amps):
            raise SceneError(f"analyses.limit_cycle.mode_cycle_amplitudes: must be numbers > 0 (got {amps})")
    return out


def _check_segmented_pad(a: dict) -> None:
    from fem_squeal.dynamics import pad_parameters

    for i, pair in enumerate(a["velocity_pairs"]):
        key = f"analyses.segmented_pad.velocity_pairs[{i}]"
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(v, (int, float))
                                                                  and not isinstance(v, bool) for v in pair)):
            raise SceneError(f"{key}: must be [v_s, v_d] in m/s (got {pair!r})")
        if not 0 < pair[0] < pair[1]:
            raise SceneError(f"{key}: must satisfy 0 < v_s < v_d (got {pair})")
    if a["velocity_pairs"] and not a["pair_speeds"]:
        raise SceneError("analyses.segmented_pad.pair_speeds: required with velocity_pairs")
    if a["dt"] >= a["t_end"]:
        raise SceneError(f"analyses.segmented_pad.dt: must be < t_end = {a['t_end']} (got {a['dt']})")
    try:
        pad_parameters(a)
    except ValueError as e:
        raise SceneError(f"analyses.{e}") from None


def _validate_lumped(raw: dict, scene: dict) -> dict:
    """A scene of lumped analyses only: no geometry, materials, interfaces or loads."""
    extra = sorted(set(raw) - {"title", "analyses", "solver"})
    if extra:
        raise SceneError(f"{extra[0]}: not used by the analyses {sorted(raw['analyses'])} (they need no "
                         "finite-element model); remove it")
    scene["solver"] = _check_fields(raw.get("solver", {}), SECTIONS["solver"], "solver")
    scene["analyses"] = _check_analyses(raw["analyses"])
    return scene


def _check_patch_list(key: str, v) -> None:
    if v and (len(v) != 2 or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in v)):
        raise SceneError(f"{key}: must be [] or [n_radial, n_angular], integers >= 1 (got {v})")


def _check_damping_pair(key: str, cd) -> None:
    if cd and (len(cd) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0
                                       for v in cd)):
        raise SceneError(f"{key}: must be [] or [c_max > 0, depth > 0] (got {cd})")


def _check_reduced(scene: dict, volumes) -> None:
    """Cross-checks of analyses.reduced/sweep/map (which pull in analyses.reduced)."""
    ana = scene["analyses"]
    if not ({"sweep", "map", "masa", "transient"} & set(ana) or "reduced" in ana):
        return
    ana.setdefault("reduced", _check_fields({}, ANALYSES["reduced"], "analyses.reduced"))
    frictional = [n for n, t in scene["interfaces"].items()
                  if t["type"] in ("rigid_plate", "contact") and t.get("mu", 0) > 0 and t.get("sliding", 0)]
    mus = {scene["interfaces"][n]["mu"] for n in frictional}
    if not frictional:
        raise SceneError("analyses.reduced: needs an interface with friction (mu > 0, sliding != 0); "
                         "its friction stiffness sets the μ direction of the reduced model")
    if len(mus) > 1:
        raise SceneError(f"interfaces: frictional interfaces have different mu {sorted(mus)}; the reduced "
                         "model scales one common friction coefficient")
    if "sweep" in ana:
        par = ana["sweep"]["parameter"]
        if par != "mu":
            if not par.startswith("E.") or par[2:] not in volumes:
                raise SceneError(f"analyses.sweep.parameter: must be 'mu' or 'E.<part>' with a part of "
                                 f"{sorted(volumes)} (got {par!r})")
            if ana["sweep"]["range"][0] <= 0:
                raise SceneError(f"analyses.sweep.range: Young's modulus must be > 0 "
                                 f"(got {ana['sweep']['range']})")
    for name in ("masa", "transient"):
        if name not in ana:
            continue
        m = ana[name]
        if not any(t["type"] == "contact" for t in scene["interfaces"].values()):
            raise SceneError(f"analyses.{name}: needs an interface of type 'contact' (its points carry the "
                             "nonlinear contact law)")
        if scene["preload"]["mode"] != "nonlinear":
            raise SceneError(f"analyses.{name}: needs preload.mode = 'nonlinear' (it starts from the static "
                             "equilibrium)")
        if m["cubic_share"] > 1:
            raise SceneError(f"analyses.{name}.cubic_share: must be in [0, 1] (got {m['cubic_share']})")
        for key in ("patches", "attachments"):
            _check_patch_list(f"analyses.{name}.{key}", m[key])
        _check_damping_pair(f"analyses.{name}.contact_damping", m["contact_damping"])
    if "masa" in ana and not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                 for v in ana["masa"]["mu"]):
        raise SceneError(f"analyses.masa.mu: must be a list of numbers (got {ana['masa']['mu']})")
    if "transient" in ana:
        t = ana["transient"]
        if t["dt"] >= t["t_end"]:
            raise SceneError(f"analyses.transient.dt: must be < t_end = {t['t_end']} (got {t['dt']})")
        if t["snapshot_window"] > t["t_end"]:
            raise SceneError(f"analyses.transient.snapshot_window: must be <= t_end = {t['t_end']} "
                             f"(got {t['snapshot_window']})")
        if t["friction"] == "stribeck" and t["v_d"] <= t["v_s"]:
            raise SceneError(f"analyses.transient.v_d: must be > v_s = {t['v_s']} (got {t['v_d']})")
    if "map" in ana:
        m = ana["map"]
        if m["part"] not in volumes:
            raise SceneError(f"analyses.map.part: unknown part {m['part']!r}; parts: {sorted(volumes)}")
        if m["E_range"]:
            msg = increasing(2, 0.0)(m["E_range"])
            if msg or len(m["E_range"]) != 2:
                raise SceneError(f"analyses.map.E_range: {msg or 'must be [E_min, E_max]'}")


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
    plates = tuple(RigidPlate(t["face"], float(t["kn"]), float(t["mu"]), int(t["sliding"]))
                   for t in scene["interfaces"].values() if t["type"] == "rigid_plate")
    interfaces = tuple(
        Interface(name, t["slave"], t["master"], t["type"], float(t["kn"]), float(t.get("kt", 0.0)),
                  float(t.get("mu", 0.0)), int(t.get("sliding", 0)))
        for name, t in scene["interfaces"].items() if t["type"] != "rigid_plate")
    springs = tuple(GroundSpring(t["face"], float(t["k_axial"]), float(t["k_transverse"]))
                    for t in scene["boundary"]["ground_springs"].values())
    pressures = tuple(Pressure(t["face"], float(t["p"])) for t in scene["loads"]["pressure"].values())
    d = scene["discretisation"]
    return ModelSpec(mats, plates, tuple(scene["boundary"]["clamped"]), d["degree"],
                     d["quadrature_degree"] or None, interfaces=interfaces, ground_springs=springs,
                     pressures=pressures, interface_quadrature_degree=d["interface_quadrature_degree"])
