"""The ``operating_matrix`` analysis (issue 39, first part): brake conditions swept like a dynamometer
squeal test (SAE J2521) on the reduced model, with friction laws μ(T, Ω) per interface, and the
noise-matrix report (occurrence of instability against 1/3-octave band and against each condition
variable, the unstable modes per condition with their growth rates).

The physics of a condition is in :mod:`fem_squeal.reduced.operating_matrix`: temperature and speed act
through the friction laws (and the speed through the model's gyroscopic, centrifugal and friction-damping
terms where Ω is a parameter), the direction turns the friction and gyroscopic terms.  The pressure is
the scale of ``loads.pressure``: the preload stage continues the scene's preload to the other pressures
(:mod:`fem_squeal.app.analyses.pressure_continuation`); they are evaluated on the one reduced model.  A
pressure that opens or closes contact points (e.g. a pad's taper, ``interfaces.<c>.initial_gap``) is
evaluated with its own contact state: the model's ``contact_states``, its basis enriched with the modes
about each such state, solved or as static derivatives where the change is small
(:func:`fem_squeal.fe.projection.adaptive_reduce`), its checks solved on the full operators linearised
about that state, at the corners and at the inner pressure whose set changed most
(:func:`checked_conditions`).  With the contact set of the scene the stress stiffening and
the contacts' friction damping make the pressure the model's parameter ``pressure`` (K_σ(u(s)) = K_σ(u(1))
+ (s − 1) K_σ(du/ds), C_d(p(s)) = C_d(p(1)) + (s − 1) C_d(dp/ds), exact for the fixed contact set and the
linear penalty: :mod:`fem_squeal.fe.pressure_terms`); with a changing set the model holds each pressure's
own projections of these two (``pressure_tables``); the other pressure-dependent terms are refused before
any computation (:func:`pressure_dependent_terms`).
Parts with a loss-factor table
``materials.<part>.eta_table`` η(f, T): at each condition's temperature, per band mode at its own frequency
(fixed point; ``loss_factor_fixed_point`` in results.json: iterations, modes not converged).  ``verify``:
full CEAs at the corner conditions, compared as analyses.reduced compares its check points; with a table
in f, the full nonlinear eigenproblem T(λ) with η at each answer's own frequency, from the unstable and
least stable reduced eigenvalues (``analyses.reduced.nominal_snapshot`` adds the full eigenvectors at the
nominal point to the basis, which brings the fixed point to the full NEP).
Every unstable mode carries its coupling (the participation of the basis's real modes, as the μ sweep's).
Files: operating_matrix_conditions.csv, operating_matrix_modes.csv (with the coupling pair),
operating_matrix_bands.csv, operating_matrix.png (+ its .csv)."""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses import pressure_continuation
from fem_squeal.app.analyses.condition_values import VALUES, values
from fem_squeal.app.analyses.reduced import (
    band_and_growth_tol,
    band_eigenvalues,
    destroy_state_operators,
    full_cea,
    mismatches,
    parametric_operators,
    speed_not_a_parameter,
    state_operators,
)
from fem_squeal.app.fields import Field, one_of
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import num as _num
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.affine import PRESSURE
from fem_squeal.reduced.eigensolve import band_centre_hz, in_band, unstable
from fem_squeal.reduced.laws.friction import ConstantFriction, StribeckFriction, TableFriction
from fem_squeal.reduced.laws.loss_factor import loss_table
from fem_squeal.reduced.operating_matrix import (
    DIRECTIONS,
    UNITS,
    VARIABLES,
    Conditions,
    InterfaceLaw,
    LossFactors,
    evaluate,
    factorial,
    from_table,
    mode_couplings,
    noise_matrix,
    parameter_points,
)
from fem_squeal.util.atomic import write_csv_atomic
from fem_squeal.util.errors import EigenSolveError, ModelError, SceneError

