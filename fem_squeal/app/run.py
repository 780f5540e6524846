"""The runner, :func:`run_scene`: it plans the stages of a scene
(:mod:`fem_squeal.app.pipeline`: only the stages the analyses need, cached by content hash) and
writes ``outdir``: ``results.json`` (schema below, written atomically by rank 0), the stages'
files (XDMF, PNG, npz, json) and ``report.html``.

results.json (schema_version 3)
-------------------------------
scene            the validated scene (all defaults filled in)
run              scene_file, overrides (the --set values; from the command line), version, code_version
                 (hash of the sources), ranks, blas_threads (OpenBLAS threads per rank: the cores over
                 the ranks on the machine unless OPENBLAS_NUM_THREADS or OMP_NUM_THREADS says), started (UTC)
stages           [{stage, key, status ("run" | "cached" | "memory" | "forced"), seconds (of the
                 run that computed it), peak_rss_gib (a stage computed in this run: the processes'
                 peak resident memory so far, largest_rank and sum_of_ranks of the ranks' peaks; it
                 never falls, so the stage after which it rose set it)}]
files            output files of the stages (relative to outdir)
mesh             cells, volumes (part names)
matrices         (a model given as matrices) dofs, files {name: {file, format, sha256, nonzeros}}, operators
                 {M, C, K: the affine form}, parameters {name: nominal value}, ranges, asymmetry {M, C, K:
                 ‖A − Aᵀ‖_F/‖A‖_F at the nominal point}; its real_modes rows hold freq_hz and residual, its
                 complex_modes rows no mesh descriptors
model            dofs, cells, ranks, degree
timings_s        wall time per stage
solver           kernels {name: built} (fem_squeal.fe.kernels: the compiled kernels this installation
                 has) and paths {stage: {operation: {path: count}}}: which path each assembly, block
                 product, factorisation, block solve and eigensolve of a computed stage took (rank 0;
                 "compiled", "compiled-avx512", "cholmod", "petsc", "dolfinx", "mumps, block Lanczos", ...),
                 recorded when the stage was computed and kept with its cache entry; factors: where
                 MUMPS kept the factors of the stages run ("in core", "out of core": the scene's
                 ICNTL(22), "out of core (memory model)": chosen because in core did not fit)
estimate         (when a stage runs) cells, dofs, memory_gib of the largest solve, available_gib,
                 machines, factors: the size check made before any stage ran (fem_squeal.app.resources)
preload          (models with contact interfaces) mode, iterations, history [[closed points,
                 ‖R‖/‖f‖]], jacobian (how Newton's steps were solved: "update", "refactorise",
                 "symmetric"; preload.jacobian "auto" resolved), factorisations, update_columns,
                 krylov_iterations, and per interface: normal_force [N], friction_force [N],
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
mode_shapes      the modes drawn for the report (fem_squeal.app.mode_shapes): modes (indices: the
                 unstable ones by decreasing Re λ, or the first three), points and triangles of the
                 outer surface drawn, surface_seconds, seconds_per_mode
cea_method       "linear" (undamped: EPS) or "pep" (damping, friction damping or the turning disc), or
                 "projection" (analyses.cea.method = "projection": issue 36)
cea_choice       (analyses.cea.method = "auto") why the method was chosen: DOFs and real modes below
                 the band top against the thresholds (fem_squeal.app.analyses.cea.AUTO_DOFS, AUTO_MODES;
                 AUTO_DOFS None: "auto" keeps the full CEA and writes no cea_choice)
cea_projection   (the projection) cut_hz, shift_hz, basis_size, basis {modes, static, enrichment,
                 dropped, size}, enrichment_rounds, worst_residual (the complex_modes' residual),
                 worst_relative_residual (η, relative to λ²M), n_real_modes_in_band, rounds [{size,
                 pairs_in_band, worst_residual, worst_relative_residual, above_tol}], seconds
cea_rotation     (operating.gyroscopic or preload.geometric_stiffness) speed and the norms of the added
                 terms
                 complex_modes rows also carry (fem_squeal.app.nvh): coupling {real_modes, percent,
                 real_freqs_hz, outside, pair, label, pair_kind} (analyses.cea.coupling: participation
                 100|c_i|²/Σ|c_j|² [%] of the real modes of ½(K + Kᵀ) ≥ 1 %, c = ΦᵀMx; outside =
                 1 − Σ|c_j|²/x^HMx), erp_w, erp_db [dB re 1 pW], squeal_index_db (unstable modes; None else)
cea_coupling     f_max_hz, n_real_modes, real_freqs_hz, real_modes [{index, freq_hz, nodal_diameter,
                 nodal_share, in_plane_share}] (those named in a coupling), basis
cea_radiation    rho_c, kinetic_energy_j, area_m2, default_efficiency, efficiency, exclude_faces, norm,
                 squeal_index (the definitions; analyses.cea.radiation)
cea_squeal_ranking  unstable modes (index), highest squeal index first
cea_bands        [{band_hz, lower_hz, upper_hz, n_modes, n_unstable, max_level_db,
                 max_unstable_level_db, max_squeal_index_db}] (1/3-octave bands 1-16 kHz)
reduced          size, parameters, mu0, rounds [{cut_hz, modes, sampled_modes, static, dropped,
                 size, change, seconds}], converged, tol, estimated_error, lifted_residuals
                 [{point, freq_hz, real_part, backward_error}], verification [{point,
                 max_rel_error, n_unstable_full, n_unstable_reduced, full_cea_s, ...}], contact_states
                 [{pressure, changed_share, entered_as ("modes" or "static derivatives")}] (the
                 operating matrix's pressures whose contact set is not the scene's), snapshots [{point,
                 vectors, seconds}] (analyses.reduced.nominal_snapshot: the greedy step's full CEA)
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
operating_matrix conditions [{pressure, temperature, speed, direction}], n_conditions, band_hz, mu {law:
                 |μ| per condition}, n_unstable, max_growth_rate (per condition), unstable_conditions,
                 occurrence, third_octave [{band_hz, lower_hz, upper_hz, conditions, occurrence,
                 in_model_band}], by_variable {variable: [{value, conditions, unstable, occurrence}]},
                 modes [{condition, frequency_hz, growth_rate, damping_ratio}], squeal_index (why
                 not), seconds, seconds_per_condition, verification [{condition, point, method,
                 between_corners, max_rel_error, n_unstable_full, n_unstable_reduced, full_cea_s,
                 ...}] (the corners, and the inner pressure whose contact set changed most)
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

Files (the field files, .xdmf/.h5/.vtu, only without ``--no-fields``; the cache keeps them either
way): real_modes.xdmf, complex_modes.xdmf (mode_re, mode_im), preload.xdmf, and the same fields
as VTU (meshio; real_modes.vtu mode_<j>, complex_modes.vtu mode_<j>_re/_im, preload.vtu; frequencies
in the field data) for tools other than ParaView
(preload_displacement, contact_pressure), contact_pressure.png; reduced_model.npz,
sweep.json, root_locus.png, complex_plane.png, stability_map.npz/png (every PNG plot with its data
as CSV of the same name); mode_shapes.npz and mode_shapes/ (the report's mode pictures and their
CSV, published with the field files); each stage module of :mod:`fem_squeal.app.analyses` lists its
files.
"""
from __future__ import annotations

