"""The runner, :func:`run_scene`: it plans the stages of a scene
(:mod:`fem_squeal.app.pipeline`: only the stages the analyses need, cached by content hash) and
writes ``outdir``: ``results.json`` (schema below, written atomically by rank 0), the stages'
files (XDMF, PNG, npz, json) and ``report.html``.

results.json (schema_version 3)
-------------------------------
scene            the validated scene (all defaults filled in)
run              scene_file, overrides (the --set values; from the command line), version, code_version
                 (hash of the sources), ranks, started (UTC)
stages           [{stage, key, status ("run" | "cached" | "memory" | "forced"), seconds (of the
                 run that computed it)}]
files            output files of the stages (relative to outdir)
mesh             cells, volumes (part names)
model            dofs, cells, ranks, degree
timings_s        wall time per stage
estimate         (when the mesh is built) cells, dofs, memory_gib of the largest solve, available_gib,
                 machines: the size check made before any stage ran (fem_squeal.app.resources)
preload          (models with contact interfaces) mode, iterations, history [[closed points,
                 ‖R‖/‖f‖]], and per interface: normal_force [N], friction_force [N],
                 contact_area [m²], area [m²], peak_pressure [Pa], closed_share
friction_damping (interfaces with friction_damping) norm (‖C_d‖), speed [rad/s]
real_modes       [{freq_hz, residual, in_plane_share, nodal_diameter, nodal_share}] (nodal_share: the
                 projection on the uniform harmonic ±k, not an energy share: fem_squeal.fe.descriptors)
complex_modes    [{index, freq_hz, real_part [1/s], damping_ratio, residual, unstable,
                   in_plane_share, nodal_diameter, nodal_share, travelling_index,
                   travelling_direction, energy_shares {component: share}}]
                 (Im λ > 0, inside analyses.cea.band_hz; descriptors of describe_part;
                 energy_shares only for models with several parts)
n_unstable       number of complex modes with Re λ > analyses.cea.growth_tol·|λ| (their ``unstable``)
cea_method       "linear" (undamped: EPS) or "pep" (damping, friction damping or the turning disc)
cea_rotation     (operating.gyroscopic or preload.geometric_stiffness) speed and the norms of the added
                 terms
reduced          size, parameters, mu0, rounds [{cut_hz, modes, sampled_modes, static, dropped,
                 size, change, seconds}], converged, tol, estimated_error, lifted_residuals
                 [{point, freq_hz, real_part, backward_error}], verification [{point,
                 max_rel_error, n_unstable_full, n_unstable_reduced, full_cea_s, ...}]
sweep            parameter, values, critical [{branch, partner, value, bracket, freq_hz, kind,
                 onset, labels, zero_crossing (False: no Re λ = 0 in reach, value is where Re λ =
                 growth_tol |λ|)}], solves (reduced solves while tracking), vector_solves (of which
                 with eigenvectors), seconds (branches in sweep.json)
map              parameter ("E.<part>" or "speed": the second axis), points, seconds, seconds_per_point,
                 axes, bands_hz, counts, total (stability_map.npz: mu, E or speed, counts, total, ...)
sensitivity      [{index, freq_hz, real_part, unstable, d_real_part {parameter: ∂Re λ/∂p}, d_freq_hz
                   {parameter: ∂f/∂p}, rel_d_real_part, rel_d_freq_hz (p·∂/∂p), kappa_local, kappa,
                   near_coalescence (then the derivatives are None), ranking, full (with
                   analyses.sensitivity.full: the same derivatives from the full CEA's right and left
                   eigenvectors)}] (reduced model)
robustness       n_samples, seed, ranks, seconds, seconds_per_sample, parameters {name: distribution},
                 probability {p, stderr, wilson95}, bands [{band_hz, p, stderr, ...}], families
                 [{label, freq_hz, nominal_real_part, p, stderr, growth {mean, std, min, q05,
                 median, q95, max}, drivers}], drivers {parameter: Spearman ρ and its 95 % interval},
                 sobol {parameter: first-order Sobol' index and its bootstrap interval},
                 family_assignment, spot_checks [{point, max_rel_error, ...}] (full CEA)
masa             cases [{mu, equilibrium, elements, basis, instabilities [{freq_hz, real_part,
                 stationary_amplitudes, stationary_in_unit, broke_at, steps}], seconds}]
transient        basis, contact_elements, steps, steps_computed (fewer when resumed), dt, t_end,
                 wall_s, ms_per_step,
                 iterations_per_step, stats, resumed, static_closure, probe, steady_sliding_unstable
                 [{freq_hz, real_part}], pushed_mode, peak_closure_change, energy_leak, friction_work
limit_cycle      limit_cycle {saturated, frequency_hz, amplitude, t_saturation, growth_rate},
                 window_s, svd_energy, svd_best_mac [{shape, freq_hz, real_part, mac, plane_share}],
                 dynamic_stability {samples, followed_real_part, unstable_share}, energy_shares,
                 mode_energy_shares, mode_cycles [{alpha, friction_work, torque_mean, ...}]
segmented_pad    runs [{kind, speed, v_s, v_d, regimes, regime, fractions (time shares of s < v_s,
                 v_s ≤ s < v_d, s ≥ v_d per element), s_min (per element) [m/s], steps}], seconds

Files: real_modes.xdmf, complex_modes.xdmf (mode_re, mode_im), preload.xdmf, and the same fields
as VTU (meshio; real_modes.vtu mode_<j>, complex_modes.vtu mode_<j>_re/_im, preload.vtu; frequencies
in the field data) for tools other than ParaView
(preload_displacement, contact_pressure), contact_pressure.png; reduced_model.npz,
sweep.json, root_locus.png, complex_plane.png, stability_map.npz/png; each stage module of
:mod:`fem_squeal.app.analyses` lists its files.
"""
from __future__ import annotations