NAME = "operating_matrix"
_KEY = f"analyses.{NAME}"
#: corner checks with a loss factor η(f): the least stable reduced modes solved in the full NEP besides
#: the unstable ones (a barely stable reduced mode that the full model has unstable is then caught)
NEP_LEAST_STABLE = 3
#: ... converged when |Δλ|/|λ| ≤ this: the unstable modes of a merged pair sit near an exceptional point,
#: where λ is known to about √ε (the ring's stalled at 3.8e-12 against the solver's default 1e-12)
NEP_TOL = 1e-10
SECTION = {
    "pressure": Field((list, dict), [1.0], None, "scales of loads.pressure (" + VALUES + "); other than 1 "
                      "(the scene's): the preload is continued to them and each must keep the scene's contact "
                      "set; they act through the friction laws μ(p, T, Ω), the stress stiffening "
                      "(preload.geometric_stiffness) and the contacts' friction damping"),
    "temperature": Field((list, dict), [20.0], None, f"disc temperatures [°C] ({VALUES}); they act through "
                         "the friction laws"),
    "speed": Field((list, dict), [], None, f"disc speeds |Ω| [rad/s] ({VALUES}); [] = operating.speed"),
    "direction": Field(list, ["forward", "reverse"], None, "'forward' (the scene's sliding direction) and/or "
                       "'reverse' (the disc turning the other way)"),
    "design": Field(str, "factorial", one_of("factorial", "table"), "factorial: every combination of the "
                    "lists; table: the rows of conditions"),
    "conditions": Field(list, [], None, "design = 'table': [{pressure, temperature, speed, direction}, ...]"),
    "friction": Field(dict, {}, None, "friction laws μ(T, Ω): default = {...} (every frictional interface "
                      "without its own) and <interface> = {...}; a law is {law = 'constant', mu}, {law = "
                      "'stribeck', mu_s, mu_d, v_s, v_d, radius [m]} (V = |Ω| radius) or {law = 'table', "
                      "temperature = [...], speed = [...], mu = [[...], ...]} (bilinear, one row per temperature, "
                      "no extrapolation); {} = the scene's μ everywhere"),
    "verify": Field(bool, False, None, "full CEAs at the corner conditions, compared with the reduced (with a "
                    "loss-factor table in f: the full nonlinear eigenproblem, η at each mode's own frequency, "
                    "from the unstable and the least stable reduced eigenvalues)"),
}


def loss_factors(scene, spec) -> LossFactors | None:
    """The parts' loss-factor tables (materials.<part>.eta_table) at the conditions' temperatures, the band
    whose modes a table in frequency follows (fixed point per mode), or None without a table."""
    if spec is not None:
        tables = {p: m.eta_table for p, m in spec.materials.items() if getattr(m, "eta_table", None) is not None}
    else:       # while the scene is validated (its spec is built after the cross-checks)
        tables = {p: loss_table(m["eta_table"], f"materials.{p}.eta_table")
                  for p, m in scene.get("materials", {}).items() if m.get("eta_table") is not None}
    return LossFactors(tables, band_and_growth_tol(scene)[0]) if tables else None


def check_loss_factors(scene, spec, cond: Conditions) -> None:
    """Named errors before any computation: a condition's temperature outside a part's η(f, T) table, the
    band outside a table that varies with f."""
    loss = loss_factors(scene, spec)
    if loss is None:
        return
    for part, table in loss.tables.items():
        try:
            table.check_range(temperature=cond.temperature)
            if table.varies_with_frequency:
                table.check_range(frequency=np.asarray(loss.band_hz))
        except ModelError as e:
            why = str(e).split(": ", 1)[-1]
            raise SceneError(f"materials.{part}.eta_table: {why} (conditions of {_KEY} / its band_hz)") from None


def conditions(scene) -> Conditions:
    """The conditions of the section (factorial design or table); speed [] = operating.speed."""
    a = scene.analyses[NAME]
    try:
        if a["design"] == "table":
            if not a["conditions"]:
                raise SceneError(f"{_KEY}.conditions: design = 'table' needs at least one condition")
            rows = [dict(r) for r in a["conditions"]]
            for i, r in enumerate(rows):
                if not isinstance(r, dict):
                    raise SceneError(f"{_KEY}.conditions[{i}]: must be a table {{{', '.join(VARIABLES)}}}")
                r.setdefault("pressure", pressure_continuation.SCENE_PRESSURE)
                r.setdefault("speed", scene.operating.speed)
            return from_table(rows)
        speed = values(a["speed"], f"{_KEY}.speed") if a["speed"] else [float(scene.operating.speed)]
        for d in a["direction"]:
            if d not in DIRECTIONS:
                raise SceneError(f"{_KEY}.direction: must be a list of {list(DIRECTIONS)} (got {d!r})")
        if not a["direction"]:
            raise SceneError(f"{_KEY}.direction: must not be empty")
        return factorial(values(a["pressure"], f"{_KEY}.pressure"),
                         values(a["temperature"], f"{_KEY}.temperature"), speed, a["direction"])
    except ModelError as e:
        raise SceneError(f"{_KEY}.{e}") from None