import errno
import os
import shutil
import socket
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from mpi4py import MPI

from fem_squeal import __version__
from fem_squeal.app.analyses import STAGES
from fem_squeal.app.outputs import listed_outputs, publish, staged_outputs
from fem_squeal.app.outputs import remove_stale_outputs as _remove_stale
from fem_squeal.app.pipeline import Cache, code_version, make_plan, scratch
from fem_squeal.app.report import write_report
from fem_squeal.app.resources import check_outdir, check_resources, factor_folder_parent, factorisation_kind
from fem_squeal.app.scene import model_spec
from fem_squeal.app.stage import Context
from fem_squeal.util.atomic import jsonable, write_json_atomic
from fem_squeal.util.blas import blas_threads, limit_threads_for
from fem_squeal.util.errors import FemSquealError
from fem_squeal.util.memory import peak_rss_bytes, release_freed_memory
from fem_squeal.util.parallel import on_root
from fem_squeal.util.storage import STORAGE_ERRNOS, free_bytes, storage_error, storage_errors

SCHEMA_VERSION = 3
#: a stage failure with less than this free [bytes] on the cache's file system is reported as a full disk
#: (a library writing HDF5 reports its own error, not ENOSPC)
FULL_DISK_BYTES = 4 << 20


FACTOR_FOLDER = "fem_squeal_factors"     # <this>.<host>.<pid of rank 0>.<random>: out-of-core factor files


