"""Time-domain analyses of a scene: the ``transient``, ``limit_cycle`` and ``segmented_pad`` stages.

transient      the reduced brake (:func:`fem_squeal.reduced.transient.from_reduced`): contact
               elements on polar patches with the cubic law and contact damping, the chosen
               friction law, the disc at Ω; from steady sliding plus a push of ``amplitude`` ×
               the static closure along the most unstable tangent-CEA mode, Newmark/HHT for
               ``t_end``.  The run streams to ``<cache>/.run-transient-<key>/`` with checkpoints,
               so an interrupted run resumes there; the finished history is moved to ``run/``.
limit_cycle    on that history (seed 002 §3–4): envelope saturation, frequency and amplitude;
               space–time SVD of the last cycles in the strain-energy norm and its MAC with the
               tangent CEA modes at steady sliding; the dynamic stability diagram (tangent CEA
               along the last cycle); component strain-energy shares along it; and the
               complex-mode cycles Re(αψe^(iωt)) of the most unstable mode for each α (eq. 6),
               with braking torque and friction work per cycle.
segmented_pad  the lumped sintered pad of seed 004, no mesh: phase portraits and regimes
               (stick-slip, creep, periodic, steady) against disc speed and against (v_s, v_d).

The reduced transient is small: rank 0 integrates it and the others wait for its results.
Files: transient.png, transient.npz, run/chunk_*.npz; limit_cycle.json, limit_cycle.png,
dynamic_stability.png, energy_shares.png, mode_cycles.png; segmented_pad.json,
segmented_pad_speeds.png, segmented_pad_velocities.png.
"""
from __future__ import annotations

import dataclasses
import shutil
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from fem_squeal.parallel import on_root
from fem_squeal.reduced.eigensolve import TWO_PI


def friction_law(a: dict, mu: float):
    """The friction law of analyses.transient (``mu``: the scene's |μ|, used when mu_s/mu_d are 0)."""
    from fem_squeal.reduced.friction import ConstantFriction, ElasticCoulomb, StribeckFriction

    mu_s = a["mu_s"] or mu
    mu_d = a["mu_d"] or mu
    if a["friction"] == "constant":
        return ConstantFriction(mu)
    if a["friction"] == "stribeck":
        return StribeckFriction(mu_s, mu_d, a["v_s"], a["v_d"])
    return ElasticCoulomb(mu_s, mu_d, a["k_t"], a["c_t"])


def integrator_options(a: dict) -> dict:
    """The :class:`~fem_squeal.reduced.transient.NewmarkHHT` options of analyses.transient ``a``."""
    return {k: a[k] for k in ("alpha", "rtol", "tangent", "adaptive", "max_iterations", "event_limit")}


def brake_model(rm, a: dict):
    """(dynamic model, integrator, steady-sliding state) of analyses.transient ``a`` on the reduced model."""
    from fem_squeal.reduced.transient import NewmarkHHT, from_reduced

    cd = a["contact_damping"] or [0.0, np.inf]
    dm = from_reduced(rm, omega=a["omega"], cubic_share=a["cubic_share"], c_max=cd[0], depth=cd[1],
                      patches=tuple(a["patches"]) if a["patches"] else None,
                      friction=friction_law(a, abs(rm.mu0)), f_cut=a["f_cut_hz"] or None, zeta_cut=a["zeta_cut"],
                      normal=a["normal"], zeta=a["zeta"])
    integ = NewmarkHHT(dm, a["dt"], **integrator_options(a))
    qs = integ.steady_sliding(rm.q_static)
    return dm, integ, qs


