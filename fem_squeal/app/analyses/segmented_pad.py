"""The ``segmented_pad`` analysis: the lumped sintered pad of seed 004, no mesh.  Phase portraits and
regimes (stick-slip, creep, periodic, steady) against disc speed and against (v_s, v_d); the runs
are dealt over the ranks.  Files: segmented_pad.json, segmented_pad_speeds.png,
segmented_pad_velocities.png."""
from __future__ import annotations

import dataclasses
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.fields import REAL, Field, dataclass_fields, increasing, positive
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.segmented_pad import SegmentedPad, simulate
from fem_squeal.util.atomic import write_json_atomic
from fem_squeal.util.errors import SceneError

SECTION = {
    "speeds": Field(list, [0.005, 0.03, 0.1, 0.3], increasing(1, 0.0), "disc speeds at the mean radius [m/s]"),
    "velocity_pairs": Field(list, [], None, "[[v_s, v_d], ...] [m/s], each run at every pair_speeds"),
    "pair_speeds": Field(list, [0.05], increasing(1, 0.0), "disc speeds of the (v_s, v_d) study [m/s]"),
    "t_end": Field(REAL, 0.3, positive, "simulated time per run [s]"),
    "dt": Field(REAL, 4e-5, positive, "time step [s]"),
    "alpha": Field(REAL, -0.3, lambda v: None if -1 / 3 <= v <= 0 else f"must be in [-1/3, 0] (got {v})",
                   "HHT α (damps the stiff sub-v_s branch of the law)"),
    # + every field of fem_squeal.reduced.segmented_pad.SegmentedPad (added below)
}
SECTION.update(dataclass_fields(SegmentedPad))


def pad_parameters(a: dict):

    names = {f.name for f in dataclasses.fields(SegmentedPad)}
    return SegmentedPad(**{k: v for k, v in a.items() if k in names})


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """Seed 004's segmented pad: regimes and phase portraits against disc speed and (v_s, v_d).
    The runs are dealt over the ranks; every rank gets all results."""


    a = ctx.scene.analyses["segmented_pad"]
    comm = ctx.comm
    pad = pad_parameters(a)
    cases = [("speed", pad, v) for v in a.speeds]
    cases += [("velocities", replace(pad, v_s=vs, v_d=vd), v) for vs, vd in a.velocity_pairs
              for v in a.pair_speeds]
    t0 = time.perf_counter()
    mine = {}
    for n, (kind, p, speed) in enumerate(cases):
        if n % comm.size == comm.rank:
            r = simulate(p, speed, t_end=a.t_end, dt=a.dt, alpha=a.alpha)
            late = r.t >= 0.5 * r.t[-1]
            centre = p.n_elements // 2
            mine[n] = {"kind": kind, "speed": speed, "v_s": p.v_s, "v_d": p.v_d, "regimes": r.regime,
                       "fractions": r.fractions, "steps": r.stats["steps"],
                       "s_min": np.linalg.norm(r.w[late], axis=-1).min(axis=0),
                       "portrait": {"x": r.q[late, 3 * centre + 1], "v": r.v[late, 3 * centre + 1],
                                    "w": np.linalg.norm(r.w[late, centre], axis=-1), "t": r.t[late]}}
    runs: dict[int, dict] = {}
    for d in comm.allgather(mine):
        runs.update(d)
    rows = [runs[n] for n in range(len(cases))]
    timings["segmented_pad"] = time.perf_counter() - t0
    summary = [{k: r[k] for k in ("kind", "speed", "v_s", "v_d", "regimes", "fractions", "s_min", "steps")} |
               {"regime": _majority(r["regimes"])} for r in rows]
    if comm.rank == 0:
        write_json_atomic(work / "segmented_pad.json", {"runs": summary})
        for kind in ("speed", "velocities"):
            sel = [r for r in rows if r["kind"] == kind]
            if sel:
                plots.pad_portraits(work / f"segmented_pad_{'speeds' if kind == 'speed' else 'velocities'}.png",
                                    sel, pad, "against disc speed" if kind == "speed" else "against (v_s, v_d)")
    ctx.say("[fem_squeal] segmented pad: " + ", ".join(
        f"{r['speed'] * 1e3:g} mm/s (v_s {r['v_s'] * 1e3:g}, v_d {r['v_d'] * 1e3:g} mm/s): {r['regime']}"
        for r in summary) + f"; {timings['segmented_pad']:.1f} s")
    return {"segmented_pad": {"runs": summary, "seconds": timings["segmented_pad"]}}


def _majority(regimes: list[str]) -> str:
    """The regime of most elements ("mixed: a/b" when no regime holds a majority)."""
    names, counts = np.unique(regimes, return_counts=True)
    order = np.argsort(-counts)
    if counts[order[0]] * 2 > len(regimes):
        return str(names[order[0]])
    return "mixed: " + "/".join(str(names[o]) for o in order)


def check(scene: dict, volumes) -> None:
    """(v_s, v_d) pairs with 0 < v_s < v_d, their speeds, dt < t_end, and a valid pad."""
    a = scene.analyses["segmented_pad"]
    for i, pair in enumerate(a.velocity_pairs):
        key = f"analyses.segmented_pad.velocity_pairs[{i}]"
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(v, (int, float))
                                                                  and not isinstance(v, bool) for v in pair)):
            raise SceneError(f"{key}: must be [v_s, v_d] in m/s (got {pair!r})")
        if not 0 < pair[0] < pair[1]:
            raise SceneError(f"{key}: must satisfy 0 < v_s < v_d (got {pair})")
    if a.velocity_pairs and not a.pair_speeds:
        raise SceneError("analyses.segmented_pad.pair_speeds: required with velocity_pairs")
    if a.dt >= a.t_end:
        raise SceneError(f"analyses.segmented_pad.dt: must be < t_end = {a['t_end']} (got {a['dt']})")
    try:
        pad_parameters(a)
    except ValueError as e:
        raise SceneError(f"analyses.{e}") from None


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "segmented_pad" not in res:
        return ""
    rows = [[r["speed"] * 1e3, r["v_s"] * 1e3, r["v_d"] * 1e3, r["regime"], r["steps"]]
            for r in res["segmented_pad"]["runs"]]
    return ("<h2>Segmented pad</h2>" + _table(["V [mm/s]", "v_s [mm/s]", "v_d [mm/s]", "regime", "steps"],
                                                 rows))


STAGE = Stage("segmented_pad", (), run, "lumped segmented pad (seed 004)", section=SECTION, check=check,
              report=report, lumped=True)