def _law(spec, key: str) -> InterfaceLaw:
    """One friction law of the section (SceneError naming the key)."""
    if not isinstance(spec, dict):
        raise SceneError(f"{key}: must be a table {{law = ..., ...}}")
    kind = spec.get("law", "table")
    allowed = {"constant": {"law", "mu"}, "stribeck": {"law", "mu_s", "mu_d", "v_s", "v_d", "radius"},
               "table": {"law", "temperature", "speed", "mu", "pressure"}}
    if not isinstance(kind, str) or kind not in allowed:     # a list or a table is no law's name
        raise SceneError(f"{key}.law: must be one of {list(allowed)} (got {kind!r})")
    unknown = sorted(set(spec) - allowed[kind])
    if unknown:
        raise SceneError(f"{key}.{unknown[0]}: unknown key for law = {kind!r}; allowed: {sorted(allowed[kind])}")
    missing = sorted(allowed[kind] - set(spec) - {"law", "pressure"})
    if missing:
        raise SceneError(f"{key}.{missing[0]}: required for law = {kind!r}")
    try:
        if kind == "constant":
            return InterfaceLaw(ConstantFriction(float(spec["mu"])))
        if kind == "stribeck":
            law = StribeckFriction(*(float(spec[k]) for k in ("mu_s", "mu_d", "v_s", "v_d")))
            if not float(spec["radius"]) > 0:
                raise SceneError(f"{key}.radius: must be > 0 (got {spec['radius']})")
            return InterfaceLaw(law, float(spec["radius"]))
        return InterfaceLaw(TableFriction(spec["temperature"], spec["speed"], spec["mu"], name=key,
                                          pressure=spec.get("pressure")))
    except (TypeError, ValueError) as e:
        msg = str(e)
        if isinstance(e, ModelError) and msg.startswith(key):
            raise SceneError(msg) from None
        raise SceneError(f"{key}: {msg}") from None


def friction_laws(scene) -> tuple[InterfaceLaw | None, dict[str, InterfaceLaw]]:
    """(the default law or None, the laws by interface name) of the section."""
    spec = scene.analyses[NAME]["friction"]
    default = _law(spec["default"], f"{_KEY}.friction.default") if "default" in spec else None
    sliding = sorted(n for n, u in scene.interfaces.items() if u.get("sliding", 0) and u.get("mu", 0))
    laws = {}
    for name, s in spec.items():
        if name == "default":
            continue
        t = scene.interfaces.get(name)
        if name not in sliding or t["type"] not in ("contact", "rigid_plate"):
            raise SceneError(f"{_KEY}.friction.{name}: not a sliding interface with friction; those: {sliding}")
        laws[name] = _law(s, f"{_KEY}.friction.{name}")
    return default, laws


def friction_values(scene, cond: Conditions) -> dict[str, np.ndarray]:
    """|μ| of every law at every condition (the range checks: a named error before any computation)."""
    default, laws = friction_laws(scene)
    out = {}
    try:
        for name, law in {**({"default": default} if default is not None else {}), **laws}.items():
            out[name] = law.mu(cond.temperature, cond.speed, cond.pressure)
    except ModelError as e:
        raise SceneError(f"{_KEY}.friction: {e}" if not str(e).startswith(_KEY) else str(e)) from None
    return dict(sorted(out.items()))


def check(scene, volumes) -> None:
    """The conditions, the friction laws and their ranges, the pressure (only the scene's) and the speed
    (other speeds need Ω as a parameter of the reduced model, unless nothing but μ depends on it)."""
    cond = conditions(scene)
    friction_values(scene, cond)
    check_loss_factors(scene, scene.spec, cond)
    other = sorted(set(cond.pressure.tolist()) - {1.0})
    why = pressure_dependent_terms(scene)
    if other and why:
        raise SceneError(f"{_KEY}.pressure: other pressures than the scene's (1) need a reduced model whose "
                         f"operators do not depend on the pressure, but {why}; run one scene per pressure "
                         f"(got {other})")
    speeds = set(cond.speed.tolist()) - {float(scene.operating.speed)}
    why = speed_not_a_parameter(scene)
    terms = scene.operating.gyroscopic or any(t.get("friction_damping") for t in scene.interfaces.values())
    if speeds and why and terms:
        raise SceneError(f"{_KEY}.speed: other speeds than operating.speed need the speed as a parameter of the "
                         f"reduced model: {why}")
    spec = scene.analyses[NAME]["friction"]
    own = [n for n, t in scene.interfaces.items() if t.get("friction", "constant") != "constant"
           and "default" not in spec and n not in spec]
    if speeds and own:
        law = scene.interfaces[own[0]]["friction"]
        raise SceneError(f"{_KEY}.friction: interfaces.{own[0]} has a μ(V) law ({law!r}) that the reduced model "
                         f"holds at operating.speed only; give its law at the conditions "
                         f"({_KEY}.friction.{own[0]} or .default)")
    if terms and np.any(cond.speed <= 0):
        raise SceneError(f"{_KEY}.speed: must be > 0 with gyroscopic or friction-damping terms")