def _remove_stale_factor_folders(parent: str, host: str) -> float:
    """Remove the out-of-core factor folders under ``parent`` that a run on ``host`` left when it was
    killed (its process is gone: a killed process runs no clean-up, and at 1.3M DOFs they hold 26 GB);
    the bytes removed."""
    freed = 0.0
    for d in Path(parent).glob(f"{FACTOR_FOLDER}.{host}.*.*"):
        try:
            pid = int(d.name.split(".")[-2])
            os.kill(pid, 0)                     # alive (or another user's): kept
            continue
        except ProcessLookupError:
            pass
        except (ValueError, PermissionError):
            continue
        freed += sum(f.stat().st_size for f in d.glob("*") if f.is_file())
        shutil.rmtree(d, ignore_errors=True)
    return freed


@contextmanager
def _factors_out_of_core(comm, say) -> Iterator[str]:
    """Every MUMPS factor of the stages run inside in files of a folder of this run's own, under
    $MUMPS_OOC_TMPDIR or the system's temporary folder, removed afterwards (app.resources: chosen by
    the memory model where in-core factors do not fit); first the folders of killed runs on this
    machine are removed."""
    from fem_squeal.fe.factorisation import factors_out_of_core  # heavy: the FE stack, only when chosen

    parent, host = factor_folder_parent(), socket.gethostname()
    if comm.rank == 0:
        freed = _remove_stale_factor_folders(parent, host)
        if freed:
            say(f"[fem_squeal] removed {freed / 1e9:.3g} GB of factor files that killed runs left in {parent}")
    folder = comm.bcast(tempfile.mkdtemp(prefix=f"{FACTOR_FOLDER}.{host}.{os.getpid()}.", dir=parent)
                        if comm.rank == 0 else None, root=0)
    os.makedirs(folder, exist_ok=True)                  # the ranks of other machines: their own disk
    say(f"[fem_squeal] MUMPS's factors go out of core, to files in {folder}")
    try:
        with factors_out_of_core(folder):
            yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)       # nothing a factor left (MUMPS removes its own)


def _tally(reset: bool = False) -> dict:
    """The finite-element layer's tally of the paths that ran (:func:`fem_squeal.fe.kernels.tally`),
    {} for a run that never loaded it (a lumped model)."""
    kernels = sys.modules.get("fem_squeal.fe.kernels")
    return kernels.tally(reset) if kernels is not None else {}


def _kernels_built() -> dict[str, bool]:
    """Which compiled kernels the package was built with (:func:`fem_squeal.fe.kernels.status`)."""
    from fem_squeal.fe import kernels  # heavy: the FE layer's package (dolfinx is not imported by it)

    return kernels.status()


def _stage_functions() -> dict:
    """name -> the stage's function, from the registry (a function, so tests can stand in for one)."""
    return {name: st.run for name, st in STAGES.items()}


def remove_stale_outputs(outdir: Path, files: list[str]) -> None:
    """Delete the files that an earlier run listed in ``outdir/results.json`` and this run did not
    write (a MASA plot of a μ no longer asked for), so the folder shows one run."""
    _remove_stale(outdir, listed_outputs(outdir), files)


