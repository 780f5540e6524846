"""Ring (seed 003) time against error: 4 mesh sizes for P1 and P2 (curved), plus a reference.

Each case runs in a fresh process (so that peak memory is per case) and reports DOFs, wall time
split into mesh / assembly / eigensolve, peak RSS, the largest frequency error and the largest
growth-rate error over the unstable pairs k = 2..6, both against the finest P2 run.

    .venv/bin/python benchmarks/ring_convergence.py [--ranks 2] [--quick]

Writes benchmarks/out/ring_convergence.md (Markdown table) and .json.
"""
from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
P2_SIZES = [0.004, 0.003, 0.002, 0.0015]
P1_SIZES = [0.002, 0.0015, 0.001, 0.0007]
REF = (2, 0.0008)


def run_case(degree: int, mesh_size: float) -> dict:
    from mpi4py import MPI

    from fem_squeal.assembly import assemble_operators
    from fem_squeal.descriptors import CircumferentialBasis
    from fem_squeal.eigen import solve_complex_modes
    from fem_squeal.run import build_mesh
    from fem_squeal.scene import load_scene, model_spec

    comm = MPI.COMM_WORLD
    scene = load_scene(ROOT / "scenes" / "ryzhik_ring.toml",
                       [f"geometry.mesh_size={mesh_size}", f"discretisation.degree={degree}"])
    t0 = time.perf_counter()
    md = build_mesh(comm, scene)
    t1 = time.perf_counter()
    ops = assemble_operators(md, model_spec(scene))
    Kt = ops.K_total()
    t2 = time.perf_counter()
    cea = scene["analyses"]["cea"]
    cm = solve_complex_modes(Kt, ops.M, None, cea["n_modes"], 3535.0, band_hz=tuple(cea["band_hz"]))
    t3 = time.perf_counter()
    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    unstable = {}
    for lam, xr, xi in zip(cm.eigenvalues, cm.vectors_re, cm.vectors_im):
        d = basis.describe(xr, xi)
        if lam.real > 0 and d.in_plane_share > 0.99 and 2 <= d.nodal_diameter <= 6:
            unstable[d.nodal_diameter] = [lam.real, lam.imag]
    rss = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, op=MPI.MAX) / 1024
    return {"degree": degree, "mesh_size": mesh_size, "ranks": comm.size,
            "dofs": ops.V.dofmap.index_map.size_global * 3, "t_mesh": t1 - t0, "t_assembly": t2 - t1,
            "t_eig": t3 - t2, "t_total": t3 - t0, "peak_rss_mb_per_rank": rss, "unstable": unstable}


def spawn(degree: int, mesh_size: float, ranks: int) -> dict:
    return casework.spawn(__file__, [str(degree), str(mesh_size)], ranks)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs=2)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--quick", action="store_true", help="two meshes per degree, coarse reference (smoke)")
    a = ap.parse_args()
    if a.case:
        casework.report(run_case(int(a.case[0]), float(a.case[1])))
        return
    cases = [(2, h) for h in P2_SIZES] + [(1, h) for h in P1_SIZES]
    ref_case = REF
    if a.quick:
        cases, ref_case = [(2, 0.004), (2, 0.0025), (1, 0.002)], (2, 0.0015)
    ref = spawn(*ref_case, a.ranks)
    rows = [spawn(d, h, a.ranks) for d, h in cases] + [ref]
    lines = [f"Ring, seed 003 (R 0.05, b 0.005, h 0.004; kn 1e10, mu 0.3); {a.ranks} rank(s); reference: "
             f"P{ref_case[0]} at {ref_case[1]} m ({ref['dofs']} DOFs). Errors: max over the unstable pairs "
             "k = 2..6.", "",
             "| P | mesh size [m] | DOFs | mesh [s] | assembly [s] | eigensolve [s] | total [s] | "
             "peak RSS/rank [MB] | freq error | growth-rate error |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        fe, ge = [], []
        for k, (re, im) in r["unstable"].items():
            rr, ri = ref["unstable"][k]
            fe.append(abs(im / ri - 1))
            ge.append(abs(re / rr - 1))
        full = len(r["unstable"]) == 5
        ferr = f"{max(fe):.2e}" if full else f"{max(fe):.2e} (k={sorted(r['unstable'])})" if fe else "n/a"
        gerr = f"{max(ge):.2e}" if full else f"{max(ge):.2e}" if ge else "n/a"
        lines.append(f"| {r['degree']} | {r['mesh_size']} | {r['dofs']} | {r['t_mesh']:.2f} | "
                     f"{r['t_assembly']:.2f} | {r['t_eig']:.2f} | {r['t_total']:.2f} | "
                     f"{r['peak_rss_mb_per_rank']:.0f} | {ferr} | {gerr} |")
    casework.save("ring_convergence", lines, rows, a.ranks, a.quick)


if __name__ == "__main__":
    main()
