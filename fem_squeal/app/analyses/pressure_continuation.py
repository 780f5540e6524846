"""The preload at the operating matrix's other brake pressures (issue 39): the pressure continuation run
by the ``preload`` stage after the scene's own preload, and what the operating matrix reads of it.

The pressure scales are those of ``analyses.operating_matrix`` other than 1 (the scene's loads.pressure).
The scene's preload is solved first (keeping its factorisation), then each other scale is continued from
the nearest solved one (:mod:`fem_squeal.fe.preload_continuation`), the states cached by content under
the run's cache (``<cache>/preload_states``).  Per scale the summary gives the Newton work, the normal
forces, the closed points and whether the contact set is the scene's (``same_contact_set``), and how far
the state is from the scene's scaled, ‖u(s) − s u(1)‖/‖s u(1)‖ (``nonlinearity``).

The states themselves stay in memory for the run (``pressure_states``): with the stress stiffening
(preload.geometric_stiffness) the pressure is a parameter of the reduced model, K_σ(u(s)) = K_σ(u(1)) +
(s − 1) K_σ(du/ds) (:func:`stiffening`, :mod:`fem_squeal.fe.pressure_stiffening`), and the operating
matrix's corner checks assemble each pressure's K_σ from its own state."""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from fem_squeal.app.analyses.condition_values import values
from fem_squeal.util.atomic import write_json_atomic
from fem_squeal.util.errors import SceneError

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


def stress_stiffening(scene) -> bool:
    """The brake pressure is a parameter of the reduced model: the scene has the stress stiffening
    (preload.geometric_stiffness, which grows with the pressure), a nonlinear preload (the contact state
    at each pressure) and other pressure scales than 1."""
    pl = scene.preload
    return bool(pl["geometric_stiffness"]) and pl["mode"] == "nonlinear" and bool(scales(scene))


def key_inputs(scene) -> Any:
    """The preload stage's cache-key inputs: ``scene.preload``, with the continuation's scales when there
    are any (so that a scene without them keeps its key)."""
    s = scales(scene)
    return scene.preload if not s else {**dict(scene.preload), "pressure_scales": s}


def run(ctx, ops, pre, factor, work: Path, settings: dict) -> dict[str, Any]:
    """Continue the converged preload ``pre`` (scale 1, solved with ``factor``) to the other scales; the
    summary (also written to ``work``/FILE for the operating matrix); the states' vectors are kept in
    ``ctx.products["pressure_states"]`` by scale (:func:`stiffening`)."""
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
        changed = comm.allreduce(int(sum(int(np.sum(r.active[n] != pre.active[n])) for n in pre.active)),
                                 op=MPI.SUM)
        closed = comm.allreduce(int(sum(int(a.sum()) for a in r.active.values())), op=MPI.SUM)
        d = pre.u.copy()
        d.scale(st.scale)
        ref = d.norm()
        d.axpy(-1.0, r.u)
        rows.append({"scale": st.scale, "iterations": r.iterations, "factorisations": r.factorisations,
                     "update_columns": r.update_columns, "seconds": st.seconds, "cached": st.cached,
                     "normal_force": r.normal_force, "contact_area": r.contact_area, "closed_points": closed,
                     "changed_points": changed, "same_contact_set": changed == 0,
                     "nonlinearity": d.norm() / ref if ref > 0 else 0.0})
        d.destroy()
        kept[float(st.scale)] = r.u
    ctx.products["pressure_states"] = kept
    out = {"scales": [r["scale"] for r in rows], "seconds": time.perf_counter() - t, "pressures": rows}
    if comm.rank == 0:
        write_json_atomic(work / FILE, out)
    ctx.products["pressure_continuation"] = out
    ctx.say(f"[fem_squeal] preload at {len(rows)} other pressures by continuation in {out['seconds']:.2f} s; "
            f"contact set as the scene's at {sum(r['same_contact_set'] for r in rows)} of them")
    return out


def check_contact_sets(summ: dict, key: str = "analyses.operating_matrix") -> None:
    """A SceneError naming the first pressure of the continuation's summary ``summ`` where the contact set
    is not the scene's (the reduced model holds one contact state: a pressure that opens or closes contact
    points needs per-pressure contact operators, not implemented)."""
    for r in summ["pressures"]:
        if not r["same_contact_set"]:
            raise SceneError(f"{key}.pressure: at {r['scale']:g} × loads.pressure the contact set is not the "
                             f"scene's ({r['changed_points']} contact points opened or closed): the reduced "
                             f"model holds one contact state, and per-pressure contact operators in reduced "
                             f"coordinates are not implemented; keep pressures where the contact set holds")


def stiffening(ctx):
    """The stress stiffening across the pressures of this run (:class:`fem_squeal.fe.pressure_stiffening.
    PressureStiffening`, a new one: its owner destroys it) from the scene's preload and the continued
    states, or None when the pressure is not a parameter (:func:`stress_stiffening`).  A SceneError names
    a pressure whose contact set is not the scene's (there u(s) is not affine in s)."""
    if not stress_stiffening(ctx.scene):
        return None
    check_contact_sets(summary(ctx))
    from fem_squeal.fe.assembly import geometric_stiffness  # heavy: FE stack
    from fem_squeal.fe.pressure_stiffening import REFERENCE, PressureStiffening  # heavy: FE stack

    ops, mesh, spec = ctx.products["linear"], ctx.products["mesh"], ctx.spec
    states = {REFERENCE: ctx.products["preload"].u, **ctx.products["pressure_states"]}
    return PressureStiffening(states, lambda u: geometric_stiffness(ops, mesh, spec, u))


def summary(ctx) -> dict[str, Any]:
    """The continuation's summary: this run's, or the preload stage's cached file."""
    if "pressure_continuation" not in ctx.products:
        ctx.products["pressure_continuation"] = json.loads((ctx.entry("preload") / FILE).read_text())
    return ctx.products["pressure_continuation"]
