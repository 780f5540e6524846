"""``analyses.sweep`` on a model given as matrices (a ``[matrices]`` scene): one named parameter over
``points`` (its values) or its range, on the reduced model of the matrices
(:func:`fem_squeal.reduced.matrix_reduction.reduce_matrix_model`: real modes of the symmetric part plus
static corrections, or eigenvector snapshots of the non-symmetric problem), every branch tracked
(:func:`fem_squeal.reduced.tracking.track`) and the critical values where a mode changes stability
located; the same files and results.json ``sweep`` as the sweep of a finite-element model (sweep.json,
root_locus.png, complex_plane.png), plus ``sweep_reduction``: the basis and the check of the reduced
eigenvalues against the full sparse CEA of the assembled matrices at ``check_points`` values of the
sweep (relative error of every full eigenvalue in the band to the nearest reduced one, against
``tol``).  The basis: :func:`fem_squeal.app.analyses.matrix_reduced.reduced_model` (on several ranks
the modal and the snapshot bases are built distributed); every rank tracks the same
reduced model: serial and MPI runs give the same sweep."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses import matrix_reduced
from fem_squeal.app.analyses.matrices import model_of
from fem_squeal.app.fields import REAL, Field, at_least, band, increasing, one_of, positive
from fem_squeal.app.stage import Context
from fem_squeal.reduced.eigensolve import unstable
from fem_squeal.reduced.matrix_reduction import ReducedMatrixModel
from fem_squeal.reduced.sweep import path_solver
from fem_squeal.reduced.tracking import track
from fem_squeal.util.atomic import write_json_atomic
from fem_squeal.util.errors import InputError, SceneError

SECTION = {
    "parameter": Field(str, None, None, "the parameter swept: a name of matrices.parameters"),
    "points": Field(list, None, increasing(2), "the values swept (increasing); not set: n values over range"),
    "range": Field(list, None, increasing(2), "[first, last] value; not set: the parameter's range"),
    "n": Field(int, 101, at_least(2), "number of values (with range)"),
    "refine_tol": Field(REAL, 1e-10, positive, "critical values refined to this fraction of the range"),
    "band_hz": Field(list, None, band, "[low, high] Hz: the branches tracked and checked; not set: "
                     "analyses.cea.band_hz, else up to the highest real mode of the basis"),
    "growth_tol": Field(REAL, 1e-6, positive, "unstable: Re λ > growth_tol |λ|"),
    "basis": Field(str, "auto", one_of("auto", "modes", "snapshots"), "'modes': real modes of the symmetric "
                   "part + static corrections; 'snapshots': eigenvectors of the non-symmetric problem at "
                   "sampled values; 'auto': modes where M's symmetric part is positive definite"),
    "modes": Field(int, 20, at_least(1), "real modes in the basis"),
    "corrections": Field(bool, True, None, "static corrections of the non-symmetric and parameter terms"),
    "snapshots": Field(int, 5, at_least(1), "snapshot basis: parameter values sampled (evenly over the sweep)"),
    "snapshot_modes": Field(int, 10, at_least(1), "snapshot basis: eigenvectors per value, nearest target_hz"),
    "target_hz": Field(REAL, 0.0, None, "snapshot basis: the frequency the eigenvectors are taken near"),
    "check_points": Field(int, 3, at_least(0), "values of the sweep (evenly spaced) where the reduced "
                          "eigenvalues are checked against the full sparse CEA"),
    "tol": Field(REAL, 1e-6, positive, "relative eigenvalue error allowed at the check points"),
}


def sweep_values(scene) -> np.ndarray:
    """The values swept: ``points``, or ``n`` values over ``range`` (else the parameter's range)."""
    s = scene.analyses["sweep"]
    if s["points"] is not None:
        return np.asarray(s["points"], float)
    lo, hi = s["range"] if s["range"] is not None else scene.matrices.parameters[s["parameter"]]["range"]
    return np.linspace(lo, hi, s["n"])


def check(scene, volumes) -> None:
    """The parameter is one of matrices.parameters; values or range (or the parameter's), not both; every
    coefficient of the operators finite over the values."""
    s, key = scene.analyses["sweep"], "analyses.sweep"
    params = scene.matrices.parameters
    if s["parameter"] is None:
        raise SceneError(f"{key}.parameter: required on a model given as matrices; one of {sorted(params)}")
    if s["parameter"] not in params:
        raise SceneError(f"{key}.parameter: {s['parameter']!r} is not a parameter of matrices.parameters; "
                         f"parameters: {sorted(params)}")
    if s["points"] is not None and s["range"] is not None:
        raise SceneError(f"{key}.points: give points or range, not both")
    if s["points"] is None and s["range"] is None and params[s["parameter"]]["range"] is None:
        raise SceneError(f"{key}.range: required: matrices.parameters.{s['parameter']} has no range "
                         "(or give analyses.sweep.points)")
    values = sweep_values(scene)
    model = model_of(scene.matrices)
    try:
        for op in model.operators.values():
            op.coefficients({**model.nominal, s["parameter"]: values})
    except InputError as e:
        raise SceneError(f"{key}.{'points' if s['points'] is not None else 'range'}: {e}") from None


def reduced_model(ctx: Context, values: np.ndarray) -> ReducedMatrixModel:
    """The reduced model of the scene's matrices (:func:`fem_squeal.app.analyses.matrix_reduced.reduced_model`;
    snapshots at ``snapshots`` values evenly over the sweep)."""
    s = ctx.scene.analyses["sweep"]
    idx = np.unique(np.linspace(0, values.size - 1, s["snapshots"]).round().astype(int))
    return matrix_reduced.reduced_model(ctx, s, [{s["parameter"]: float(values[i])} for i in idx])


def check_point(ctx: Context, red: ReducedMatrixModel, par: str, value: float, band_hz, growth_tol: float) -> dict:
    """The full sparse CEA of the assembled matrices at ``par = value`` (PETSc/SLEPc, distributed) against
    the reduced eigenvalues (:func:`fem_squeal.app.analyses.matrix_reduced.check_point`)."""
    c = matrix_reduced.check_point(ctx, red, {par: value}, band_hz, growth_tol, "sweep_check_")
    del c["point"]
    return {"value": float(value), **c}


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.sweep on a model given as matrices (module docstring)."""
    scene = ctx.scene
    s = scene.analyses["sweep"]
    par, gt = s["parameter"], s["growth_tol"]
    values = sweep_values(scene)
    t = time.perf_counter()
    red = reduced_model(ctx, values)
    timings["sweep_reduction"] = time.perf_counter() - t
    band_hz = matrix_reduced.study_band(ctx, s, red)
    t = time.perf_counter()
    tr = track(path_solver(red, par), values, growth_tol=gt, start=float(values[0]), progress=ctx.comm.rank == 0,
               values_solve=path_solver(red, par, vectors=False), tol=s["refine_tol"], band_hz=band_hz)
    timings["sweep"] = time.perf_counter() - t
    f = tr.freqs_hz
    inside = np.flatnonzero(np.any((f >= band_hz[0]) & (f <= band_hz[1]), axis=0))
    events = [e for e in tr.events if band_hz[0] <= e.freq_hz <= band_hz[1]]
    t = time.perf_counter()
    idx = np.unique(np.linspace(0, values.size - 1, s["check_points"]).round().astype(int)) \
        if s["check_points"] else np.zeros(0, int)
    checks = [check_point(ctx, red, par, float(values[i]), band_hz, gt) for i in idx]
    timings["sweep_check"] = time.perf_counter() - t
    worst = max((c["max_rel_error"] for c in checks), default=None)
    out = {"parameter": par, "values": values, "branches": [
        {"label": tr.labels[j], "parent_hz": tr.parents_hz[j], "freq_hz": f[:, j],
         "real_part": tr.eigenvalues[:, j].real} for j in inside],
        "critical": [e.as_dict() for e in events], "band_hz": list(band_hz),
        "solves": tr.solves, "vector_solves": tr.vector_solves, "ambiguous_steps": tr.ambiguous_steps,
        "seconds": timings["sweep"], "seconds_per_value": timings["sweep"] / values.size}
    reduction = {**red.info, "verification": checks, "max_rel_error": worst, "tol": s["tol"],
                 "passed": worst is None or worst <= s["tol"]}
    ctx.say(f"[fem_squeal] sweep of {par} on the matrices' reduced model ({red.info['basis']}, size "
            f"{red.size}): {values.size} values, {tr.solves} reduced solves, {len(events)} stability changes "
            f"in {band_hz[0]:g}-{band_hz[1]:g} Hz; reduced vs full CEA at {len(checks)} values: worst "
            + (f"{worst:.1e} (tol {s['tol']:g})" if worst is not None else "not checked"))
    if not reduction["passed"]:
        ctx.say(f"[fem_squeal] warning: the reduced model misses the full CEA by {worst:.1e} > tol {s['tol']:g}: "
                "raise analyses.sweep.modes")
    if ctx.comm.rank == 0:
        write_json_atomic(work / "sweep.json", {**out, "reduction": reduction})
        plots.root_locus(work / "root_locus.png", values, tr.eigenvalues, unstable(tr.eigenvalues, gt), par,
                         band_hz, tr.labels, scene.title)
        plots.complex_plane(work / "complex_plane.png", tr.eigenvalues, band_hz, gt, scene.title)
    out.pop("branches")  # kept in sweep.json; results.json holds the summary
    return {"sweep": out, "sweep_reduction": reduction}
