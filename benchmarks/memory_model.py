"""Peak memory of the brake CEA against DOFs, ranks and MUMPS block low-rank (BLR) factorisation.

Each case runs ``scenes/brake_corner_cea.toml`` (mesh, assembly, nonlinear preload, the CEA's
non-symmetric shift-invert EPS of every mode in 0-10 kHz) in a fresh process and reports the DOFs,
the sum over the ranks of their peak RSS, the preload and eigensolve seconds, and the frequencies.
BLR (MUMPS ICNTL(35) = 2: factors stored low-rank, CNTL(7) = ε the dropping threshold) is switched on
for both factorisations of a run (the preload's Newton solves, ``preload_mat_mumps_*``, and the CEA's
K − σM, ``cea_st_mat_mumps_*``).  A BLR case is checked against the exact (full-rank) case of the same
mesh: the largest relative frequency difference over the modes (each matched to the nearest exact
frequency) and the largest eigen-residual ‖(λ²M + K)x‖/(‖K‖‖x‖), computed with the exact matrices.

Out-of-core factors (``ooc``: MUMPS ICNTL(22) = 1, files in $MUMPS_OOC_TMPDIR) are the other kind.

The memory model of ``fem_squeal/app/resources.py`` (``solve_memory(N, ranks, kind)``) is fitted here:
M = a N + b N^(4/3) per factorisation kind through two one-rank sizes (``--sizes``, default 0.011 and
0.0056: 89k and 348k DOFs); ``--check MESH_SIZE`` runs one more size to compare with the prediction;
``--from-json`` tabulates saved case lines (``--case`` output) and runs nothing.

    .venv/bin/python benchmarks/memory_model.py [--quick] [--kinds exact blr ooc] [--check 0.0075]

Writes benchmarks/out/memory_model_1ranks[_quick].md and .json.
"""
from __future__ import annotations

import argparse
import json
import re
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GIB = 2.0 ** 30


def blr_options(eps: float, refine: int = 2) -> list[str]:
    """PETSc options (scene overrides) switching MUMPS BLR on for the preload and the CEA: factors
    stored low-rank (ICNTL(35) = 2) with dropping threshold ε (CNTL(7)), and ``refine`` steps of
    iterative refinement with the exact matrix in each solve (ICNTL(10) = −refine)."""
    out = []
    for prefix in ("preload_", "cea_st_"):
        out += [f"solver.petsc_options.{prefix}mat_mumps_icntl_35=2",
                f"solver.petsc_options.{prefix}mat_mumps_cntl_7={eps:g}",
                f"solver.petsc_options.{prefix}mat_mumps_icntl_10={-refine}"]
    return out


def ooc_options() -> list[str]:
    """MUMPS out-of-core factors (ICNTL(22) = 1, files in $MUMPS_OOC_TMPDIR) for the preload and the CEA."""
    return [f"solver.petsc_options.{prefix}mat_mumps_icntl_22=1" for prefix in ("preload_", "cea_st_")]


class StagePeaks:
    """Peak resident memory [bytes] of this process per stage, sampled every 50 ms from /proc; the
    stage is taken from the runner's log lines ("stage i/n: name")."""

    def __init__(self):
        import threading

        self.stage, self.peaks, self._stop = "start", {}, threading.Event()
        self._page = resource.getpagesize()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _rss(self) -> int:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * self._page

    def _run(self) -> None:
        while not self._stop.wait(0.05):
            self.peaks[self.stage] = max(self.peaks.get(self.stage, 0), self._rss())

    def log(self, msg: str = "", *args, **kwargs) -> None:
        m = re.search(r"stage \d+/\d+: (\w+)", msg)
        if m:
            self.peaks[self.stage] = max(self.peaks.get(self.stage, 0), self._rss())
            self.stage = m.group(1)
            print(f"[memory_model] {time.strftime('%H:%M:%S')} stage {self.stage}, peak so far "
                  f"{max(self.peaks.values()) / GIB:.2f} GiB", file=sys.stderr, flush=True)

    def stop(self) -> dict[str, float]:
        self._stop.set()
        self._thread.join()
        return self.peaks


def run_case(mesh_size: str, eps: float, refine: int = 2) -> dict:
    """One CEA in this process: DOFs, peak RSS (whole run and per stage) summed over the ranks, times,
    modes (eps 0: exact in-core factorisations, eps < 0: exact out-of-core, eps > 0: BLR)."""
    from mpi4py import MPI

    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    comm = MPI.COMM_WORLD
    sets = [f"geometry.mesh_size={mesh_size}"] + (blr_options(eps, refine) if eps > 0 else
                                                   ooc_options() if eps < 0 else [])
    scene = load_scene(ROOT / "scenes" / "brake_corner_cea.toml", sets)
    peaks = StagePeaks()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = comm.bcast(tmp, root=0)
        res = run_scene(scene, tmp, comm, write_fields=False, log=peaks.log)
    stages = {k: comm.allreduce(v, op=MPI.SUM) / GIB for k, v in peaks.stop().items()}
    rss = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, op=MPI.SUM) * 1024 / GIB
    t = res["timings_s"]
    return {"mesh_size": float(mesh_size), "eps": eps, "refine": refine, "ranks": comm.size,
            "dofs": res["model"]["dofs"],
            "peak_gib": rss, "stage_peak_gib": stages, "preload_s": t["preload"], "cea_s": t["cea"],
            "freqs": [m["freq_hz"] for m in res["complex_modes"]],
            "real_parts": [m["real_part"] for m in res["complex_modes"]],
            "max_residual": max(m["residual"] for m in res["complex_modes"])}


