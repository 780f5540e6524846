"""Stability map, sensitivities and robustness of a model given as matrices, on 1 and on 2 ranks: the
modal basis is built on the whole matrices with SciPy on one rank and distributed with PETSc/SLEPc on
two (:mod:`fem_squeal.fe.matrix_basis`); the row compares the two runs (the map's eigenvalues, dλ/dp,
the Monte Carlo's growth rates: the largest relative difference) and gives each run's basis and study
times, the reduced model's check against the full sparse CEA (map points, spot samples) and the
sensitivities' difference to central differences of full sparse CEAs.

    .venv/bin/python benchmarks/matrix_studies.py          # the 48-DOF stand-in, W and s (scale of KR)
    .venv/bin/fem-squeal export scenes/brake_corner_cea.toml out/brake_matrices --set geometry.mesh_size=0.016
    .venv/bin/python benchmarks/matrix_studies.py --scene out/brake_matrices/scene.toml --parameters mu E_disc \\
        --ranges 0.3 0.5 1.1e11 1.4e11 --band 500 5000 --modes 40

Writes benchmarks/out/matrix_studies_<scene>.md and .json.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
STAND_IN = ROOT / "scenes" / "matrices_brake.toml"


def stand_in_scene(folder: Path) -> Path:
    """scenes/matrices_brake.toml with absolute paths and K = K1 + s KR + (W² − 1) KGEO (s in [0.8, 1.2])."""
    text = STAND_IN.read_text().replace('"matrices/', f'"{ROOT}/scenes/matrices/')
    text = text.replace('K = "K1 + KR + (W**2 - 1)*KGEO"', 'K = "K1 + s*KR + (W**2 - 1)*KGEO"')
    text = text[:text.index("[analyses.real_modes]")]
    text += "[matrices.parameters.s]\nvalue = 1.0\nrange = [0.8, 1.2]\n"
    path = folder / "stand_in.toml"
    path.write_text(text)
    return path


def studies(params: list[str], ranges: list[float], band: list[float], modes: int, n: int, samples: int) -> str:
    """The [analyses.map], [analyses.sensitivity] and [analyses.robustness] sections."""
    common = f"basis_modes = {modes}\nband_hz = [{band[0]}, {band[1]}]\n"
    rng = {p: (ranges[2 * i], ranges[2 * i + 1]) for i, p in enumerate(params)}
    axes = ", ".join(f"{p} = [{lo!r}, {hi!r}]" for p, (lo, hi) in rng.items())
    text = (f"\n[analyses.map]\nparameters = {json.dumps(params)}\nn = {n}\ncheck_points = 2\nn_bands = 4\n"
            f"ranges = {{ {axes} }}\n" + common)
    text += (f"\n[analyses.sensitivity]\nmodes = \"band\"\nfull = true\nparameters = {json.dumps(params)}\n"
             + common)
    text += f"\n[analyses.robustness]\nn_samples = {samples}\nspot_checks = 2\n" + common
    for p, (lo, hi) in rng.items():
        text += f"parameters.{p} = {{ distribution = \"uniform\", lower = {lo!r}, upper = {hi!r} }}\n"
    return text


def run(scene: Path, out: Path, ranks: int) -> tuple[dict, float]:
    cmd = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(out / "cache"), "--log-level", "warning",
           "run", str(scene), "-o", str(out / "out"), "--no-report", "--no-fields"]
    if ranks > 1:
        cmd = [shutil.which("mpirun"), "-n", str(ranks), "--oversubscribe"] + cmd
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT),
           "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    if p.returncode:
        raise SystemExit(p.stdout[-3000:] + p.stderr[-3000:])
    return json.loads((out / "out" / "results.json").read_text()), time.perf_counter() - t


def compare(a_dir: Path, b_dir: Path, a: dict, b: dict) -> dict:
    """The largest relative differences of 2 ranks to 1: map eigenvalues, dλ/dp, growth rates."""
    ma, mb = (np.load(d / "out" / "stability_map.npz") for d in (a_dir, b_dir))
    la, lb = np.sort_complex(ma["eigenvalues"], ), np.sort_complex(mb["eigenvalues"])
    d_map = float(np.max(np.abs(la - lb) / np.abs(la)))
    d_sens = 0.0
    lb_modes = np.array([r["real_part"] + 2j * np.pi * r["freq_hz"] for r in b["sensitivity"]])
    assert len(lb_modes) == len(a["sensitivity"])
    for ra in a["sensitivity"]:     # paired by eigenvalue: a coupled pair has one frequency (its order: a tie)
        rb = b["sensitivity"][int(np.argmin(np.abs(lb_modes - (ra["real_part"] + 2j * np.pi * ra["freq_hz"]))))]
        for p, v in ra["d_real_part"].items():
            if v is None:
                continue
            da, db = complex(v, ra["d_freq_hz"][p]), complex(rb["d_real_part"][p], rb["d_freq_hz"][p])
            d_sens = max(d_sens, abs(da - db) / abs(da))
    ga, gb = (np.load(d / "out" / "robustness.npz")["max_growth"] for d in (a_dir, b_dir))
    scale = np.max(np.abs(la))
    return {"map_eigenvalues": d_map, "d_lambda": d_sens, "max_growth": float(np.max(np.abs(ga - gb)) / scale),
            "same_map_counts": bool(np.array_equal(ma["total"], mb["total"])),
            "same_probability": a["robustness"]["probability"] == b["robustness"]["probability"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", type=Path, help="a [matrices] scene (default: the 48-DOF stand-in)")
    ap.add_argument("--parameters", nargs="+", default=["s", "W"])
    ap.add_argument("--ranges", nargs="+", type=float, default=[0.8, 1.2, 0.5, 3.0])
    ap.add_argument("--band", nargs=2, type=float, default=[100.0, 1000.0])
    ap.add_argument("--modes", type=int, default=16)
    ap.add_argument("--n", type=int, default=21, help="map values per axis")
    ap.add_argument("--samples", type=int, default=1000)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="matrix_studies_"))
    base = args.scene.resolve() if args.scene else stand_in_scene(work)
    text = base.read_text()
    text = text[:text.index("[analyses.")] if "[analyses." in text else text
    scene = base.parent / f"_studies_{base.stem}.toml"
    scene.write_text(text + studies(args.parameters, args.ranges, args.band, args.modes, args.n, args.samples))
    try:
        runs = {}
        for ranks in (1, 2):
            runs[ranks] = run(scene, work / f"r{ranks}", ranks)
    finally:
        scene.unlink()
    (one, _), (two, _) = runs[1], runs[2]
    diff = compare(work / "r1", work / "r2", one, two)
    sens = [v for r in one["sensitivity"] for v in r.get("full", {}).get("rel_difference", {}).values()
            if v is not None]
    rows = []
    for ranks, (res, wall) in runs.items():
        t = res["timings_s"]
        rows.append({"ranks": ranks, "dofs": res["matrices"]["dofs"], "basis": res["map_reduction"]["basis"],
                     "size": res["map_reduction"]["size"],
                     "built_on": res["map_reduction"].get("built_on", "rank 0"),
                     "basis_s": t.get("map_reduction"), "map_s": t.get("map"), "sensitivity_full_s":
                     t.get("sensitivity_full"), "robustness_s": t.get("robustness"), "wall_s": wall,
                     "map_check": res["map_reduction"]["max_rel_error"],
                     "spot_check": res["robustness_reduction"]["max_rel_error"],
                     "p_unstable": res["robustness"]["probability"]["p"]})
    name = base.stem if args.scene is None else base.parent.name
    out = {"scene": str(base), "parameters": args.parameters, "rows": rows, "two_vs_one": diff,
           "sensitivity_vs_central_differences": max(sens) if sens else None}
    (ROOT / "benchmarks" / "out").mkdir(exist_ok=True)
    (ROOT / "benchmarks" / "out" / f"matrix_studies_{name}.json").write_text(json.dumps(out, indent=1))
    md = [f"# Studies of a model given as matrices: {name} ({rows[0]['dofs']} DOFs), parameters "
          f"{', '.join(args.parameters)}", "",
          "| ranks | basis | size | built on | basis [s] | map [s] | full FD [s] | MC [s] | wall [s] | "
          "map check | spot check | P(unstable) |", "|" + "---|" * 12]
    md += [f"| {r['ranks']} | {r['basis']} | {r['size']} | {r['built_on']} | {r['basis_s']:.2f} | "
           f"{r['map_s']:.2f} | {r['sensitivity_full_s']:.2f} | {r['robustness_s']:.2f} | {r['wall_s']:.1f} | "
           f"{r['map_check']:.1e} | {r['spot_check']:.1e} | {r['p_unstable']:.4f} |" for r in rows]
    md += ["", "2 ranks against 1: " + ", ".join(f"{k} {v:.1e}" if isinstance(v, float) else f"{k} {v}"
                                                  for k, v in diff.items()),
           f"Reduced dλ/dp against central differences of full sparse CEAs: worst relative difference "
           f"{out['sensitivity_vs_central_differences']:.1e}"]
    (ROOT / "benchmarks" / "out" / f"matrix_studies_{name}.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
