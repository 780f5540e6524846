"""The preload at the operating matrix's other brake pressures (issue 39): the pressure continuation run
by the ``preload`` stage after the scene's own preload, and what the operating matrix reads of it.

The pressure scales are those of ``analyses.operating_matrix`` other than 1 (the scene's loads.pressure).
The scene's preload is solved first (keeping its factorisation), then each other scale is continued from
the nearest solved one (:mod:`fem_squeal.fe.preload_continuation`), the states cached by content under
the run's cache (``<cache>/preload_states``).  Per scale the summary gives the Newton work, the normal
forces, the closed points and whether the contact set is the scene's (``same_contact_set``), and how far
the state is from the scene's scaled, ‖u(s) − s u(1)‖/‖s u(1)‖ (``nonlinearity``).

The states themselves stay in memory for the run (``pressure_states``): with the stress stiffening
(preload.geometric_stiffness) or the friction damping of a contact the pressure is a parameter of the
reduced model, K_σ(u(s)) = K_σ(u(1)) + (s − 1) K_σ(du/ds) and C_d(p(s)) = C_d(p(1)) + (s − 1) C_d(dp/ds)
(:func:`pressure_terms`, :mod:`fem_squeal.fe.pressure_terms`), and the operating matrix's corner checks
assemble each pressure's operators from its own state."""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from mpi4py import MPI

from fem_squeal.app.analyses.condition_values import values
from fem_squeal.util.atomic import write_json_atomic

FILE = "pressure_continuation.json"
#: the scene's own pressure as a scale of loads.pressure (a table row without a pressure)
SCENE_PRESSURE = 1.0


def scales(scene) -> list[float]:
    """The pressure scales other than 1 that ``analyses.operating_matrix`` asks for ([] if none)."""
    a = scene.analyses.get("operating_matrix")
    if a is None:
        return []
    if a["design"] == "table":
        ps = [float(r.get("pressure", SCENE_PRESSURE)) for r in a["conditions"] if isinstance(r, dict)]
    else:
        ps = values(a["pressure"], "analyses.operating_matrix.pressure")
    return sorted(set(ps) - {SCENE_PRESSURE})


def friction_damped_contacts(scene) -> list[str]:
    """The contact interfaces with friction damping (∝ the contact pressure), sorted."""
    return sorted(n for n, t in scene.interfaces.items()
                  if t.get("type") == "contact" and t.get("friction_damping"))


def pressure_parameter(scene) -> bool:
    """The brake pressure is a parameter of the reduced model: the scene has a term that grows with it (the
    stress stiffening, preload.geometric_stiffness; the friction damping of a contact), a nonlinear preload
    (the contact state at each pressure) and other pressure scales than 1."""
    pl = scene.preload
    terms = bool(pl["geometric_stiffness"]) or bool(friction_damped_contacts(scene))
    return terms and pl["mode"] == "nonlinear" and bool(scales(scene))


def key_inputs(scene) -> Any:
    """The preload stage's cache-key inputs: ``scene.preload``, with the continuation's scales when there
    are any (so that a scene without them keeps its key)."""
    s = scales(scene)
    return scene.preload if not s else {**dict(scene.preload), "pressure_scales": s}


def run(ctx, ops, pre, factor, work: Path, settings: dict) -> dict[str, Any]:
    """Continue the converged preload ``pre`` (scale 1, solved with ``factor``) to the other scales; the
    summary (also written to ``work``/FILE for the operating matrix); the states are kept in
    ``ctx.products["pressure_states"]`` by scale (:func:`pressure_terms`)."""
    from fem_squeal.fe.preload import changed_points  # heavy: FE stack
    from fem_squeal.fe.preload_continuation import StateCache, continue_preload  # heavy: FE stack

    comm = ctx.comm
    t = time.perf_counter()
    cache = StateCache(ctx.cache.root / "preload_states", ctx.keys["operators"],
                       {k: settings[k] for k in ("friction", "tol")}, comm)
    states = continue_preload(ops, scales(ctx.scene), start=(1.0, pre.u), factor=factor, cache=cache,
                              progress=lambda line: ctx.say(f"[fem_squeal] {line}"), **settings)
    rows, kept = [], {}
    for st in states:
        r = st.result
        changed = changed_points(r, pre, comm)
        closed = comm.allreduce(int(sum(int(a.sum()) for a in r.active.values())), op=MPI.SUM)
        d = pre.u.copy()
        d.scale(st.scale)
        ref = d.norm()
        d.axpy(-1.0, r.u)
        rows.append({"scale": st.scale, "iterations": r.iterations, "factorisations": r.factorisations,
                     "update_columns": r.update_columns,
                     "krylov_iterations": r.krylov_iterations, "seconds": st.seconds, "cached": st.cached,
                     "normal_force": r.normal_force, "contact_area": r.contact_area, "closed_points": closed,
                     "changed_points": changed, "same_contact_set": changed == 0,
                     "nonlinearity": d.norm() / ref if ref > 0 else 0.0})
        d.destroy()
        kept[float(st.scale)] = r
    ctx.products["pressure_states"] = kept
    out = {"scales": [r["scale"] for r in rows], "seconds": time.perf_counter() - t, "pressures": rows}
    if comm.rank == 0:
        write_json_atomic(work / FILE, out)
    ctx.products["pressure_continuation"] = out
    ctx.say(f"[fem_squeal] preload at {len(rows)} other pressures by continuation in {out['seconds']:.2f} s; "
            f"contact set as the scene's at {sum(r['same_contact_set'] for r in rows)} of them")
    return out


def changed_states(ctx) -> dict:
    """The continued preload states whose contact set is not the scene's, by pressure scale ({} if none,
    also when the scene asks for no other pressure: then there is no continuation to read)."""
    if not ctx.products.get("pressure_states"):
        return {}
    same = {r["scale"]: r["same_contact_set"] for r in summary(ctx)["pressures"]}
    return {s: st for s, st in ctx.products["pressure_states"].items() if not same.get(s, True)}


def pressure_terms(ctx):
    """The operators across the pressures of this run (:class:`fem_squeal.fe.pressure_terms.PressureTerms`,
    a new one: its owner destroys it) from the scene's preload and the continued states: the stress stiffening
    (preload.geometric_stiffness) and the contacts' friction damping, or None when the pressure is not a
    parameter (:func:`pressure_parameter`).  Where a pressure's contact set is not the scene's the state is not
    affine in s: the reduced model then holds each pressure's own projected terms (``pressure_tables``)."""
    if not pressure_parameter(ctx.scene):
        return None
    from fem_squeal.fe.assembly import geometric_stiffness  # heavy: FE stack
    from fem_squeal.fe.preload import friction_damping  # heavy: FE stack
    from fem_squeal.fe.pressure_terms import REFERENCE, PressureTerms  # heavy: FE stack

    ops, mesh, spec = ctx.products["linear"], ctx.products["mesh"], ctx.spec
    states = {REFERENCE: ctx.products["preload"], **ctx.products["pressure_states"]}
    stiff = (lambda u: geometric_stiffness(ops, mesh, spec, u)) if ctx.scene.preload["geometric_stiffness"] \
        else None
    damp = (lambda p: friction_damping(ops, mesh, spec, None, p)) if friction_damped_contacts(ctx.scene) else None
    return PressureTerms(states, stiff, damp)


def summary(ctx) -> dict[str, Any]:
    """The continuation's summary: this run's, or the preload stage's cached file."""
    if "pressure_continuation" not in ctx.products:
        ctx.products["pressure_continuation"] = json.loads((ctx.entry("preload") / FILE).read_text())
    return ctx.products["pressure_continuation"]