def _as_storage_error(e: BaseException, stage: str, folder: Path) -> BaseException:
    """A stage's failure to write its cache entry as a named :class:`StorageError`: an ``OSError`` for
    space or permission, or any library error (PETSc's HDF5 writer) on a file system left with less
    than :data:`FULL_DISK_BYTES`; ``e`` itself otherwise."""
    if isinstance(e, FemSquealError):
        return e
    what = f"writing the cache entry of stage {stage}"
    if isinstance(e, OSError) and e.errno in STORAGE_ERRNOS:
        return storage_error(e, what, folder)
    try:
        full = free_bytes(folder) < FULL_DISK_BYTES
    except OSError:
        full = False
    if full:
        cause = str(e).splitlines()[0] if str(e) else ""
        return storage_error(OSError(errno.ENOSPC, f"no space left on device (the writer said: {type(e).__name__}"
                                     f"{': ' + cause if cause else ''})", str(folder)), what, folder)
    return e


def _run_stage(fn, ctx: Context, work: Path, stage_t: dict, stage: str, comm, where: Path) -> dict:
    """``fn(ctx, work, stage_t)``, a failure on any rank raised on every rank, storage failures named
    (:func:`_as_storage_error`) by the folder ``where`` (the cache)."""
    error = None
    try:
        sections = fn(ctx, work, stage_t)
    except Exception as e:          # not KeyboardInterrupt/SystemExit: those end the run at once
        error = _as_storage_error(e, stage, where)
    failed = comm.allreduce(error is not None, op=MPI.LOR)
    if error is not None:
        raise error
    if failed:
        raise FemSquealError(f"stage {stage}: failed on another rank (its message is above)")
    return sections