def most_unstable(integ, qs: np.ndarray, band) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Tangent CEA at steady sliding: (λ, shapes, in-band-unstable mask, index of the largest Re λ)."""
    from fem_squeal.reduced.limit_cycle import tangent_eigs

    Kt, Ct = integ.tangent_matrices(qs, np.zeros_like(qs))
    lam, Y = tangent_eigs(Kt, Ct, integ.model.M, vectors=True)
    f = lam.imag / TWO_PI
    unstable = (f >= band[0]) & (f <= band[1]) & (lam.real > 1e-6 * np.abs(lam))
    i = int(np.argmax(np.where(unstable, lam.real, -np.inf))) if unstable.any() else -1
    return lam, Y, unstable, i


class BrakeStart(NamedTuple):
    """The transient's start: dynamic model, integrator, steady sliding q_s, tangent CEA there
    (λ, shapes Y, unstable mask) and the pushed mode (index i, −1 if none is unstable; shape y)."""
    dm: Any
    integ: Any
    qs: np.ndarray
    lam: np.ndarray
    Y: np.ndarray
    unstable: np.ndarray
    i: int
    y: np.ndarray


def brake_start(rm, a: dict, band) -> BrakeStart:
    """:func:`brake_model` and :func:`most_unstable` of analyses.transient ``a``."""
    dm, integ, qs = brake_model(rm, a)
    lam, Y, unstable, i = most_unstable(integ, qs, band)
    y = Y[:, i] if i >= 0 else Y[:, int(np.argmax(lam.real))]
    return BrakeStart(dm, integ, qs, lam, Y, unstable, i, y)


def static_closure(dm, qs: np.ndarray) -> float:
    return float(np.median(np.concatenate([cs.d0 + cs.D @ qs for cs in dm.contacts])))


def probe(dm, y: np.ndarray) -> tuple[int, int]:
    """(contact set, element) that moves most in the shape ``y``: the signal of the time histories."""
    k = int(np.argmax([np.abs(cs.D @ y).max() for cs in dm.contacts]))
    return k, int(np.argmax(np.abs(dm.contacts[k].D @ y)))


def stage_transient(ctx, work: Path, timings: dict) -> dict[str, Any]:
    from fem_squeal.blas import single_threaded

    with single_threaded():
        return _stage_transient(ctx, work, timings)


def _stage_transient(ctx, work: Path, timings: dict) -> dict[str, Any]:
    from fem_squeal import plots
    from fem_squeal.output import write_npz_atomic
    from fem_squeal.reduced.transient import run_transient

    a = ctx.scene["analyses"]["transient"]
    band = tuple(ctx.scene["analyses"]["reduced"]["band_hz"])
    comm, say = ctx.comm, ctx.say

    def compute() -> dict[str, Any]:
        t0 = time.perf_counter()
        dm, integ, qs, lam, Y, unstable, i, y = brake_start(ctx.reduced_model(), a, band)
        closure = static_closure(dm, qs)
        top = sorted(lam[unstable], key=lambda z: -z.real)[:5]
        say(f"[fem_squeal] transient: {dm.size} basis vectors, {sum(c.size for c in dm.contacts)} contact "
            f"elements; {int(unstable.sum())} unstable at steady sliding, the fastest: "
            + (", ".join(f"{z.imag / TWO_PI:.0f} Hz ({z.real:.1f}/s)" for z in top) or "none"))
        k, j = probe(dm, y)
        d = dm.contacts[k].D[j] @ y
        y = y * (np.conj(d) / abs(d))       # the eigenvector's phase is arbitrary (round-off picks it): fix
        push = a["amplitude"] * closure / abs(d)   # it so that the probe element starts at its largest closure
        lam_y = lam[i] if i >= 0 else lam[int(np.argmax(lam.real))]   # the eigenvalue of y
        q0, v0 = qs + (push * y).real, (push * lam_y * y).real
        run_dir = ctx.cache.root / f".run-transient-{ctx.keys['transient']}"
        resume = (run_dir / "checkpoint.npz").exists()
        if resume:
            say(f"[fem_squeal] transient: resuming from the checkpoint in {run_dir}")
        t1 = time.perf_counter()
        res = run_transient(dm, q0, v0, a["t_end"], a["dt"], record_every=a["record_every"], folder=run_dir,
                            checkpoint_every=a["checkpoint_every"], resume=resume, progress=True,
                            **integrator_options(a))
        wall = time.perf_counter() - t1
        shutil.move(str(run_dir), str(work / "run"))
        st = res.stats
        x = res.q @ dm.contacts[k].D[j]
        xv = res.v @ dm.contacts[k].D[j]
        E = res.total_energy()
        leak = float(np.abs(res.energy_residual()).max() / max(E.max(), 1e-300))
        contact = {f"{cs.name}.{q}": res.contact[f"{cs.name}.{q}"] for cs in dm.contacts
                   for q in ("normal_force", "torque") if f"{cs.name}.{q}" in res.contact}
        write_npz_atomic(work / "transient.npz", {"t": res.t, "probe": x, "probe_rate": xv, "q_static": qs,
                                                   "q0": q0, **contact})
        extra = {f"{cs.name} normal force [kN]": res.contact[f"{cs.name}.normal_force"] / 1e3
                 for cs in dm.contacts}
        plots.transient(work / "transient.png", res.t, x, xv, extra,
                        title=f"{ctx.scene['title']}: closure of the most active contact element",
                        label="closure [µm]")
        if a["snapshots"] and ctx.write_fields:
            write_transient_snapshots(ctx, work, a, res, qs)
        timings["transient"] = time.perf_counter() - t0
        out = {"basis": dm.size, "contact_elements": sum(c.size for c in dm.contacts), "steps": st["n_steps"],
               "steps_computed": st["steps"],
               "dt": a["dt"], "t_end": a["t_end"], "wall_s": wall, "ms_per_step": 1e3 * wall / max(st["steps"], 1),
               "iterations_per_step": st["iterations"] / max(st["steps"], 1), "stats": st,
               "resumed": resume, "static_closure": closure,
               "probe": {"contact": dm.contacts[k].name, "element": j},
               "steady_sliding_unstable": [{"freq_hz": z.imag / TWO_PI, "real_part": z.real}
                                           for z in lam[unstable]],
               "pushed_mode": {"freq_hz": lam[i].imag / TWO_PI, "real_part": lam[i].real} if i >= 0 else None,
               "peak_closure_change": float(np.abs(x - x[0]).max()), "energy_leak": leak,
               "friction_work": float(res.energy["W_friction"][-1])}
        say(f"[fem_squeal] transient: {st['steps']} steps in {wall:.1f} s ({out['ms_per_step']:.3f} ms/step, "
            f"{out['iterations_per_step']:.2f} Newton iterations/step), energy balance {leak:.1e}")
        return out

    return {"transient": on_root(comm, compute)}


def write_transient_snapshots(ctx, work: Path, a: dict, res, qs: np.ndarray) -> None:
    """``analyses.transient.snapshots`` fields Φ(q − q_static) evenly over the last ``snapshot_window``
    (nearest recorded states), from the reduced stage's ``basis_field.npz``."""
    from fem_squeal.output import write_snapshots

    with np.load(ctx.entry("reduced") / "basis_field.npz") as f:
        field = {k: f[k] for k in f.files}
    window = a["snapshot_window"] or float(res.t[-1] - res.t[0])
    wanted = np.linspace(res.t[-1] - window, res.t[-1], a["snapshots"])
    idx = np.unique(np.abs(res.t[None, :] - wanted[:, None]).argmin(axis=1))
    write_snapshots(work / "transient_snapshots", field, res.t[idx], res.q[idx], qs)
    ctx.say(f"[fem_squeal] transient: {len(idx)} snapshots from t = {res.t[idx[0]] * 1e3:.3f} ms to "
            f"{res.t[idx[-1]] * 1e3:.3f} ms in transient_snapshots.vtu/.xdmf")