def pressure_dependent_terms(scene) -> str:
    """Why the linearised operators of the scene depend on the brake pressure in a way the reduced model
    cannot follow ('' if they do not).  With the linear penalty and a fixed contact set the stiffness
    (elastic, contact k_n, friction μ k_n), mass, damping and gyroscopic operators are those of the scene's
    pressure: only μ(p, T, Ω), the stress stiffening K_σ(u(p)) and a contact's friction damping C_d(p(p))
    change, the latter two affine in p (the model's ``pressure`` parameter).  A rigid plate's friction
    damping (its pressure k_n max(u·n, 0) from the displacement) is held at the scene's pressure only."""
    if scene.preload["mode"] != "nonlinear":
        return "preload.mode is 'all_closed' (the contact state at each pressure needs the nonlinear preload)"
    damped = sorted(n for n, t in scene.interfaces.items()
                    if t.get("friction_damping") and t.get("type") != "contact")
    if damped:
        return (f"interfaces.{damped[0]}.friction_damping = true on a {scene.interfaces[damped[0]]['type']} (its "
                f"friction damping grows with the pressure k_n max(u·n, 0), which the reduced model does not "
                f"follow; a contact interface's it does)")
    return ""


def pressure_states(ctx, cond: Conditions) -> dict | None:
    """The preload's continuation to the conditions' other pressures (None: only the scene's pressure).
    A pressure whose contact set is not the scene's is evaluated with its own contact state (the reduced
    model's ``contact_states``)."""
    if not set(cond.pressure.tolist()) - {1.0}:
        return None
    return pressure_continuation.summary(ctx)


def _full_cea(par, point: dict, reverse: bool, band, nev: int, options) -> tuple[np.ndarray, float]:
    """The full CEA's eigenvalues at ``point`` (:func:`~fem_squeal.app.analyses.reduced.full_cea`),
    with the gyroscopic term turned for the reverse direction (C(−Ω) = C(|Ω|) − 2|Ω|G)."""
    G = par.operating.G if par.operating is not None else None
    if not reverse or G is None:
        return full_cea(par, point, band, nev, options)
    from fem_squeal.fe.assembly import combination  # heavy: FE stack
    from fem_squeal.fe.eigen import solve_complex_modes  # heavy: FE stack

    Ki = par.loss_stiffness(point)
    if Ki is not None:
        Ki.destroy()
        raise ModelError("verify: the reverse direction with a gyroscopic term and a loss factor is not checked "
                         "(the full problem of twice the size has no turned gyroscopic term here)")
    t = time.perf_counter()
    Kt, Ct = par.terms(point)
    Ct = [(A, -c if A is G else c) for A, c in Ct]
    K, C = combination(Kt), combination(Ct)
    cm = solve_complex_modes(K, par.ops.M, C, nev, band_centre_hz(band), band_hz=tuple(band), options=options,
                             prefix="verify_", progress=True)
    lam = cm.eigenvalues
    for A in (K, C, *cm.vectors_re, *cm.vectors_im):
        A.destroy()
    return lam, time.perf_counter() - t


