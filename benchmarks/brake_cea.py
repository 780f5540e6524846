"""Brake corner CEA: wall time, memory and mesh convergence of the unstable modes.

Each case runs ``scenes/brake_corner_cea.toml`` in a fresh process (peak memory per case) and reports
DOFs, the wall time split into mesh / assembly (volume forms) / interface operators / preload /
eigensolve, the peak RSS per rank, and the unstable modes.  The unstable modes of each mesh are
matched to those of the finest mesh (nearest frequency with the same disc nodal diameter) and
their frequency and growth-rate differences are tabulated.

    .venv/bin/python benchmarks/brake_cea.py [--ranks 2] [--quick]

Writes benchmarks/out/brake_cea_<ranks>ranks.md and .json.
"""
from __future__ import annotations

import argparse
import resource
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
# (mesh size, matching pad/disc meshes, degree, geometry order)
CASES = [("0.012", False, 2, 2), ("0.008", False, 2, 2), ("0.008", True, 2, 2), ("0.008", False, 2, 1),
         ("0.008", False, 1, 1), ("0.004", False, 1, 1), ("0.00615", False, 2, 2)]
QUICK = [("0.016", False, 2, 2), ("0.012", False, 2, 2), ("0.012", False, 1, 1)]


def run_case(mesh_size: str, matching: bool, degree: int = 2, order: int = 2) -> dict:
    from mpi4py import MPI

    from fem_squeal.run import run_scene
    from fem_squeal.scene import load_scene

    comm = MPI.COMM_WORLD
    scene = load_scene(ROOT / "scenes" / "brake_corner_cea.toml",
                       [f"geometry.mesh_size={mesh_size}", f"geometry.matching={str(matching).lower()}",
                        f"discretisation.degree={degree}", f"geometry.order={order}"])
    with tempfile.TemporaryDirectory() as tmp:
        tmp = comm.bcast(tmp, root=0)
        res = run_scene(scene, tmp, comm, write_fields=False, log=lambda *a, **k: None)
    rss = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, op=MPI.MAX) / 1024
    t = res["timings_s"]
    return {"mesh_size": float(mesh_size), "matching": matching, "degree": degree, "order": order,
            "ranks": comm.size, "dofs": res["model"]["dofs"],
            "timings": t, "peak_rss_mb_per_rank": rss, "n_modes": len(res["complex_modes"]),
            "unstable": [[m["freq_hz"], m["real_part"], m["nodal_diameter"]] for m in res["complex_modes"]
                         if m["unstable"]],
            "preload": {k: v["normal_force"] for k, v in res["preload"]["interfaces"].items()}}


def spawn(mesh_size: str, matching: bool, ranks: int, degree: int = 2, order: int = 2,
          env: dict[str, str] | None = None) -> dict:
    return casework.spawn(__file__, [mesh_size, str(int(matching)), str(degree), str(order)], ranks, env)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs=4)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="two coarse meshes (smoke)")
    a = ap.parse_args()
    if a.case:
        casework.report(run_case(a.case[0], bool(int(a.case[1])), int(a.case[2]), int(a.case[3])))
        return
    rows = [spawn(h, m, a.ranks, d, o) for h, m, d, o in (QUICK if a.quick else CASES)]
    ref = min((r for r in rows if r["degree"] == 2 and r["order"] == 2), key=lambda r: r["mesh_size"])
    lines = [f"Brake corner CEA (scene defaults, 0-10 kHz, mu 0.4), {a.ranks} rank(s).", "",
             "| P | geometry | mesh size [m] | pad/disc mesh | DOFs | mesh [s] | assembly [s] | interfaces [s] | "
             "preload [s] | "
             "eigensolve [s] | total [s] | peak RSS/rank [MB] | modes | unstable |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t = r["timings"]
        asm = t["assembly"] - t["interface_operators"]
        total = sum(t[k] for k in ("mesh", "assembly", "preload", "cea"))
        geo = "curved" if r["order"] == 2 else "straight"
        pads = "matching" if r["matching"] else "non-matching"
        lines.append(f"| {r['degree']} | {geo} | {r['mesh_size']} | {pads} | "
                     f"{r['dofs']} | "
                     f"{t['mesh']:.1f} | {asm:.1f} | {t['interface_operators']:.1f} | {t['preload']:.1f} | "
                     f"{t['cea']:.1f} | {total:.1f} | {r['peak_rss_mb_per_rank']:.0f} | {r['n_modes']} | "
                     f"{len(r['unstable'])} |")
    lines += ["", f"Unstable modes (Re λ > 0) against the finest mesh ({ref['dofs']} DOFs): frequency [Hz] and "
              "growth rate Re λ [1/s]; relative differences in brackets.", ""]
    head = "| ND | " + " | ".join(f"P{r['degree']}{'' if r['order'] == 2 else ' straight'} {r['mesh_size']} m"
                                  f"{', matching' if r['matching'] else ''}" for r in rows) + " |"
    lines += [head, "|" + "---|" * (len(rows) + 1)]
    for f_ref, re_ref, nd in ref["unstable"]:
        cells = []
        for r in rows:
            cand = [u for u in r["unstable"] if u[2] == nd]
            if not cand:
                cells.append("—")
                continue
            f, re, _ = min(cand, key=lambda u: abs(u[0] - f_ref))
            if abs(f / f_ref - 1) > 0.05:
                cells.append("—")
                continue
            diff = "" if r is ref else f" ({f / f_ref - 1:+.1e} / {re / re_ref - 1:+.1e})"
            cells.append(f"{f:.1f} / {re:.1f}{diff}")
        lines.append(f"| {nd} | " + " | ".join(cells) + " |")
    casework.save("brake_cea", lines, rows, a.ranks, a.quick)


if __name__ == "__main__":
    main()