def stage_limit_cycle(ctx, work: Path, timings: dict) -> dict[str, Any]:
    from fem_squeal.blas import single_threaded

    with single_threaded():
        return _stage_limit_cycle(ctx, work, timings)


def _stage_limit_cycle(ctx, work: Path, timings: dict) -> dict[str, Any]:
    from fem_squeal import plots
    from fem_squeal.output import write_json_atomic
    from fem_squeal.reduced.limit_cycle import (
        detect_limit_cycle,
        dynamic_stability,
        follow_mode,
        mac,
        mode_cycle,
        plane_mac,
        space_time_svd,
        strain_energy_shares,
    )
    from fem_squeal.reduced.transient import load_history

    a = ctx.scene["analyses"]["limit_cycle"]
    ta = ctx.scene["analyses"]["transient"]
    band = tuple(ctx.scene["analyses"]["reduced"]["band_hz"])
    comm = ctx.comm

    def compute() -> dict[str, Any]:
        t0 = time.perf_counter()
        rm = ctx.reduced_model()
        dm, integ, qs, lam, Y, unstable, i, y = brake_start(rm, ta, band)
        h = load_history(ctx.entry("transient") / "run")
        t, Q, V = h["t"], h["q"], h["v"]
        k, j = probe(dm, y)
        x = Q @ dm.contacts[k].D[j]
        lc = detect_limit_cycle(t, x)
        period = 1.0 / lc.frequency_hz
        last = t >= t[-1] - a["cycles"] * period
        Kt, _ = integ.tangent_matrices(qs, np.zeros_like(qs))
        W = 0.5 * (Kt + Kt.T)
        svd = space_time_svd(Q[last] - Q[last].mean(axis=0), weight=W)
        n_sh = min(a["svd_shapes"], svd.shapes.shape[1])
        near = (lam.imag > 0) & (lam.imag / TWO_PI >= band[0]) & (lam.imag / TWO_PI <= band[1])
        cand = np.flatnonzero(near)
        macs = mac(svd.shapes[:, :n_sh], Y[:, cand])
        planes = plane_mac(svd.shapes[:, :n_sh], Y[:, cand])
        best = [{"shape": r + 1, "freq_hz": float(lam[cand[c]].imag / TWO_PI),
                 "real_part": float(lam[cand[c]].real), "mac": float(macs[r, c]),
                 "plane_share": float(planes[r, c])} for r, c in enumerate(np.argmax(planes, axis=1))]
        samples = np.flatnonzero(t >= t[-1] - period)
        samples = samples[:: max(samples.size // a["stability_samples"], 1)]
        ds = dynamic_stability(integ, t[samples], Q[samples], V[samples])
        trail = follow_mode(ds, lam[i]) if i >= 0 else None
        K_parts = rm.K_parts
        shares_t = None
        if K_parts:
            dq = Q[samples] - Q[last].mean(axis=0)
            e = np.array([[0.5 * d @ (K @ d) for K in K_parts.values()] for d in dq])
            shares_t = e / np.maximum(e.sum(axis=1, keepdims=True), 1e-300)
        cycles = []
        if i >= 0:
            omega = float(lam[i].imag)
            yn = y / np.abs(dm.contacts[k].D[j] @ y)        # unit closure amplitude at the probe
            for alpha in a["mode_cycle_amplitudes"]:
                mc = mode_cycle(integ, qs, yn, omega, alpha * static_closure(dm, qs), n=a["mode_cycle_samples"])
                dsm = dynamic_stability(integ, mc.t, mc.q, mc.v)
                re = dsm.eigenvalues.real[np.arange(len(mc.t)), follow_mode(dsm, lam[i])]
                cycles.append({"alpha": alpha, "friction_work": mc.friction_work,
                               "torque_mean": float(np.mean(mc.torque)), "torque_range": float(np.ptp(mc.torque)),
                               "normal_force_range": float(np.ptp(mc.normal_force)),
                               "pseudo_real_part_min": float(re.min()), "pseudo_real_part_max": float(re.max())})
        out = {"limit_cycle": lc.as_dict(), "window_s": float(t[last][-1] - t[last][0]),
               "svd_energy": svd.energy_fraction()[:n_sh], "svd_best_mac": best,
               "dynamic_stability": {"samples": int(samples.size), "followed_real_part": (
                   [float(ds.eigenvalues[s, c].real) for s, c in enumerate(trail)] if trail is not None else []),
                   "unstable_share": float(np.mean(ds.eigenvalues[np.arange(samples.size), trail].real > 0))
                   if trail is not None else None},
               "energy_shares": ({p: float(v) for p, v in zip(K_parts, shares_t.mean(axis=0))}
                                 if shares_t is not None else {}),
               "mode_energy_shares": strain_energy_shares(y, K_parts) if K_parts else {},
               "mode_cycles": cycles}
        write_json_atomic(work / "limit_cycle.json", out)
        plots.dynamic_stability(work / "dynamic_stability.png", ds.t, ds.eigenvalues, band,
                                title="tangent CEA over the last cycle (seed 002 Fig. 10)")
        plots.limit_cycle(work / "limit_cycle.png", t, x, lc, svd.energy_fraction()[:n_sh], best,
                          t[samples], shares_t, list(K_parts), cycles, ctx.scene["title"])
        timings["limit_cycle"] = time.perf_counter() - t0
        ctx.say(f"[fem_squeal] limit cycle: saturated {lc.saturated}, {lc.frequency_hz:.0f} Hz, amplitude "
                f"{lc.amplitude * 1e6:.3g} µm; SVD shape 1 lies {100 * best[0]['plane_share']:.0f} % in the plane "
                f"of the {best[0]['freq_hz']:.0f} Hz mode (MAC {best[0]['mac']:.2f})")
        return out

    return {"limit_cycle": on_root(comm, compute)}


def pad_parameters(a: dict):
    from fem_squeal.reduced.segmented_pad import SegmentedPad

    names = {f.name for f in dataclasses.fields(SegmentedPad)}
    return SegmentedPad(**{k: v for k, v in a.items() if k in names})


def stage_segmented_pad(ctx, work: Path, timings: dict) -> dict[str, Any]:
    """Seed 004's segmented pad: regimes and phase portraits against disc speed and (v_s, v_d).
    The runs are dealt over the ranks; every rank gets all results."""
    from dataclasses import replace

    from fem_squeal import plots
    from fem_squeal.output import write_json_atomic
    from fem_squeal.reduced.segmented_pad import simulate

    a = ctx.scene["analyses"]["segmented_pad"]
    comm = ctx.comm
    pad = pad_parameters(a)
    cases = [("speed", pad, v) for v in a["speeds"]]
    cases += [("velocities", replace(pad, v_s=vs, v_d=vd), v) for vs, vd in a["velocity_pairs"]
              for v in a["pair_speeds"]]
    t0 = time.perf_counter()
    mine = {}
    for n, (kind, p, speed) in enumerate(cases):
        if n % comm.size == comm.rank:
            r = simulate(p, speed, t_end=a["t_end"], dt=a["dt"], alpha=a["alpha"])
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

