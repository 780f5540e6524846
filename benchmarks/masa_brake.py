"""MASA cost and accuracy on the reduced brake (issue 5 benchmark; seed 000 Table 1).

    python benchmarks/masa_brake.py REDUCED_MODEL.npz [--quick]

REDUCED_MODEL.npz is the reduced brake written by ``demos/masa_brake.py`` (out/masa_brake/).
The instabilities are collected from the CEA at equilibrium for sign(v)μ = 0.3, 0.4, … (one
static equilibrium each, as the seed's one superelement per μ) until there are 30; each is swept
over 100 amplitudes from 0 to 5× the amplitude of its first contact loss (measured on the
contact points).  Tables:

1. 30 × 100 on 8 × 16 patches per pad (256 contact elements): with and without the sweep
   break, on 1 and 2 ranks (seed: RM104 5 h 24 min, 3 h 06 min with the break);
2. cost and stationary amplitudes against the AFT elements (4 × 8, 8 × 16, 16 × 32 patches,
   every quadrature point), the points being the reference;
3. cost of one state matrix against the basis size (dense eigenvalues of K + J + K₁).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from casework import report, save, spawn  # noqa: E402

N_INST, N_AMP, AMP_MAX = 30, 100, 5.0
MUS = [0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]


def _targets(rm, patches):
    from fem_squeal.reduced.masa import MasaProblem, from_reduced, static_equilibrium
    from fem_squeal.reduced.model import MU

    groups, total = [], 0
    for mu in MUS:
        pts = from_reduced(rm, {MU: mu}, cubic_share=0.3)
        eq = static_equilibrium(pts, rm.q_static)
        ref = MasaProblem(pts, eq, (0.0, 10000.0))
        targets = ref.instabilities()[: N_INST - total]
        model = pts if patches is None else from_reduced(rm, {MU: mu}, cubic_share=0.3, patches=patches)
        prob = MasaProblem(model, eq, (0.0, 10000.0))
        amps = np.array([np.linspace(0, AMP_MAX * ref.loss_amplitude(t), N_AMP) for t in targets])
        groups.append((mu, prob, targets, amps))
        total += len(targets)
        if total >= N_INST:
            break
    return groups


def case(path: str, patches: str, brk: str) -> None:
    from mpi4py import MPI

    from fem_squeal.reduced.masa import run_masa
    from fem_squeal.reduced.model import ReducedModel
    from fem_squeal.util.blas import limit_threads_for

    comm = MPI.COMM_WORLD
    limit_threads_for(comm)
    rm = ReducedModel.load(path)
    pt = None if patches == "points" else tuple(int(v) for v in patches.split("x"))
    t = time.perf_counter()
    groups = _targets(rm, pt)
    t_setup = time.perf_counter() - t
    comm.barrier()
    t = time.perf_counter()
    steps, stationary, n_inst = 0, [], 0
    for mu, prob, targets, amps in groups:
        for r in run_masa(prob, targets, amps, sweep_break=brk == "1", comm=comm):
            steps += r.steps
            stationary.append([mu, r.freq_hz, r.stationary])
            n_inst += 1
    seconds = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
    report({"patches": patches, "break": brk == "1", "ranks": comm.size, "instabilities": n_inst,
            "elements": groups[0][1].n_elements, "basis": rm.size, "steps": steps, "seconds": seconds,
            "setup_seconds": t_setup, "stationary": stationary})


def eig_cost(m: int, reps: int = 20) -> float:
    from fem_squeal.reduced.eigensolve import quadratic_eigs
    from fem_squeal.util.blas import limit_threads

    limit_threads(1)
    rng = np.random.default_rng(0)
    K = np.diag(np.linspace(1e6, 4e9, m)) + 1e5 * rng.normal(size=(m, m))
    t = time.perf_counter()
    for _ in range(reps):
        quadratic_eigs(K)
    return (time.perf_counter() - t) / reps


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--case":
        case(*sys.argv[2:5])
        return
    path = sys.argv[1]
    quick = "--quick" in sys.argv
    script = str(Path(__file__).resolve())
    rows = []
    lines = ["## 1. 30 instabilities × 100 amplitude steps, 8 × 16 patches per pad", "",
             "| ranks | sweep break | instabilities | contact elements | basis | state matrices | MASA [s] |",
             "|---|---|---|---|---|---|---|"]
    for ranks in (1, 2):
        for brk in ("0", "1"):
            r = spawn(script, [path, "8x16", brk], ranks)
            rows.append(r)
            lines.append(f"| {ranks} | {'yes' if r['break'] else 'no'} | {r['instabilities']} | {r['elements']} | "
                         f"{r['basis']} | {r['steps']} | {r['seconds']:.2f} |")
    lines += ["", "## 2. AFT elements: cost (2 ranks, no break) and stationary amplitudes against the points",
              "", "| elements | count | MASA [s] | max rel. change of stationary amplitudes vs points |",
              "|---|---|---|---|"]
    per = {}
    for patches in (("4x8", "8x16") if quick else ("4x8", "8x16", "16x32", "points")):
        per[patches] = spawn(script, [path, patches, "0"], 2)
        rows.append(per[patches])
    ref = per.get("points", per[list(per)[-1]])
    for name, r in per.items():
        errs = [abs(a - b) / b for (_, _, sa), (_, _, sb) in zip(r["stationary"], ref["stationary"])
                for a, b in zip(sa, sb) if len(sa) == len(sb)]
        counts = sum(len(s) for _, _, s in r["stationary"])
        lines.append(f"| {name} | {r['elements']} | {r['seconds']:.2f} | "
                     f"{max(errs) if errs else float('nan'):.1e} ({counts} stationary amplitudes) |")
    lines += ["", "## 3. One dense state-matrix eigensolve (undamped: eig of the m × m K + J + K₁), 1 thread",
              "", "| basis m | seconds |", "|---|---|"]
    for m in (100, 200, 300, 400):
        t = eig_cost(m)
        rows.append({"m": m, "eig_seconds": t})
        lines.append(f"| {m} | {t * 1e3:.1f} ms |")
    save("masa_brake", lines, rows, 2, quick)


if __name__ == "__main__":
    main()
