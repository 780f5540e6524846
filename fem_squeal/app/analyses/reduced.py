"""The ``reduced`` analysis: the parametric reduced model of the linearised brake.

The basis is grown to ``tol`` (:func:`fem_squeal.fe.projection.adaptive_reduce`), checked at the
nominal point and at the corners of the parameter ranges that the sweep, the map and MASA ask for
(:func:`design_points`); optionally the full CEA at those points, compared with the reduced one
(``verify``).  Every analysis on the reduced model (sweep, map, masa, transient) pulls this one in
with its defaults.  File: reduced_model.npz (and basis_field.npz for transient snapshots)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app.analyses import pressure_continuation
from fem_squeal.app.analyses.preload import operating
from fem_squeal.app.fields import REAL, Field, band, increasing, positive
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import num as _num
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.fe.model import common_mu
from fem_squeal.reduced.eigensolve import TWO_PI, band_centre_hz, in_band, unstable
from fem_squeal.reduced.model import MU, PRESSURE, SPEED, e_param, format_point
from fem_squeal.reduced.operating_matrix import LossFactors, condition_fixed_point
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.errors import ModelError, SceneError

SECTION = {
    "band_hz": Field(list, [0.0, 10000.0], band, "band of interest of the reduced model"),
    "tol": Field(REAL, 1e-3, positive, "allowed relative change of the unstable eigenvalues"),
    "cut_factors": Field(list, [1.25, 1.6, 2.0, 2.5], increasing(2, 1.0),
                         "modes up to factor × band top, one basis per factor until tol is met"),
    "static_correction": Field(bool, True, None, "add (K + σM)⁻¹ K_f Φ"),
    "sigma_hz": Field(REAL, None, positive, "the corrections and E directions use (K + σM)⁻¹ with "
                      "σ = (2π f)²; not set: the band centre f_c inside the band, (K − (2π f_c)²M)⁻¹",
                      unset=0),
    "growth_tol": Field(REAL, 1e-6, positive, "unstable: Re λ > growth_tol |λ|"),
    "enrich_rtol": Field(REAL, 1e-3, positive, "modes sampled at other parameter values keep only "
                         "directions whose new part exceeds this share of their norm"),
    "verify": Field(bool, False, None, "full CEA at the check points, compared with the reduced"),
    "nominal_snapshot": Field(bool, False, None, "one greedy step once tol is met: the full CEA's band "
                              "eigenvectors at the nominal point (the parts' nominal loss factors; with a "
                              "loss factor the real problem of twice the size) join the basis; it brings a "
                              "shim's η(f) fixed point to the full nonlinear eigenproblem (two blocks: "
                              "2.2e-6 to 1.1e-7), at the cost of that CEA"),
}


def map_E_range(scene: dict, spec) -> tuple[float, float]:
    m = scene.analyses["map"]
    E0 = spec.materials[m["part"]].E
    return tuple(m["E_range"]) if m["E_range"] else (0.8 * E0, 1.2 * E0)


def map_speed_range(scene: dict) -> tuple[float, float]:
    """analyses.map.speed_range, or operating.speed × [0.5, 2] when not given."""
    m = scene.analyses["map"]
    w = scene.operating.speed
    return tuple(m["speed_range"]) if m["speed_range"] else (0.5 * w, 2.0 * w)


def speed_not_a_parameter(scene: dict) -> str | None:
    """Why ``speed`` (the disc speed Ω) is not a parameter of this scene's reduced model; None when it
    is: that needs a nominal operating.speed > 0, a term that depends on it (operating.gyroscopic or
    an interface's friction_damping) and no μ(V) law (whose μ, damping and preload are not affine in Ω)."""
    speed = scene.operating.speed
    if not speed > 0:
        return f"operating.speed = {speed}: the nominal speed must be > 0"
    laws = [n for n, t in scene.interfaces.items() if t.get("friction", "constant") != "constant"]
    if laws:
        return (f"interfaces.{laws[0]}.friction = {scene.interfaces[laws[0]]['friction']!r}: μ(V), its damping "
                "and the preload are not affine in the speed")
    if not (scene.operating.gyroscopic or any(t.get("friction_damping") for t in scene.interfaces.values())):
        return ("nothing depends on it: set operating.gyroscopic = true or interfaces.<name>.friction_damping "
                "= true")
    return None


def robustness_E_ranges(section: dict, prefixes: tuple[str, ...] = ("E",)) -> dict[str, tuple[float, float]]:
    """``E.<part>`` (and ``<prefix>.<name>`` for the other ``prefixes``, e.g. kn, kt) → (low, high) of
    analyses.robustness's distributions (the nested ``E = {part = ...}`` too): a uniform's bounds,
    mean ∓ 3 std of a normal, exp(m ∓ 3s) of a lognormal (99.7 % of the samples)."""
    params = section.get("parameters", {})
    tables = {}
    for prefix in prefixes:
        nested = params.get(prefix, {})
        if isinstance(nested, dict):
            tables.update({f"{prefix}.{k}": v for k, v in nested.items() if isinstance(v, dict)})
        tables.update({k: v for k, v in params.items() if k.startswith(prefix + ".")})
        if prefix == SPEED and isinstance(params.get(SPEED), dict):   # a bare name, no target
            tables[SPEED] = params[SPEED]
    out = {}
    for name, t in tables.items():
        kind = t.get("distribution") if isinstance(t, dict) else None
        try:
            if kind == "uniform":
                out[name] = (float(t["lower"]), float(t["upper"]))
            elif kind == "normal":
                out[name] = (float(t["mean"]) - 3 * float(t["std"]), float(t["mean"]) + 3 * float(t["std"]))
            elif kind == "lognormal":
                s2 = np.log1p((float(t["std"]) / float(t["mean"])) ** 2)
                m = np.log(float(t["mean"])) - s2 / 2
                out[name] = (float(np.exp(m - 3 * np.sqrt(s2))), float(np.exp(m + 3 * np.sqrt(s2))))
        except (KeyError, TypeError, ValueError, ZeroDivisionError):
            continue   # the robustness section's own check names the bad key
    return out


def design_points(scene: dict, spec, mu0: float) -> tuple[list[dict], list[dict], list[str]]:
    """(check points, E samples for the basis, parts whose E varies) implied by sweep, map, the E, kn and
    kt distributions of robustness (their ranges: :func:`robustness_E_ranges`) and the operating matrix's
    pressures where the pressure is a parameter (stress stiffening, friction damping: its extreme scales)."""
    ana = scene.analyses
    checks: list[dict] = [{MU: mu0}]
    samples: list[dict] = []
    parts: list[str] = []
    if "sweep" in ana:
        s = ana["sweep"]
        lo, hi = s["range"]
        if s["parameter"] == MU:
            checks += [{MU: lo}, {MU: hi}]
        elif s["parameter"] == SPEED:   # the modes do not depend on Ω: no samples, the corrections do
            checks += [{MU: mu0, SPEED: lo}, {MU: mu0, SPEED: hi}]
        else:
            parts.append(s["parameter"][2:])
            samples += [{s["parameter"]: lo}, {s["parameter"]: hi}]
            checks += [{MU: mu0, s["parameter"]: lo}, {MU: mu0, s["parameter"]: hi}]
    if "map" in ana:
        m = ana["map"]
        if m["second"] == SPEED:
            checks += [{MU: s * m["mu_max"], SPEED: w} for s in (-1, 1) for w in map_speed_range(scene)]
        else:
            name = e_param(m["part"])
            parts.append(m["part"])
            e_lo, e_hi = map_E_range(scene, spec)
            samples += [{name: e_lo}, {name: e_hi}]
            checks += [{MU: s * m["mu_max"], name: e} for s in (-1, 1) for e in (e_lo, e_hi)]
    if "masa" in ana:
        checks += [{MU: float(v)} for v in ana["masa"]["mu"]]
    if "robustness" in ana:   # E, k_n, k_t of the scatter: modes sampled at the ends of their ranges
        for name, (lo, hi) in robustness_E_ranges(ana["robustness"], ("E", "kn", "kt", SPEED)).items():
            if name.startswith("E."):
                parts.append(name[2:])
            if name != SPEED:     # the modes do not depend on the speed: checks only
                samples += [{name: lo}, {name: hi}]
            checks += [{MU: mu0, name: lo}, {MU: mu0, name: hi}]
    if pressure_continuation.pressure_parameter(scene):    # K_σ(u(s)), C_d(p(s)) at the extreme scales s
        ps = pressure_continuation.scales(scene) + [pressure_continuation.SCENE_PRESSURE]
        checks += [{MU: mu0, PRESSURE: min(ps)}, {MU: mu0, PRESSURE: max(ps)}]
    uniq = lambda pts: [dict(t) for t in dict.fromkeys(tuple(sorted(p.items())) for p in pts)]  # noqa: E731
    return uniq(checks), uniq(samples), sorted(set(parts))


def basis_design(scene: dict, spec) -> tuple[float, list[dict], list[dict], list[str]]:
    """(μ₀, check points, E samples, parts whose stiffness the basis carries): :func:`design_points`,
    with every part when a transient asks for component strain-energy shares along its cycle, and
    every part with a loss factor η > 0 (its K_i carries the i η K_i term of the reduced model)."""
    mu0 = common_mu(spec)
    checks, samples, parts = design_points(scene, spec, mu0)
    if "transient" in scene.analyses:
        parts = sorted(spec.materials)
    parts = sorted(set(parts) | {p for p, m in spec.materials.items()
                                 if getattr(m, "eta", 0.0) > 0 or getattr(m, "eta_table", None) is not None})
    return mu0, checks, samples, parts


def full_cea(par, point: dict, band, nev: int, options) -> tuple[np.ndarray, float]:
    """Eigenvalues (Im λ > 0, in ``band``) of the full CEA at ``point`` and its wall time [s]
    (:func:`fem_squeal.fe.projection.full_modes`: with a loss factor, the real problem of twice the size)."""
    from fem_squeal.fe.projection import full_modes  # heavy: FE stack

    t = time.perf_counter()
    lam = full_modes(par, point, nev, band_centre_hz(band), band_hz=tuple(band), options=options, prefix="verify_",
                     progress=True)
    return lam, time.perf_counter() - t


def band_eigenvalues(lam: np.ndarray, band) -> tuple[np.ndarray, int]:
    """The reduced eigenvalues a full CEA is compared with: those in ``band``, the rigid-body modes of free
    parts (λ ≈ 0) aside (:func:`~fem_squeal.reduced.eigensolve.in_band`); and how many modes the full CEA
    asks for, as many as the band holds with them, + 2 (its reach to the band's edges)."""
    f = lam.imag / TWO_PI
    return lam[in_band(lam, band)], int(np.sum((f >= band[0]) & (f <= band[1]))) + 2


def verify_point(par, model, point: dict, band, growth_tol: float, options) -> dict:
    """Full CEA at ``point`` against the reduced eigenvalues: worst relative error of the unstable
    full eigenvalues (of all in the band when none is unstable)."""
    from fem_squeal.fe.projection import relative_change  # heavy: FE stack

    lam_r, n_ask = band_eigenvalues(solve_points(model, {k: np.array([v]) for k, v in point.items()})[0], band)
    full, seconds = full_cea(par, point, band, n_ask, options)
    full = full[in_band(full, band)]
    bad = unstable(full, growth_tol)
    watched = full[bad] if bad.any() else full
    return {"point": point, "n_full": int(full.size), "n_unstable_full": int(bad.sum()),
            "n_unstable_reduced": int(unstable(lam_r, growth_tol).sum()),
            "max_rel_error": relative_change(watched, lam_r), "full_cea_s": seconds,
            "unstable_full": [complex(x) for x in full[bad]]}


def band_and_growth_tol(scene: dict) -> tuple[tuple[float, float], float]:
    """analyses.reduced's band [Hz] and growth tolerance (unstable: Re λ > growth_tol |λ|)."""
    a = scene.analyses["reduced"]
    return tuple(a["band_hz"]), a["growth_tol"]


def field_basis_needed(scene: dict) -> bool:
    """The transient writes snapshots, so the reduced stage keeps Φ on the mesh nodes (basis_field.npz)."""
    return scene.analyses.get("transient", {}).get("snapshots", 0) > 0


def extra_vector_settings(scene: dict) -> list | None:
    """Patch attachments that MASA and the transient need in the basis (None: no extra vectors)."""
    ana = scene.analyses
    sets = [ana[a]["attachments"] for a in ("masa", "transient") if a in ana]
    if not sets:
        return None
    non_empty = [s for s in sets if s]
    return max(non_empty, key=lambda s: s[0] * s[1]) if non_empty else []


def inputs(scene: dict, spec) -> dict:
    """What the reduced basis depends on: analyses.reduced, the check points, E samples and parts
    of :func:`basis_design`, and the extra vectors that masa and transient add."""
    _, checks, samples, parts = basis_design(scene, spec)
    return {"reduced": scene.analyses["reduced"], "checks": checks, "samples": samples, "parts": parts,
            "extra_vectors": extra_vector_settings(scene), "field_basis": field_basis_needed(scene)}


def masa_vectors(ops, preload, attachments: list, band, options) -> np.ndarray:
    """Basis vectors MASA and the transient need beyond the modes: the preload displacement (so
    that the reduced static equilibrium reproduces the full one) and the contact-patch
    attachments ([n_radial, n_angular]; [] = none)."""
    from fem_squeal.fe.projection import contact_attachments  # heavy: FE stack

    cols = [preload.u.array_r.copy()[:, None]]
    if attachments:
        cols.append(contact_attachments(ops, tuple(attachments), 0.1 * band[1], options))
    return np.hstack(cols)


def parametric_operators(ctx: Context, mu0: float, parts: list[str]):
    """The full-order K(p), C(p) (:class:`fem_squeal.fe.projection.ParametricOperators`) of this scene
    about its preload, with the rotation, prestress and friction damping at operating.speed, and the
    stress stiffening and friction damping across the operating matrix's pressures where the pressure is a
    parameter (:func:`~fem_squeal.app.analyses.pressure_continuation.pressure_terms`)."""
    from fem_squeal.fe.projection import ParametricOperators  # heavy: FE stack

    return ParametricOperators(ctx.products["linear"], ctx.spec, mu0, parts, preload=ctx.products["preload"],
                               operating=operating(ctx), speed0=ctx.scene.operating.speed,
                               pressure=pressure_continuation.pressure_terms(ctx))


def state_operators(ctx: Context, mu0: float, parts: list[str], state):
    """(the full-order K(p), C(p) about another contact state ``state`` (a continued preload: the operating
    matrix's pressure whose contact set is not the scene's), the operators it was built on): the scene's
    linearisation moved to that state's closed points (:func:`fem_squeal.fe.assembly.relinearise`), with
    the rotation and prestress of :func:`parametric_operators`.  The caller destroys both (the operators'
    new K and K_f: :func:`destroy_state_operators`)."""
    from fem_squeal.fe.assembly import relinearise  # heavy: FE stack
    from fem_squeal.fe.projection import ParametricOperators  # heavy: FE stack

    ops = relinearise(ctx.products["linear"], ctx.products["preload"].active, state.active)
    return ParametricOperators(ops, ctx.spec, mu0, parts, preload=state, operating=operating(ctx),
                               speed0=ctx.scene.operating.speed,
                               pressure=pressure_continuation.pressure_terms(ctx)), ops


def destroy_state_operators(par, ops) -> None:
    """Destroy what :func:`state_operators` made."""
    from fem_squeal.fe.assembly import destroy_relinearised  # heavy: FE stack

    par.destroy()
    destroy_relinearised(ops)


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.reduced: the basis grown to ``tol`` about the preload; ``reduced_model.npz``."""
    from fem_squeal.fe.output import write_basis_field  # heavy: FE stack
    from fem_squeal.fe.projection import adaptive_reduce  # heavy: FE stack

    scene, spec, comm, say = ctx.scene, ctx.spec, ctx.comm, ctx.say
    ops, preload = ctx.products["linear"], ctx.products["preload"]
    a = scene.analyses["reduced"]
    band = tuple(a["band_hz"])
    opts = scene.solver.petsc_options
    mu0, checks, samples, parts = basis_design(scene, spec)
    par = parametric_operators(ctx, mu0, parts)
    t = time.perf_counter()
    attach = extra_vector_settings(scene)
    extra = masa_vectors(ops, preload, attach, band, opts) if attach is not None else None
    model, basis, report = adaptive_reduce(
        ops, par, band, checks, tol=a["tol"], cut_factors=tuple(a["cut_factors"]), samples=samples,
        static=a["static_correction"], sigma_hz=a["sigma_hz"], growth_tol=a["growth_tol"],
        enrich_rtol=a["enrich_rtol"], preload=preload, options=opts, log=say, extra=extra,
        states=ctx.products.get("pressure_states"), snapshots=checks[:1] if a["nominal_snapshot"] else ())
    timings["reduced_basis"] = time.perf_counter() - t
    if comm.rank == 0:
        model.save(work / "reduced_model.npz")
    if field_basis_needed(scene):
        write_basis_field(comm, work / "basis_field.npz", ops.V, basis.Phi)
    out: dict[str, Any] = {"size": model.size, "parameters": model.parameters, "mu0": mu0, **report.as_dict()}
    say(f"[fem_squeal] reduced model: {model.size} vectors {basis.counts}, estimated error "
        f"{report.estimate:.1e}, {timings['reduced_basis']:.1f} s")
    if a["verify"]:
        t = time.perf_counter()
        rows = [verify_point(par, model, p, band, a["growth_tol"], opts) for p in checks]
        timings["reduced_verify"] = time.perf_counter() - t
        out["verification"] = rows
        say("[fem_squeal] reduced vs full CEA: " + ", ".join(
            f"{format_point(r['point'])}: {r['max_rel_error']:.1e}" for r in rows))
    par.destroy()
    fp = loss_factor_fixed_point(spec, model, band)
    if fp is not None:
        out["loss_factor_fixed_point"] = fp
        say(f"[fem_squeal] reduced model, η(f) fixed point: {fp['converged']}/{fp['modes']} modes converged, "
            f"at most {fp['max_iterations_used']} iterations")
    ctx.products["reduced"] = model
    return {"reduced": out}


def loss_factor_fixed_point(spec, model, band) -> dict | None:
    """With a part's loss factor η(f, T) that varies with f: the nominal point's band modes solved at their
    own frequency (the fixed point of :func:`fem_squeal.reduced.operating_matrix.condition_fixed_point`) at
    the tables' reference temperature: the summary and the eigenvalues [re, im]; None otherwise."""
    tables = {p: m.eta_table for p, m in spec.materials.items() if getattr(m, "eta_table", None) is not None}
    varying = {p: t for p, t in tables.items() if t.varies_with_frequency}
    if not varying:
        return None
    temps = sorted({float(t.reference_temperature) for t in tables.values()
                    if t.reference_temperature is not None})
    if len(temps) > 1:
        raise SceneError(f"materials: the η(f, T) tables have different reference temperatures {temps}; "
                         "the reduced stage solves at one temperature")
    T = temps[0] if temps else float(next(iter(tables.values())).temperature[0])
    try:
        lam, res = condition_fixed_point(model, {}, 1.0, LossFactors(tables, tuple(band)), T)
    except ModelError as e:
        raise SceneError(f"materials: {e}") from None
    return {"temperature": float(T), **res.summary(),
            "eigenvalues": [[float(x.real), float(x.imag)] for x in res.eigenvalues],
            "iterations": res.iterations.tolist(), "converged_per_mode": res.converged.tolist()}


def mismatches(rows: list[dict], tol: float, what: str = "",
               where=lambda r: format_point(r["point"])) -> list[str]:
    """The reduced-vs-full checks ``rows`` (``max_rel_error``, ``n_unstable_full``, ``n_unstable_reduced``)
    where the reduced model misses the full CEA: relative error above ``tol``, or a different number of
    unstable modes; ``where(row)`` names the point."""
    out = []
    for v in rows:
        if v["max_rel_error"] > tol:
            out.append(f"{what}reduced vs full at {where(v)}: {v['max_rel_error']:.1e} > tol {tol}")
        if v["n_unstable_full"] != v["n_unstable_reduced"]:
            out.append(f"{what}{v['n_unstable_reduced']} unstable reduced vs {v['n_unstable_full']} full "
                       f"at {where(v)}")
    return out


def verification_failures(reduced: dict, what: str = "") -> list[str]:
    """The check points of ``results["reduced"]`` where the reduced model misses the full CEA
    (:func:`mismatches` with the requested ``tol``)."""
    return mismatches(reduced.get("verification", []), reduced["tol"], what)


def check(scene: dict, volumes) -> None:
    """A reduced model needs friction (its μ direction) with one common μ on every frictional interface."""
    frictional = [n for n, t in scene.interfaces.items()
                  if t["type"] in ("rigid_plate", "contact") and t.get("mu", 0) > 0 and t.get("sliding", 0)]
    mus = {scene.interfaces[n]["mu"] for n in frictional}
    if not frictional:
        raise SceneError("analyses.reduced: needs an interface with friction (mu > 0, sliding != 0); "
                         "its friction stiffness sets the μ direction of the reduced model")
    if len(mus) > 1:
        raise SceneError(f"interfaces: frictional interfaces have different mu {sorted(mus)}; the reduced "
                         "model scales one common friction coefficient")


def check_contact_study(scene: dict, name: str) -> None:
    """Cross-checks shared by the nonlinear studies on the reduced model (masa, transient)."""
    m = scene.analyses[name]
    if not any(t["type"] == "contact" for t in scene.interfaces.values()):
        raise SceneError(f"analyses.{name}: needs an interface of type 'contact' (its points carry the "
                         "nonlinear contact law)")
    if scene.preload.mode != "nonlinear":
        raise SceneError(f"analyses.{name}: needs preload.mode = 'nonlinear' (it starts from the static "
                         "equilibrium)")
    if m["cubic_share"] > 1:
        raise SceneError(f"analyses.{name}.cubic_share: must be in [0, 1] (got {m['cubic_share']})")
    for key in ("patches", "attachments"):
        v = m[key]
        if v and (len(v) != 2 or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in v)):
            raise SceneError(f"analyses.{name}.{key}: must be [] or [n_radial, n_angular], integers >= 1 "
                             f"(got {v})")
    cd = m["contact_damping"]
    if cd and (len(cd) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0
                                       for v in cd)):
        raise SceneError(f"analyses.{name}.contact_damping: must be [] or [c_max > 0, depth > 0] (got {cd})")


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "reduced" not in res:
        return ""
    r = res["reduced"]
    txt = (f"<h2>Reduced model</h2><p>{r['size']} vectors, parameters {_e(r['parameters'])}, estimated "
           f"error {_num(r.get('estimated_error'))} (tol {_num(r['tol'])}), "
           f"converged {_e(r.get('converged'))}.</p>")
    if r.get("verification"):
        txt += _table(["point", "max rel. error", "unstable full", "unstable reduced"],
                      [[format_point(v["point"]), v["max_rel_error"], v["n_unstable_full"],
                        v["n_unstable_reduced"]] for v in r["verification"]])
    return (txt)


STAGE = Stage("reduced", ("preload",), run, "reduced basis with error control", inputs=inputs, section=SECTION,
              check=check, report=report, pulled=True)