import json
import shutil
import tempfile
import time
import warnings
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from mpi4py import MPI

from fem_squeal import __version__
from fem_squeal.app.analyses import STAGES
from fem_squeal.app.pipeline import Cache, code_version, make_plan, publish, scratch
from fem_squeal.app.report import write_report
from fem_squeal.app.resources import check_outdir, check_resources
from fem_squeal.app.scene import model_spec
from fem_squeal.app.stage import Context
from fem_squeal.util.atomic import jsonable, write_json_atomic
from fem_squeal.util.blas import limit_threads_for
from fem_squeal.util.parallel import on_root

SCHEMA_VERSION = 3


def _stage_functions() -> dict:
    """name -> the stage's function, from the registry (a function, so tests can stand in for one)."""
    return {name: st.run for name, st in STAGES.items()}


def remove_stale_outputs(outdir: Path, files: list[str]) -> None:
    """Delete the files that an earlier run listed in ``outdir/results.json`` and this run did not
    write (a MASA plot of a μ no longer asked for), so the folder shows one run."""
    try:
        old = json.loads((outdir / "results.json").read_text()).get("files", [])
    except (OSError, ValueError):
        return
    for name in set(old) - set(files):
        p = (outdir / name).resolve()
        if outdir.resolve() in p.parents and p.is_file():
            p.unlink()


def run_scene(scene: dict, outdir: str | Path, comm: MPI.Comm = MPI.COMM_WORLD, write_fields: bool = True,
              log=print, cache: str | Path | None = None, force=(), report: bool = True,
              provenance: dict | None = None) -> dict[str, Any]:
    """Run the stages that ``scene``'s analyses need (:mod:`fem_squeal.app.pipeline`), reusing the
    entries of ``cache`` (a folder; None = a temporary cache, removed afterwards), and write the
    outputs to ``outdir``.  ``provenance``: what produced the scene (``scene_file``, ``overrides``), recorded
    with the code version under ``run``.  Returns the results dictionary (the content of results.json)."""
    outdir = Path(outdir)
    rank0 = comm.rank == 0
    limit_threads_for(comm)
    say = log if rank0 else (lambda *a, **k: None)
    on_root(comm, lambda: check_outdir(outdir))
    temporary = cache is None
    if temporary:
        cache = comm.bcast(tempfile.mkdtemp(prefix="fem_squeal_cache.") if rank0 else None, root=0)
    store = Cache(cache)
    try:
        plan = make_plan(scene, store, force=force, write_fields=write_fields)
        results: dict[str, Any] = {"schema_version": SCHEMA_VERSION, "scene": scene, "stages": [],
                                   "run": {**(provenance or {}), "version": __version__,
                                           "code_version": code_version(), "ranks": comm.size,
                                           "started": datetime.now(UTC).isoformat(timespec="seconds")}}
        if any(p.stage == "mesh" and p.status != "cached" for p in plan):   # the mesh will be built
            est, notes = check_resources(scene, comm)
            if est is not None:
                results["estimate"] = est.as_dict()
                say(f"[fem_squeal] estimate: {est.cells:.3g} cells, {est.dofs:.3g} DOFs, largest solve "
                    f"{est.memory_gib:.3g} GiB of {est.available_gib:.3g} GiB")
            for w in notes:
                warnings.warn(w, ResourceWarning, stacklevel=2)
                say(f"[fem_squeal] warning: {w}")
        spec = model_spec(scene) if "geometry" in scene else None
        ctx = Context(scene, spec, comm, say, write_fields, store, {p.stage: p.key for p in plan})
        functions = _stage_functions()
        timings: dict[str, float] = {}
        for i, item in enumerate(plan):
            t0 = time.perf_counter()
            if item.status == "cached":
                entry = store.load(item.stage, item.key)
            else:
                say(f"[fem_squeal] stage {i + 1}/{len(plan)}: {item.stage}"
                    + (" (in memory; outputs cached)" if item.status == "memory" else ""))
                stage_t: dict[str, float] = {}
                writer = scratch(comm) if item.status == "memory" else store.writing(comm, item.stage, item.key)
                with writer as work:
                    sections = jsonable(functions[item.stage](ctx, work, stage_t))
                    entry = {"stage": item.stage, "key": item.key, "results": sections, "timings": stage_t,
                             "seconds": time.perf_counter() - t0}
                    if rank0 and item.status != "memory":
                        write_json_atomic(work / "entry.json", entry)
                if item.status == "memory":
                    entry = store.load(item.stage, item.key)
                else:
                    timings.update(stage_t)
            results.update(entry["results"])
            results["stages"].append({"stage": item.stage, "key": item.key, "status": item.status,
                                      "seconds": entry["seconds"]})
        def publish_all() -> list[str]:
            outdir.mkdir(parents=True, exist_ok=True)
            files = []
            for item in plan:
                files += publish(store.entry(item.stage, item.key), outdir)
            remove_stale_outputs(outdir, files)
            return files

        results["files"] = on_root(comm, publish_all)
        results["timings_s"] = timings
        if "model" in results:
            results["model"]["ranks"] = comm.size
        def write_outputs() -> None:
            write_json_atomic(outdir / "results.json", results)
            if report:
                write_report(outdir, results)

        on_root(comm, write_outputs)      # a failure there (a report section) is raised on every rank
        return results
    finally:
        if temporary:
            comm.barrier()
            if rank0:
                shutil.rmtree(cache, ignore_errors=True)
