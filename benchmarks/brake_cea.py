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

    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

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


def match(ref: list, got: list, window: float = 0.02) -> dict[int, int]:
    """One-to-one match of unstable modes [freq, Re λ, ND] to the reference's: same nodal diameter,
    frequencies within ``window``, closest pairs first.  Returns {reference index: index in got}."""
    pairs = sorted((abs(g[0] / r[0] - 1), i, j) for i, r in enumerate(ref) for j, g in enumerate(got)
                   if g[2] == r[2] and abs(g[0] / r[0] - 1) <= window)
    out: dict[int, int] = {}
    for _, i, j in pairs:
        if i not in out and j not in out.values():
            out[i] = j
    return out


def tables(rows: list[dict], ranks: int) -> list[str]:
    """The timing table, the accuracy summary and the per-mode table, against the finest P2 curved mesh."""
    import numpy as np

    ref = min((r for r in rows if r["degree"] == 2 and r["order"] == 2), key=lambda r: r["mesh_size"])
    name = lambda r: (f"P{r['degree']}{'' if r['order'] == 2 else ' straight'} {r['mesh_size']} m"  # noqa: E731
                      f"{', matching' if r['matching'] else ''}")
    lines = [f"Brake corner CEA (scene defaults, 0-10 kHz, mu 0.4), {ranks} rank(s).", "",
             "| P | geometry | mesh size [m] | pad/disc mesh | DOFs | mesh [s] | assembly [s] | interfaces [s] | "
             "preload [s] | "
             "eigensolve [s] | total [s] | peak RSS/rank [MB] | modes | unstable |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t = r["timings"]
        asm = t["assembly"] - t["interface_operators"]
        geo = "curved" if r["order"] == 2 else "straight"
        pads = "matching" if r["matching"] else "non-matching"
        lines.append(f"| {r['degree']} | {geo} | {r['mesh_size']} | {pads} | "
                     f"{r['dofs']} | "
                     f"{t['mesh']:.1f} | {asm:.1f} | {t['interface_operators']:.1f} | {t['preload']:.1f} | "
                     f"{t['cea']:.1f} | {_total(r):.1f} | {r['peak_rss_mb_per_rank']:.0f} | {r['n_modes']} | "
                     f"{len(r['unstable'])} |")
    lines += ["", f"Accuracy against the {len(ref['unstable'])} unstable modes of the finest mesh ({ref['dofs']} "
              "DOFs), matched one to one (same nodal diameter, frequency within 2 %):", "",
              "| mesh | DOFs | total [s] | unstable modes found | largest frequency error | "
              "median growth-rate error |", "|---|---|---|---|---|---|"]
    for r in rows:
        if r is ref:
            continue
        m = match(ref["unstable"], r["unstable"])
        fe = [abs(r["unstable"][j][0] / ref["unstable"][i][0] - 1) for i, j in m.items()]
        ge = [abs(r["unstable"][j][1] / ref["unstable"][i][1] - 1) for i, j in m.items()]
        lines.append(f"| {name(r)} | {r['dofs']} | {_total(r):.1f} | {len(m)} of {len(ref['unstable'])} | "
                     + (f"{max(fe):.1e} | {np.median(ge):.1e} |" if m else "— | — |"))
    lines += ["", "Unstable modes (Re λ > 0): frequency [Hz] / growth rate Re λ [1/s]; relative differences to "
              "the finest mesh in brackets.", ""]
    lines += ["| ND | " + " | ".join(name(r) for r in rows) + " |", "|" + "---|" * (len(rows) + 1)]
    found = [match(ref["unstable"], r["unstable"]) for r in rows]
    for i, (f_ref, re_ref, nd) in enumerate(ref["unstable"]):
        cells = []
        for r, m in zip(rows, found):
            if i not in m:
                cells.append("—")
                continue
            f, re, _ = r["unstable"][m[i]]
            diff = "" if r is ref else f" ({f / f_ref - 1:+.1e} / {re / re_ref - 1:+.1e})"
            cells.append(f"{f:.1f} / {re:.1f}{diff}")
        lines.append(f"| {nd} | " + " | ".join(cells) + " |")
    return lines


def _total(r: dict) -> float:
    return sum(r["timings"][k] for k in ("mesh", "assembly", "preload", "cea"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs=4)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="two coarse meshes (smoke)")
    ap.add_argument("--tables-only", action="store_true", help="rebuild the tables from the saved JSON rows")
    a = ap.parse_args()
    if a.case:
        casework.report(run_case(a.case[0], bool(int(a.case[1])), int(a.case[2]), int(a.case[3])))
        return
    if a.tables_only:
        import json

        rows = json.loads(casework.out_path("brake_cea", a.ranks, a.quick, "json").read_text())
    else:
        rows = [spawn(h, m, a.ranks, d, o) for h, m, d, o in (QUICK if a.quick else CASES)]
    casework.save("brake_cea", tables(rows, a.ranks), rows, a.ranks, a.quick)


if __name__ == "__main__":
    main()
