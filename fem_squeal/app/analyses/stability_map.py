"""The ``map`` analysis: the (sign(v)μ, E) full-factorial design of seed 001 §4 on the reduced model,
dealt over the ranks, with the number of unstable modes per frequency band (Figs. 17-19), and the map's
instabilities: each region where one mode is unstable, where it grows fastest and the real modes that
couple in it there (:func:`fem_squeal.reduced.stability_map.instabilities`).
Files: stability_map.npz, stability_map.png, stability_map_coupling.png (the instabilities' regions
labelled by their real-mode pair) and stability_map_instabilities.csv."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses import matrix_studies
from fem_squeal.app.analyses.map_instabilities import instabilities_html, map_instabilities, masks
from fem_squeal.app.analyses.reduced import (
    band_and_growth_tol,
    map_E_range,
    map_speed_range,
    speed_not_a_parameter,
)
from fem_squeal.app.fields import REAL, Field, at_least, increasing, nonempty_str, one_of, positive
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import num as _num
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.model import MU, SPEED, e_param
from fem_squeal.reduced.stability_map import equal_bands, stability_map
from fem_squeal.reduced.sweep import Grid, evaluate, signed_mu_axis
from fem_squeal.util.atomic import write_npz_atomic
from fem_squeal.util.errors import SceneError

SECTION = {
    "mu_max": Field(REAL, 1.0, positive, "sign(v)μ from -mu_max to mu_max"),
    "n_mu": Field(int, 101, at_least(2)),
    "part": Field(str, "disc", nonempty_str, "part whose Young's modulus is varied"),
    "E_range": Field(list, [], None, "[E_min, E_max] [Pa]; [] = nominal ± 20 %"),
    "n_E": Field(int, 21, at_least(2)),
    "second": Field(str, "E", one_of("E", "speed"), "the second axis: 'E' (part's Young's modulus) or 'speed' "
                    "(the disc speed Ω, with operating.gyroscopic or friction damping)"),
    "speed_range": Field(list, [], None, "[Ω_min, Ω_max] [rad/s]; [] = operating.speed × [0.5, 2]"),
    "n_speed": Field(int, 21, at_least(2)),
    "n_bands": Field(int, 6, positive, "equal frequency ranges of analyses.reduced.band_hz"),
}


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.map: unstable modes per band over the (sign(v)μ, E) design; stability_map.npz/png."""
    scene, model = ctx.scene, ctx.reduced_model()
    m = scene.analyses["map"]
    band, gt = band_and_growth_tol(scene)
    if m["second"] == SPEED:
        name, E = SPEED, np.linspace(*map_speed_range(scene), m["n_speed"])
        axis_label, scale = "speed Ω [rad/s]", 1.0
    else:
        name, E = e_param(m["part"]), np.linspace(*map_E_range(scene, ctx.spec), m["n_E"])
        axis_label, scale = f"E of {m['part']} [GPa]", 1e-9
    grid = Grid({name: E, MU: signed_mu_axis(m["mu_max"], m["n_mu"])})
    res = evaluate(model, grid, ctx.comm, progress=True)
    timings["map"] = res.seconds
    bands = equal_bands(band, m["n_bands"])
    smap = stability_map(res, bands, gt)
    out = {"parameter": name, "points": grid.size, "seconds": res.seconds,
           "seconds_per_point": res.seconds_per_point, **smap.as_dict()}
    t = time.perf_counter()
    found = map_instabilities(ctx, work, model, res, band, gt, ("sign(v) μ", axis_label), scale)
    out["instabilities"] = [x.as_dict() for x in found]
    timings["map_instabilities"] = time.perf_counter() - t
    ctx.say(f"[fem_squeal] stability map: {grid.size} points in {res.seconds:.2f} s "
            f"({1e3 * res.seconds_per_point:.2f} ms per point per rank), "
            f"at most {int(smap.total.max())} unstable modes, {len(found)} instabilities")
    if ctx.comm.rank == 0:
        write_npz_atomic(work / "stability_map.npz", {"mu": grid.axes[MU], m["second"]: E, "counts": smap.counts,
                                                       "total": smap.total, "eigenvalues": res.eigenvalues,
                                                       "bands_hz": np.array(bands),
                                                       "instabilities": masks(found, grid.shape)})
        plots.stability_maps(work / "stability_map.png", grid.axes[MU], E * scale, smap.counts, smap.total,
                             bands, axis_label, scene.title)
    return {"map": out}


def check(scene: dict, volumes) -> None:
    """The varied part exists; E_range is [E_min, E_max] with 0 < E_min < E_max."""
    if "matrices" in scene:                 # a model given as matrices: :mod:`.matrix_studies`
        return matrix_studies.check_map(scene, volumes)
    m = scene.analyses["map"]
    if m["second"] == SPEED:
        why = speed_not_a_parameter(scene)
        if why:
            raise SceneError(f"analyses.map.second: 'speed' is not a parameter of this model: {why}")
        if m["speed_range"]:
            msg = increasing(2, 0.0)(m["speed_range"])
            if msg or len(m["speed_range"]) != 2:
                raise SceneError(f"analyses.map.speed_range: {msg or 'must be [speed_min, speed_max]'}")
        return
    if m["part"] not in volumes:
        raise SceneError(f"analyses.map.part: unknown part {m['part']!r}; parts: {sorted(volumes)}")
    if m["E_range"]:
        msg = increasing(2, 0.0)(m["E_range"])
        if msg or len(m["E_range"]) != 2:
            raise SceneError(f"analyses.map.E_range: {msg or 'must be [E_min, E_max]'}")


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "map" not in res:
        return ""
    m = res["map"]
    axes = ", ".join(m["parameters"]) if "parameters" in m else f"sign(v)μ, {m['parameter']}"  # matrices: its own
    return (f"<h2>Stability map</h2><p>{m['points']} points of ({_e(axes)}) in "
               f"{_num(m['seconds'])} s; at most "
               f"{_num(int(np.max(m['total'])) if m.get('total') else 0)} "
               "unstable modes.</p>" + instabilities_html(m.get("instabilities", [])))


STAGE = Stage("map", ("reduced",), run, "(μ, E) stability map", section=SECTION, check=check, report=report,
              on_matrices=matrix_studies.run_map, section_on_matrices=matrix_studies.MAP)