def compare(exact: dict, other: dict) -> float:
    """Largest relative frequency difference, each mode matched to the nearest exact one."""
    f0 = np.array(exact["freqs"])
    return max(float(np.min(np.abs(f0 - f)) / f) for f in other["freqs"])


KINDS = {"exact": (0.0, 0), "blr": (1e-8, 1), "ooc": (-1.0, 0)}   # (eps, refinement steps) of each case


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs=3, metavar=("MESH_SIZE", "EPS", "REFINE"))
    ap.add_argument("--quick", action="store_true", help="two small sizes (18k, 50k DOFs)")
    ap.add_argument("--sizes", nargs=2, default=["0.011", "0.0056"], help="the two mesh sizes of the fit")
    ap.add_argument("--kinds", nargs="+", default=["exact", "blr"], choices=sorted(KINDS))
    ap.add_argument("--check", nargs="*", default=[], help="mesh sizes run to check the fitted model")
    ap.add_argument("--from-json", nargs="*", default=[], help="case results (JSON lines) instead of runs")
    a = ap.parse_args()
    if a.case:
        casework.report(run_case(a.case[0], float(a.case[1]), int(a.case[2])))
        return
    import os

    os.environ.setdefault("MUMPS_OOC_TMPDIR", tempfile.gettempdir())
    sizes = ["0.024", "0.016"] if a.quick else a.sizes
    rows = [json.loads(Path(p).read_text()) for p in a.from_json]
    have = {(r["mesh_size"], r["eps"]) for r in rows}
    for size in ([] if a.from_json else sizes + a.check):      # saved cases: tabulate only
        for kind in a.kinds:
            eps, refine = KINDS[kind]
            if (float(size), eps) not in have:
                rows.append(casework.spawn(__file__, [size, repr(eps), str(refine)], 1))
    from fem_squeal.app.resources import FILL_EXPONENT

    kind_of = {v[0]: k for k, v in KINDS.items()}
    exact = {r["mesh_size"]: r for r in rows if r["eps"] == 0}
    fits = {}
    for kind in a.kinds:
        fitted = [float(x) for x in sizes]
        pts = sorted((r["dofs"], r["peak_gib"]) for r in rows
                     if kind_of[r["eps"]] == kind and r["mesh_size"] in fitted)
        if len(pts) == 2:
            (n1, m1), (n2, m2) = pts
            b = (m2 - m1 * n2 / n1) / (n2 ** FILL_EXPONENT - n1 ** (FILL_EXPONENT - 1) * n2)
            fits[kind] = ((m1 - b * n1 ** FILL_EXPONENT) / n1, b)
    lines = ["Brake CEA with preload, one rank: peak memory (RSS; per stage from /proc), times and accuracy. "
             "blr = MUMPS ICNTL(35)=2, CNTL(7)=1e-8, one refinement step ICNTL(10)=-1; ooc = ICNTL(22)=1.", "",
             "| mesh size | DOFs | kind | peak GiB | preload peak | CEA peak | model GiB | preload s | CEA s "
             "| max Δf/f vs exact | max residual |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r["dofs"], r["eps"])):
        kind = kind_of[r["eps"]]
        fa, fb = fits.get(kind, (float("nan"), float("nan")))
        ref = exact.get(r["mesh_size"])
        df = compare(ref, r) if ref is not None else float("nan")
        st = r["stage_peak_gib"]
        lines.append(f"| {r['mesh_size']:g} | {r['dofs']} | {kind} | {r['peak_gib']:.2f} | "
                     f"{st.get('preload', 0):.2f} | {st.get('cea', 0):.2f} | "
                     f"{fa * r['dofs'] + fb * r['dofs'] ** FILL_EXPONENT:.2f} | "
                     f"{r['preload_s']:.0f} | {r['cea_s']:.0f} | {df:.1e} | {r['max_residual']:.1e} |")
    lines += ["", "Fits M = a N + b N^(4/3) [GiB] through the two sizes: " +
              "; ".join(f"{k}: a = {fa:.3e}, b = {fb:.3e}, 1.2M DOFs: "
                        f"{fa * 1.2e6 + fb * 1.2e6 ** FILL_EXPONENT:.1f} GiB" for k, (fa, fb) in fits.items())]
    casework.save("memory_model", lines, rows, 1, a.quick)


if __name__ == "__main__":
    main()