def _nep_corner(par, point: dict, laws: dict, reverse: bool, lam_r: np.ndarray, gt: float, options
                ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The full nonlinear eigenproblem (:func:`fem_squeal.fe.projection.loss_nep.full_loss_nep`, η_p(f) of
    ``laws`` at each answer's own frequency) from each watched reduced eigenvalue alone (inverse iteration
    at it: no reduced vector enters the check): the unstable ones and the :data:`NEP_LEAST_STABLE` least
    stable (largest Re λ/|λ|), so that a mode the reduced model holds barely stable is solved too.
    Returns (the watched reduced eigenvalues, the full ones, the worst backward error, seconds)."""
    from fem_squeal.fe.projection.loss_nep import full_loss_nep  # heavy: FE stack

    t = time.perf_counter()
    order = np.argsort(-(lam_r.real / np.abs(lam_r)))
    watched = sorted(set(np.flatnonzero(unstable(lam_r, gt)).tolist()) | set(order[:NEP_LEAST_STABLE].tolist()))
    full, worst = np.empty(len(watched), complex), 0.0
    for i, j in enumerate(watched):
        r = full_loss_nep(par, point, laws, complex(lam_r[j]), tol=NEP_TOL, options=options,
                          prefix="verify_nep_", reverse=reverse)
        if not r.converged:
            raise EigenSolveError(f"{_KEY}.verify: the full nonlinear eigenproblem from the reduced eigenvalue "
                                  f"{lam_r[j]:.6g} did not converge in {r.iterations} iterations (|Δλ|/|λ| "
                                  f"{r.history[-1]:.1e})")
        full[i], worst = r.eigenvalue, max(worst, r.backward_error)
    return lam_r[watched], full, worst, time.perf_counter() - t


def checked_conditions(cond: Conditions, changed: dict[float, int]) -> list[tuple[int, bool]]:
    """(condition, between the corners) of the checks: the corners, and where the contact set changes
    with the pressure (``changed``: pressure scale -> points that opened or closed), one condition at the
    pressure inside the matrix whose set changed most, at the first corner's temperature, speed and
    direction where the matrix has it (its state enters the basis only through its contact rows and the
    static derivatives of the modes, as the corners' do)."""
    corners = cond.corners()
    out = [(k, False) for k in corners]
    inner = {s: n for s, n in changed.items() if n and s not in (cond.pressure.min(), cond.pressure.max())}
    if inner:
        s = max(sorted(inner), key=lambda x: inner[x])
        first = corners[0]
        at = np.flatnonzero(cond.pressure == s)
        like = [k for k in at if all(getattr(cond, v)[k] == getattr(cond, v)[first]
                                     for v in ("temperature", "speed", "direction"))]
        out.append((int((like or at)[0]), True))
    return out


def verify_corners(ctx: Context, model, res, points: dict, band, gt: float, loss: LossFactors | None = None
                   ) -> list[dict]:
    """Full CEAs at the conditions of :func:`checked_conditions` (the corners, and a pressure between
    them where the contact set changes) against the reduced eigenvalues (as analyses.reduced.verify:
    worst relative error of the unstable full eigenvalues, of all in the band when none is unstable).
    With loss-factor tables that vary with f (``loss``): the full nonlinear eigenproblem from the watched
    reduced eigenvalues (:func:`_nep_corner`), each full answer against the reduced one it started from.
    A corner at a pressure whose contact set is not the scene's is solved on the full operators about its
    own continued state (:func:`~fem_squeal.app.analyses.reduced.state_operators`)."""
    from fem_squeal.fe.projection import relative_change  # heavy: FE stack

    cond = res.conditions
    parts = sorted(model.K_parts)
    scene_par = parametric_operators(ctx, model.mu0, parts)
    changed = pressure_continuation.changed_states(ctx)
    at_state: dict[float, tuple] = {}         # pressure scale -> (operators about its state, their K, K_f)
    varying = loss.in_frequency() if loss is not None else {}
    options = ctx.scene.solver.petsc_options
    rows = []
    try:
        counts = {r["scale"]: r["changed_points"] for r in pressure_continuation.summary(ctx)["pressures"]} \
            if changed else {}
        for k, between in checked_conditions(cond, counts):
            point = {n: float(v[k]) for n, v in points.items()}
            what = "condition between the corners" if between else "corner"
            s = float(cond.pressure[k])
            par = scene_par
            if s in changed:
                if s not in at_state:
                    at_state[s] = state_operators(ctx, model.mu0, parts, changed[s])
                par = at_state[s][0]
                if par.pressure is None:      # those operators are the pressure's: no other pressure term
                    point.pop(PRESSURE, None)
            lam_r, n_ask = band_eigenvalues(res.eigenvalues[k], band)
            if varying:
                laws = {p: t.at_temperature(float(cond.temperature[k])) for p, t in varying.items()}
                red, full, backward, seconds = _nep_corner(par, point, laws, cond.direction[k] < 0, lam_r, gt,
                                                           options)
                rows.append({"condition": k, **cond.row(k), "point": point, "method": "full NEP",
                             "between_corners": between,
                             "n_full": int(full.size), "n_unstable_full": int(unstable(full, gt).sum()),
                             "n_unstable_reduced": int(unstable(red, gt).sum()),
                             "max_rel_error": float(np.max(np.abs(full - red) / np.abs(full), initial=0.0)),
                             "backward_error": backward, "full_cea_s": seconds,
                             "modes": [{"reduced": [float(a.real), float(a.imag)],
                                        "full": [float(b.real), float(b.imag)]} for a, b in zip(red, full)]})
                ctx.say(f"[fem_squeal] operating matrix {what} {k}: reduced vs full NEP "
                        f"{rows[-1]['max_rel_error']:.1e} ({full.size} modes), unstable "
                        f"{rows[-1]['n_unstable_reduced']}/{rows[-1]['n_unstable_full']}")
                continue
            full, seconds = _full_cea(par, point, cond.direction[k] < 0, band, n_ask, options)
            full = full[in_band(full, band)]
            bad = unstable(full, gt)
            watched = full[bad] if bad.any() else full
            rows.append({"condition": k, **cond.row(k), "point": point, "method": "full CEA",
                         "between_corners": between,
                         "n_full": int(full.size), "n_unstable_full": int(bad.sum()),
                         "n_unstable_reduced": int(unstable(lam_r, gt).sum()),
                         "max_rel_error": relative_change(watched, lam_r), "full_cea_s": seconds,
                         "unstable_full": [[float(x.real), float(x.imag)] for x in full[bad]]})
            ctx.say(f"[fem_squeal] operating matrix {what} {k}: reduced vs full {rows[-1]['max_rel_error']:.1e}, "
                    f"unstable {rows[-1]['n_unstable_reduced']}/{rows[-1]['n_unstable_full']}")
    finally:
        scene_par.destroy()
        for made in at_state.values():
            destroy_state_operators(*made)
    return rows


def _write_tables(work: Path, res, mus: dict, noise: dict) -> None:
    cond = res.conditions
    head = ["condition", *VARIABLES, *(f"mu_{n}" for n in mus), "n_unstable", "max_growth_rate"]
    cols = [np.arange(cond.size), cond.pressure, cond.temperature, cond.speed,
            np.where(cond.direction > 0, "forward", "reverse"), *mus.values(), np.array(noise["n_unstable"]),
            np.array([np.nan if g is None else g for g in noise["max_growth_rate"]])]
    write_csv_atomic(work / "operating_matrix_conditions.csv", head, cols)
    m = noise["modes"]
    write_csv_atomic(work / "operating_matrix_modes.csv",
                     ["condition", "frequency_hz", "growth_rate", "damping_ratio", "coupling"],
                     [*(np.array([r[k] for r in m], float) for k in ("condition", "frequency_hz", "growth_rate",
                                                                      "damping_ratio")),
                      np.array([r["coupling"]["label"] if "coupling" in r else "" for r in m], dtype=object)])
    b = noise["third_octave"]
    write_csv_atomic(work / "operating_matrix_bands.csv",
                     ["band_hz", "lower_hz", "upper_hz", "conditions", "occurrence", "in_model_band"],
                     [np.array([r[k] for r in b], float) for k in ("band_hz", "lower_hz", "upper_hz", "conditions",
                                                                    "occurrence", "in_model_band")])


_PRESSURE_MODEL = ("the contact set at every pressure is the scene's (checked by the preload continuation) and "
                   "the penalty is linear, so the linearised operators are the scene's: the pressure acts "
                   "through μ(p, T, Ω) only; the preload state scales with p, but no operator of this scene "
                   "depends on it (no stress stiffening, no friction damping)")
_PRESSURE_TERMS = (
    "the contact set at every pressure is the scene's (checked by the preload continuation) and the penalty is "
    "linear, so the preload u(p) and the contact pressures are affine in p and so are {terms}, the reduced "
    "model's parameter 'pressure' (the slopes from the continued state farthest from p = 1); the pressure acts "
    "through {them} and μ(p, T, Ω), the other operators are the scene's; the corner checks assemble {them} "
    "from each pressure's own continued state")


_PRESSURE_CONTACTS = (
    "the contact set changes with the pressure: each pressure's contact stiffness, friction and tangential "
    "matrices are those of its own closed points (from its continued preload), formed on the basis from the "
    "interfaces' rows (contact_states: {changed} points differ from the scene's at most); with the linear "
    "penalty the other operators are the scene's{terms}, so the pressure acts through the contact "
    "state{and_terms} and μ(p, T, Ω); the basis holds the modes about each state (solved where more than "
    "10 % of the closed points changed, else as their static derivatives to second order in the contact "
    "change: results.json reduced.contact_states); the checks, at the corners and at the pressure between "
    "them whose set changed most, solve the full operators linearised about each pressure's own state")


def pressure_model(model) -> str:
    """How the reduced model follows the brake pressure (results.json ``pressure.model``)."""
    if model.contact_states:
        changed = max(sum(int(np.sum(a != model.contacts[n].active)) for n, a in st.items())
                      for st in model.contact_states.values())
        terms = [t for t, key in (("the stress stiffening K_σ(u(p))", "Ks"),
                                  ("the friction damping C_d(p(p))", "Cd"))
                 if any(key in tab for tab in model.pressure_tables.values())]
        said = " and ".join(terms)
        return _PRESSURE_CONTACTS.format(
            changed=changed, terms=f" but {said}, projected from each pressure's own state" if terms else "",
            and_terms=f", {said}" if terms else "")
    if PRESSURE not in model.parameters:
        return _PRESSURE_MODEL
    terms = [t for t, on in (("the stress stiffening K_σ(u(p)) = K_σ(u(1)) + (p − 1) K_σ(du/ds)",
                              model.Ksp is not None),
                             ("the friction damping C_d(p) = C_d(1) + (p − 1) C_d(dp/ds)", model.Cdp is not None))
             if on]
    return _PRESSURE_TERMS.format(terms=" and ".join(terms), them="it" if len(terms) == 1 else "them")


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.operating_matrix: every condition on the reduced model, the noise matrix, its tables and
    plot, and the corner checks against full CEAs when asked."""
    scene, model = ctx.scene, ctx.reduced_model()
    a = scene.analyses[NAME]
    band, gt = band_and_growth_tol(scene)
    cond = conditions(scene)
    mus = friction_values(scene, cond)
    default, laws = friction_laws(scene)
    try:
        points = parameter_points(model, cond, laws, default)
    except ModelError as e:
        raise SceneError(f"{_KEY}.{e}") from None
    states = pressure_states(ctx, cond)
    loss = loss_factors(scene, ctx.spec)
    if loss is not None:      # η(T) of the tables that do not vary with f: parameters (the corner checks too)
        points = {**points, **loss.constant_in_frequency(cond.temperature)}
    res = evaluate(model, cond, points, ctx.comm, loss=loss)
    timings[NAME] = res.seconds
    noise = noise_matrix(res, band, gt)
    t = time.perf_counter()
    mode_couplings(model, res, points, noise["modes"], loss, ctx.comm)
    timings[f"{NAME}_coupling"] = time.perf_counter() - t
    out: dict[str, Any] = {"conditions": [cond.row(k) for k in range(cond.size)], "band_hz": list(band),
                           "seconds": res.seconds, "seconds_per_condition": res.seconds * res.ranks / cond.size,
                           "mu": {n: v.tolist() for n, v in mus.items()}, **noise,
                           "squeal_index": "not available: the reduced model carries no radiation (ERP); "
                                           "the CEA's nvh section ranks the nominal point's modes"}
    if states is not None:
        out["pressure"] = {"continuation": states, "model": pressure_model(model)}
    ctx.say(f"[fem_squeal] operating matrix: {cond.size} conditions in {res.seconds:.2f} s, "
            f"{noise['unstable_conditions']} with instability")
    if res.fixed_point is not None:
        out["loss_factor_fixed_point"] = res.fixed_point
        bad = sum(r["modes"] - r["converged"] for r in res.fixed_point)
        most = max(r["max_iterations_used"] for r in res.fixed_point)
        ctx.say(f"[fem_squeal] operating matrix: η(f) fixed point, at most {most} iterations, {bad} mode(s) "
                "not converged")
    if a["verify"]:
        t = time.perf_counter()
        out["verification"] = verify_corners(ctx, model, res, points, band, gt, loss)
        timings[f"{NAME}_verify"] = time.perf_counter() - t
    if ctx.comm.rank == 0:
        _write_tables(work, res, mus, noise)
        m = noise["modes"]
        plots.noise_matrix(work / "operating_matrix.png", noise, np.array([r["frequency_hz"] for r in m]),
                           np.array([r["growth_rate"] for r in m]), np.array([r["condition"] for r in m]),
                           scene.title)
    return {NAME: out}


def verification_failures(res: dict, tol: float) -> list[str]:
    """Corner conditions where the reduced model misses the full CEA (relative error above ``tol`` or a
    different number of unstable modes)."""
    return mismatches(res.get("verification", []), tol, "operating matrix: ",
                      where=lambda r: f"condition {r['condition']} (" + _at_pressure(r)
                                      + f"{r['temperature']:g} °C, {r['speed']:g} rad/s, {r['direction']})")


def _at_pressure(row: dict) -> str:
    """'2 × loads.pressure, ' for a condition at another pressure than the scene's ('' at the scene's)."""
    p = row.get("pressure", pressure_continuation.SCENE_PRESSURE)
    return "" if p == pressure_continuation.SCENE_PRESSURE else f"{p:g} × loads.pressure, "


def report(res: dict) -> str:
    """The report section (HTML): the summary, the 1/3-octave occurrence, the occurrence per variable,
    the unstable modes per condition and the corner checks."""
    if NAME not in res:
        return ""
    r = res[NAME]
    txt = (f"<h2>Operating matrix</h2><p>{r['n_conditions']} conditions on the reduced model in "
           f"{_num(r['seconds'])} s; {r['unstable_conditions']} ({100 * r['occurrence']:.0f} %) with an unstable "
           f"mode in {_num(r['band_hz'][0])}–{_num(r['band_hz'][1])} Hz. "
           f"Squeal index: {_e(r['squeal_index'])}.</p>"
           '<p><img src="operating_matrix.png" alt="noise matrix" style="max-width:100%"></p>')
    txt += "<h3>Occurrence per 1/3-octave band</h3>" + _table(
        ["band [Hz]", "conditions", "occurrence [%]", "inside the model's band"],
        [[b["band_hz"], b["conditions"], 100 * b["occurrence"], b["in_model_band"]] for b in r["third_octave"]])
    rows = [[v, f"{x['value']} {UNITS[v]}".strip() if not isinstance(x["value"], str) else x["value"],
             x["conditions"], x["unstable"], 100 * x["occurrence"]]
            for v, xs in r["by_variable"].items() for x in xs]
    txt += "<h3>Occurrence per condition variable</h3>" + _table(
        ["variable", "value", "conditions", "with instability", "occurrence [%]"], rows)
    modes: dict[int, list] = {}
    for m in r["modes"]:
        modes.setdefault(m["condition"], []).append(m)
    crow = []
    for k, c in enumerate(r["conditions"]):
        ms = modes.get(k, [])
        crow.append([k, c["pressure"], c["temperature"], c["speed"], c["direction"], len(ms),
                     ", ".join(f"{m['frequency_hz']:.0f} Hz ({m['growth_rate']:.3g}/s"
                               + (f"; {m['coupling']['label']}" if "coupling" in m else "") + ")"
                               for m in ms) or "—"])
    txt += "<h3>Unstable modes per condition</h3>" + _table(
        ["condition", "p [× loads.pressure]", "T [°C]", "|Ω| [rad/s]", "direction", "unstable",
         "f (growth rate Re λ; the real modes of the basis that couple)"], crow)
    if r.get("pressure"):
        txt += ("<h3>Pressures</h3><p>" + _e(r["pressure"]["model"]) + ".</p>" + _table(
            ["p [× loads.pressure]", "Newton iterations", "factorisations", "seconds", "closed points",
             "‖u(p) − p u(1)‖/‖p u(1)‖"],
            [[x["scale"], x["iterations"], x["factorisations"], x["seconds"], x["closed_points"],
              x["nonlinearity"]] for x in r["pressure"]["continuation"]["pressures"]]))
    if r.get("verification"):
        txt += "<h3>Reduced vs full model at the corners</h3>" + _table(
            ["condition", "p [× loads.pressure]", "T [°C]", "|Ω| [rad/s]", "direction", "full model",
             "max rel. error", "unstable full", "unstable reduced"],
            [[v["condition"], v["pressure"], v["temperature"], v["speed"], v["direction"],
              v.get("method", "full CEA") + (" (a pressure between the corners)"
                                             if v.get("between_corners") else ""),
              v["max_rel_error"], v["n_unstable_full"], v["n_unstable_reduced"]]
             for v in r["verification"]])
    return txt


@dataclass(frozen=True)
class _OperatingMatrixStage(Stage):
    """The stage needs the preload's in-memory operators only for its corner checks (``verify``)."""

    def needs_of(self, scene) -> tuple[str, ...]:
        needs = super().needs_of(scene)
        return needs if scene.analyses[self.name]["verify"] else tuple(n for n in needs if n != "preload")


STAGE = _OperatingMatrixStage(NAME, ("reduced", "preload"), run, "operating matrix (pressure, temperature, speed, "
                              "direction) on the reduced model: the noise matrix", section=SECTION, check=check,
                              report=report)