def run_scene(scene: dict, outdir: str | Path, comm: MPI.Comm = MPI.COMM_WORLD, write_fields: bool = True,
              log=print, cache: str | Path | None = None, force=(), report: bool = True,
              provenance: dict | None = None) -> dict[str, Any]:
    """Run the stages that ``scene``'s analyses need (:mod:`fem_squeal.app.pipeline`), reusing the
    entries of ``cache`` (a folder; None = a temporary cache, removed afterwards), and write the
    outputs to ``outdir`` (all at once: :mod:`fem_squeal.app.outputs`).  ``write_fields``: publish the
    field files (XDMF, VTU); it changes no cache key.  ``provenance``: what produced the scene
    (``scene_file``, ``overrides``), recorded with the code version under ``run``.  Returns the
    results dictionary (the content of results.json)."""
    outdir = Path(outdir)
    rank0 = comm.rank == 0
    limit_threads_for(comm)
    say = log if rank0 else (lambda *a, **k: None)
    on_root(comm, lambda: check_outdir(outdir))
    temporary = cache is None
    if temporary:
        cache = comm.bcast(tempfile.mkdtemp(prefix="fem_squeal_cache.") if rank0 else None, root=0)
    store = Cache(cache)
    stages_context = ExitStack()        # what the stages run inside (out-of-core factors), closed at the end
    try:
        spec = model_spec(scene) if "geometry" in scene else None   # the one the scene's validation built
        plan = on_root(comm, lambda: make_plan(scene, store, force=force))   # rank 0 reads the cache
        for item in plan:
            if item.note:
                say(f"[fem_squeal] warning: {item.note}")
        results: dict[str, Any] = {"schema_version": SCHEMA_VERSION, "scene": scene, "stages": [],
                                   "run": {**(provenance or {}), "version": __version__,
                                           "code_version": code_version(), "ranks": comm.size,
                                           "blas_threads": blas_threads(),
                                           "started": datetime.now(UTC).isoformat(timespec="seconds")}}
        if any(p.status != "cached" for p in plan):         # a stage will run: its model must fit
            est, notes = check_resources(scene, comm)
            if est is not None:
                results["estimate"] = est.as_dict()
                say(f"[fem_squeal] estimate: {est.cells:.3g} cells, {est.dofs:.3g} DOFs, largest solve "
                    f"{est.memory_gib:.3g} GiB of {est.available_gib:.3g} GiB, factors {est.factors}")
            for w in notes:
                warnings.warn(w, ResourceWarning, stacklevel=2)
                say(f"[fem_squeal] warning: {w}")
            if est is not None and est.factors == "out of core (memory model)":
                stages_context.enter_context(_factors_out_of_core(comm, say))
        ctx = Context(scene, spec, comm, say, write_fields, store, {p.stage: p.key for p in plan})
        functions = _stage_functions()
        if "matrices" in scene:     # a model given as matrices: the analyses' functions for it
            functions.update({n: st.on_matrices for n, st in STAGES.items() if st.on_matrices is not None})
        timings: dict[str, float] = {}
        paths: dict[str, dict] = {}
        for i, item in enumerate(plan):
            t0 = time.perf_counter()
            if item.status == "cached":
                entry = on_root(comm, lambda item=item: store.load(item.stage, item.key))
            else:
                say(f"[fem_squeal] stage {i + 1}/{len(plan)}: {item.stage}"
                    + (" (in memory; outputs cached)" if item.status == "memory" else ""))
                stage_t: dict[str, float] = {}
                if item.status == "memory":
                    ctx.keep_files = False
                    with scratch(comm) as work:
                        _run_stage(functions[item.stage], ctx, work, stage_t, item.stage, comm, work)
                    ctx.keep_files = True
                    entry = on_root(comm, lambda item=item: store.load(item.stage, item.key))
                else:
                    _tally(reset=True)
                    with store.writing(comm, item.stage, item.key, replace=item.status == "forced") as (work, idx):
                        sections = jsonable(_run_stage(functions[item.stage], ctx, work, stage_t, item.stage,
                                                       comm, store.root))
                        idx.update({"stage": item.stage, "key": item.key, "results": sections,
                                    "timings": stage_t, "seconds": time.perf_counter() - t0,
                                    "paths": _tally(reset=True)})
                    entry = idx
                    timings.update(stage_t)
            release_freed_memory()         # what the stage's factorisations left in the heap (util.memory)
            results.update(entry["results"])
            results["stages"].append({"stage": item.stage, "key": item.key, "status": item.status,
                                      "seconds": entry["seconds"]})
            if item.status != "cached":                  # this process's high-water mark after the stage
                peaks = comm.allgather(peak_rss_bytes())
                results["stages"][-1]["peak_rss_gib"] = {"largest_rank": max(peaks) / 2 ** 30,
                                                         "sum_of_ranks": sum(peaks) / 2 ** 30}
            if entry.get("paths"):
                paths[item.stage] = entry["paths"]
        results["timings_s"] = timings
        results["solver"] = {"kernels": _kernels_built(), "paths": paths,
                             "factors": results["estimate"]["factors"] if "estimate" in results else
                             "out of core" if factorisation_kind(scene) == "ooc" else "in core"}
        if "model" in results:
            results["model"]["ranks"] = comm.size

        def write_outputs() -> list[str]:
            """Every output into a staging folder, then all renamed into ``outdir`` at once."""
            old = listed_outputs(outdir)
            with storage_errors("writing the outputs", outdir), staged_outputs(outdir) as stage:
                files = []
                for item in plan:
                    files += publish(store.entry(item.stage, item.key), outdir, stage, fields=write_fields)
                results["files"] = files
                write_json_atomic(stage / "results.json", results)
                if report:
                    write_report(outdir, results, into=stage)
            _remove_stale(outdir, old, files)
            return files

        # a failure there (a full disk, a report section) is raised on every rank; outdir is unchanged
        results["files"] = on_root(comm, write_outputs)
        return results
    finally:
        stages_context.close()
        if temporary:
            comm.barrier()
            if rank0:
                shutil.rmtree(cache, ignore_errors=True)
