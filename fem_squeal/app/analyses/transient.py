"""The ``transient`` analysis: the nonlinear transient of the reduced brake (seed 002).

Contact elements on polar patches with the cubic (or exponential) law and contact damping, the
chosen friction law, the disc at Ω (:func:`fem_squeal.reduced.transient.from_reduced`); from steady
sliding plus a push of ``amplitude`` × the static closure along the most unstable tangent-CEA mode,
Newmark/HHT for ``t_end``.  The run streams to ``<cache>/.run-transient-<key>/`` with checkpoints,
so an interrupted run resumes there; the finished history is moved to ``run/``.  The reduced
transient is small: rank 0 integrates it and the others wait for its results.
Files: transient.png, transient.npz, run/chunk_*.npz, transient_snapshots.vtu/.xdmf."""
from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses.reduced import check_contact_study
from fem_squeal.app.fields import REAL, Field, non_negative, one_of, positive
from fem_squeal.app.html import num as _num
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.laws.contact import NORMAL_LAWS
from fem_squeal.reduced.laws.friction import FRICTION_LAWS
from fem_squeal.reduced.limit_cycle import tangent_eigs
from fem_squeal.reduced.transient import NewmarkHHT, from_reduced, run_transient
from fem_squeal.util.atomic import write_npz_atomic
from fem_squeal.util.blas import single_threaded
from fem_squeal.util.errors import SceneError
from fem_squeal.util.parallel import on_root
from fem_squeal.util.vtu import write_snapshots

SECTION = {
    "omega": Field(REAL, 5.0, positive, "disc speed Ω [rad/s]; the counter-face of each element moves at Ωr"),
    "t_end": Field(REAL, 0.1, positive, "simulated time [s]"),
    "dt": Field(REAL, 1e-6, positive, "time step [s]"),
    "alpha": Field(REAL, 0.0, lambda v: None if -1 / 3 <= v <= 0 else f"must be in [-1/3, 0] (got {v})",
                   "HHT α (0: trapezoidal rule, energy conserving)"),
    "rtol": Field(REAL, 1e-9, positive, "Newton tolerance on the dynamic force scale"),
    "tangent": Field(str, "modified", one_of("modified", "full"), "Newton tangent reuse"),
    "adaptive": Field(bool, False, None, "halve the step around contact and stick/slip events"),
    "friction": Field(str, next(iter(FRICTION_LAWS)), one_of(*FRICTION_LAWS),
                      "; ".join(f"{name}: {e.doc}" for name, e in FRICTION_LAWS.items())),
    "mu_s": Field(REAL, None, positive, "static μ (stribeck, coulomb); not set: the scene's μ", unset=0),
    "mu_d": Field(REAL, None, positive, "dynamic μ (stribeck, coulomb); not set: the scene's μ", unset=0),
    "v_s": Field(REAL, 1e-3, positive, "Stribeck static transition velocity [m/s]"),
    "v_d": Field(REAL, 1e-2, positive, "Stribeck dynamic transition velocity [m/s]"),
    "k_t": Field(REAL, 1e8, positive, "elastic Coulomb tangential stiffness per element [N/m]"),
    "c_t": Field(REAL, 0.0, non_negative, "elastic Coulomb stick damping per element [N s/m]"),
    "normal": Field(str, next(iter(NORMAL_LAWS)), one_of(*NORMAL_LAWS),
                    "normal law per element: " + "; ".join(f"{name}: {e.doc}" for name, e in NORMAL_LAWS.items())),
    "cubic_share": Field(REAL, 0.3, non_negative, "share of the preload tangent from the cubic term"),
    "contact_damping": Field(list, [2e5, 1e-6], None, "[c_max per area N s/m³, depth m] (seed 004 eq. 3); "
                             "[] = none"),
    "patches": Field(list, [8, 16], None, "[n_radial, n_angular] contact elements per pad; [] = every point"),
    "attachments": Field(list, [4, 8], None, "[n_radial, n_angular] patch attachment vectors in the basis"),
    "f_cut_hz": Field(REAL, 18000.0, non_negative,
                      "modal damping of the basis above this frequency; 0 = none"),
    "zeta_cut": Field(REAL, 0.2, non_negative, "damping ratio above f_cut_hz"),
    "zeta": Field(REAL, 0.0, non_negative, "structural damping ratio on every mode of the basis"),
    "max_iterations": Field(int, 30, positive, "Newton iterations per step"),
    "event_limit": Field(int, 0, non_negative, "adaptive: contact/stick events a step may hold before it "
                         "is halved (a Newton failure always halves)"),
    "amplitude": Field(REAL, 1e-3, positive, "initial push along the most unstable mode [× static closure]"),
    "record_every": Field(int, 10, positive, "record every k steps"),
    "checkpoint_every": Field(int, 20000, non_negative, "checkpoint every k steps (0 = at the end only)"),
    "snapshots": Field(int, 0, non_negative, "displacement fields Φ(q − q_static) written to "
                       "transient_snapshots.vtu/.xdmf, evenly over the last snapshot_window (0 = none)"),
    "snapshot_window": Field(REAL, None, positive, "time span of the snapshots [s]; not set: the whole run",
                             unset=0),
}


def friction_law(a: dict, mu: float):
    """The friction law of analyses.transient (``mu``: the scene's |μ|, used when mu_s/mu_d are not set)."""
    return FRICTION_LAWS[a.friction].make(mu, a.mu_s, a.mu_d, a.v_s, a.v_d, a.k_t, a.c_t)


