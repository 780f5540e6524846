"""Real modes on 1 against 2 ranks (issue 34): the clamped P2 disc of ``modal_peers.py``, 20 modes,
one thread per rank, each run a fresh process, repeats interleaved (the fastest kept).

Cases: 1 rank (CHOLMOD, block Lanczos); 2 ranks by default (the substructured CHOLMOD
factorisation, :mod:`fem_squeal.fe.substructured`); 2 ranks with ``real_substructure = 0`` (MUMPS,
the path before it).  Reported: read, assembly, eigensolve (factorisation + Lanczos + residuals),
end to end, the speed-up of 2 ranks over 1 on the eigensolve and end to end, and the largest
relative difference of the 20 frequencies from the 1-rank run's.

    .venv/bin/python benchmarks/real_modes_ranks.py [--sizes 0.006 0.004] [--repeats 3] [--workdir DIR]
"""
from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import modal_peers as mp  # noqa: E402

CASES = {"1 rank": (1, None), "2 ranks": (2, None), "2 ranks, MUMPS": (2, {"real_substructure": 0})}


def run(sizes: list[float], repeats: int, workdir: Path) -> list[dict]:
    rows = []
    for h in sizes:
        mesh = mp.spawn(["mesh", h, workdir, mp.N_MODES])
        s = mesh["stem"]
        scenes = {}
        for name, (ranks, opts) in CASES.items():
            f = workdir / f"{s}_{name.replace(' ', '_').replace(',', '')}.toml"
            f.write_text(mp.scene_text(f"{s}.msh", mp.N_MODES, mp.AUTO, opts))
            scenes[name] = (f, ranks)
        mp.spawn(["fem", scenes["1 rank"][0], "default"])            # warm the JIT cache
        best: dict[str, dict] = {}
        for rep in range(repeats):
            for name, (f, ranks) in scenes.items():
                r = mp.spawn(["fem", f, "default"], ranks)
                print(f"{s} #{rep} {name}: eig {r['t_eig']:.2f} s, e2e {r['t_e2e']:.2f} s ({r['solver']})",
                      file=sys.stderr, flush=True)
                if name not in best or r["t_eig"] < best[name]["t_eig"]:
                    best[name] = r
        ref = np.array(best["1 rank"]["freqs"])
        for name, r in best.items():
            rows.append({"mesh": s, "free_dofs": mesh["free_dofs"], "case": name, "solver": r["solver"],
                         "read": r["t_read"], "assembly": r["t_assembly"], "eig": r["t_eig"],
                         "factor": r["t_factor"],
                         "e2e": r["t_e2e"], "eig_speedup": best["1 rank"]["t_eig"] / r["t_eig"],
                         "e2e_speedup": best["1 rank"]["t_e2e"] / r["t_e2e"],
                         "df": float(np.max(np.abs(np.array(r["freqs"]) - ref) / ref))})
    return rows


def table(rows: list[dict]) -> str:
    out = ["| free DOFs | case | solver | read [s] | assembly [s] | eigensolve [s] (factor) | end to end [s] "
           "| eigensolve speed-up | end-to-end speed-up | max Δf/f vs 1 rank |",
           "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {r['free_dofs']} | {r['case']} | {r['solver']} | {r['read']:.2f} | {r['assembly']:.2f} | "
                   f"{r['eig']:.2f} ({r['factor']:.2f}) | {r['e2e']:.2f} | {r['eig_speedup']:.2f}× | "
                   f"{r['e2e_speedup']:.2f}× | {r['df']:.1e} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=float, nargs="+", default=[0.006, 0.004])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workdir")
    a = ap.parse_args()
    with contextlib.ExitStack() as stack:
        workdir = Path(a.workdir or stack.enter_context(tempfile.TemporaryDirectory(prefix="modes_ranks_")))
        workdir.mkdir(parents=True, exist_ok=True)
        rows = run(a.sizes, a.repeats, workdir.resolve())
    out = Path(__file__).resolve().parent / "out"
    out.mkdir(exist_ok=True)
    (out / "real_modes_ranks.json").write_text(json.dumps(rows, indent=1))
    print(table(rows))


if __name__ == "__main__":
    main()