def integrator_options(a: dict) -> dict:
    """The :class:`~fem_squeal.reduced.transient.NewmarkHHT` options of analyses.transient ``a``."""
    return {k: a[k] for k in ("alpha", "rtol", "tangent", "adaptive", "max_iterations", "event_limit")}


def brake_model(rm, a: dict):
    """(dynamic model, integrator, steady-sliding state) of analyses.transient ``a`` on the reduced model."""
    cd = a.contact_damping or [0.0, np.inf]
    dm = from_reduced(rm, omega=a.omega, cubic_share=a.cubic_share, c_max=cd[0], depth=cd[1],
                      patches=tuple(a.patches) if a.patches else None,
                      friction=friction_law(a, abs(rm.mu0)), f_cut=a.f_cut_hz or None, zeta_cut=a.zeta_cut,
                      normal=a.normal, zeta=a.zeta)
    integ = NewmarkHHT(dm, a.dt, **integrator_options(a))
    qs = integ.steady_sliding(rm.q_static)
    return dm, integ, qs


def most_unstable(integ, qs: np.ndarray, band) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Tangent CEA at steady sliding: (λ, shapes, in-band-unstable mask, index of the largest Re λ)."""
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


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """The transient of the reduced brake, integrated by rank 0 with one BLAS thread."""
    with single_threaded():
        return _stage_transient(ctx, work, timings)


def _stage_transient(ctx, work: Path, timings: dict) -> dict[str, Any]:

    a = ctx.scene.analyses["transient"]
    band = tuple(ctx.scene.analyses["reduced"].band_hz)
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
        push = a.amplitude * closure / abs(d)   # it so that the probe element starts at its largest closure
        lam_y = lam[i] if i >= 0 else lam[int(np.argmax(lam.real))]   # the eigenvalue of y
        q0, v0 = qs + (push * y).real, (push * lam_y * y).real
        run_dir = ctx.cache.root / f".run-transient-{ctx.keys['transient']}"
        resume = (run_dir / "checkpoint.npz").exists()
        if resume:
            say(f"[fem_squeal] transient: resuming from the checkpoint in {run_dir}")
        t1 = time.perf_counter()
        res = run_transient(dm, q0, v0, a.t_end, a.dt, record_every=a.record_every, folder=run_dir,
                            checkpoint_every=a.checkpoint_every, resume=resume, progress=True,
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
                        title=f"{ctx.scene.title}: closure of the most active contact element",
                        label="closure [µm]")
        if a.snapshots:   # kept in the cache; published unless --no-fields
            write_transient_snapshots(ctx, work, a, res, qs)
        timings["transient"] = time.perf_counter() - t0
        out = {"basis": dm.size, "contact_elements": sum(c.size for c in dm.contacts), "steps": st["n_steps"],
               "steps_computed": st["steps"],
               "dt": a.dt, "t_end": a.t_end, "wall_s": wall, "ms_per_step": 1e3 * wall / max(st["steps"], 1),
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
    with np.load(ctx.entry("reduced") / "basis_field.npz") as f:
        field = {k: f[k] for k in f.files}
    window = a.snapshot_window or float(res.t[-1] - res.t[0])
    wanted = np.linspace(res.t[-1] - window, res.t[-1], a.snapshots)
    idx = np.unique(np.abs(res.t[None, :] - wanted[:, None]).argmin(axis=1))
    write_snapshots(work / "transient_snapshots", field, res.t[idx], res.q[idx], qs)
    ctx.say(f"[fem_squeal] transient: {len(idx)} snapshots from t = {res.t[idx[0]] * 1e3:.3f} ms to "
            f"{res.t[idx[-1]] * 1e3:.3f} ms in transient_snapshots.vtu/.xdmf")


def check(scene: dict, volumes) -> None:
    """The nonlinear-study checks, dt < t_end, the snapshot window inside the run, v_d > v_s."""
    check_contact_study(scene, "transient")
    t = scene.analyses["transient"]
    if t.dt >= t.t_end:
        raise SceneError(f"analyses.transient.dt: must be < t_end = {t['t_end']} (got {t['dt']})")
    if t.snapshot_window is not None and t.snapshot_window > t.t_end:
        raise SceneError(f"analyses.transient.snapshot_window: must be <= t_end = {t.t_end} "
                         f"(got {t.snapshot_window})")
    if t.friction == "stribeck" and t.v_d <= t.v_s:
        raise SceneError(f"analyses.transient.v_d: must be > v_s = {t['v_s']} (got {t['v_d']})")


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "transient" not in res:
        return ""
    t = res["transient"]
    return (f"<h2>Transient</h2><p>{t['steps']} steps of {_num(t['dt'])} s on {t['basis']} vectors and "
               f"{t['contact_elements']} contact elements in {_num(t['wall_s'])} s ({_num(t['ms_per_step'])} "
               f"ms/step); energy balance {_num(t['energy_leak'])}; unstable at steady sliding: "
               + (", ".join(f"{u['freq_hz']:.0f} Hz ({u['real_part']:.0f}/s)"
                            for u in t["steady_sliding_unstable"]) or "none") + "</p>")


STAGE = Stage("transient", ("reduced",), run, "nonlinear transient of the reduced model", section=SECTION,
              check=check, report=report, fields=True,
              inputs=lambda scene, spec: {"transient": scene.analyses["transient"],
                                          "band": scene.analyses["reduced"].band_hz})
