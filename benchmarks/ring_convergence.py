"""Ring (seed 003) time against error: 4 mesh sizes each for P2 on curved and on straight-sided
tetrahedra and for P1, plus a reference (P2 curved, 314k DOFs).

Each case runs in a fresh process (so that peak memory is per case) and reports DOFs, wall time
split into mesh / assembly / eigensolve, peak RSS, the largest frequency error and the largest
growth-rate error over the unstable pairs k = 2..6, both against the finest P2 run.

    .venv/bin/python benchmarks/ring_convergence.py [--ranks 2] [--quick]

Writes benchmarks/out/ring_convergence_<ranks>ranks[_quick].md (Markdown table), .json and .png
(error against wall time).
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


def run_case(degree: int, mesh_size: float, order: int | None = None) -> dict:
    from mpi4py import MPI

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.descriptors import CircumferentialBasis
    from fem_squeal.fe.eigen import solve_complex_modes

    comm = MPI.COMM_WORLD
    order = degree if order is None else order
    scene = load_scene(ROOT / "scenes" / "ryzhik_ring.toml",
                       [f"geometry.mesh_size={mesh_size}", f"discretisation.degree={degree}",
                        f"geometry.order={order}"])
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
    return {"degree": degree, "order": order, "mesh_size": mesh_size, "ranks": comm.size,
            "dofs": ops.V.dofmap.index_map.size_global * 3, "t_mesh": t1 - t0, "t_assembly": t2 - t1,
            "t_eig": t3 - t2, "t_total": t3 - t0, "peak_rss_mb_per_rank": rss, "unstable": unstable}


def spawn(degree: int, mesh_size: float, ranks: int, order: int | None = None) -> dict:
    return casework.spawn(__file__, [str(degree), str(mesh_size), str(degree if order is None else order)], ranks)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs=3)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--quick", action="store_true", help="two meshes per degree, coarse reference (smoke)")
    a = ap.parse_args()
    if a.case:
        casework.report(run_case(int(a.case[0]), float(a.case[1]), int(a.case[2])))
        return
    # (degree, mesh size, geometry order): P2 on curved and on straight-sided tetrahedra, P1
    cases = [(2, h, 2) for h in P2_SIZES] + [(2, h, 1) for h in P2_SIZES] + [(1, h, 1) for h in P1_SIZES]
    ref_case = (*REF, 2)
    if a.quick:
        cases, ref_case = [(2, 0.004, 2), (2, 0.0025, 2), (2, 0.0025, 1), (1, 0.002, 1)], (2, 0.0015, 2)
    ref = spawn(ref_case[0], ref_case[1], a.ranks, ref_case[2])
    rows = [spawn(d, h, a.ranks, o) for d, h, o in cases] + [ref]
    lines = [f"Ring, seed 003 (R 0.05, b 0.005, h 0.004; kn 1e10, mu 0.3); {a.ranks} rank(s); reference: "
             f"P{ref_case[0]} at {ref_case[1]} m ({ref['dofs']} DOFs). Errors: max over the unstable pairs "
             "k = 2..6.", "",
             "| P | geometry | mesh size [m] | DOFs | mesh [s] | assembly [s] | eigensolve [s] | total [s] | "
             "peak RSS/rank [MB] | freq error | growth-rate error |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        fe, ge = [], []
        for k, (re, im) in r["unstable"].items():
            rr, ri = ref["unstable"][k]
            fe.append(abs(im / ri - 1))
            ge.append(abs(re / rr - 1))
        full = len(r["unstable"]) == 5
        ferr = f"{max(fe):.2e}" if full else f"{max(fe):.2e} (k={sorted(r['unstable'])})" if fe else "n/a"
        gerr = f"{max(ge):.2e}" if full else f"{max(ge):.2e}" if ge else "n/a"
        geo = "curved" if r["order"] == 2 else "straight"
        lines.append(f"| {r['degree']} | {geo} | {r['mesh_size']} | {r['dofs']} | {r['t_mesh']:.2f} | "
                     f"{r['t_assembly']:.2f} | {r['t_eig']:.2f} | {r['t_total']:.2f} | "
                     f"{r['peak_rss_mb_per_rank']:.0f} | {ferr} | {gerr} |")
    casework.save("ring_convergence", lines, rows, a.ranks, a.quick)
    _plot(rows, ref, a.ranks, a.quick)


def _plot(rows: list[dict], ref: dict, ranks: int, quick: bool) -> None:
    from fem_squeal.app.plots import pyplot

    plt = pyplot()

    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for (deg, order), mark in (((2, 2), "o-"), ((2, 1), "s--"), ((1, 1), "^:")):
        sel = [r for r in rows if r["degree"] == deg and r["order"] == order and r is not ref
               and len(r["unstable"]) == 5]
        if not sel:
            continue
        lab = f"P{deg} {'curved' if order == 2 else 'straight'}"
        for j, key in enumerate((1, 0)):   # frequency, growth rate
            err = [max(abs(r["unstable"][k][key] / ref["unstable"][k][key] - 1) for k in r["unstable"])
                   for r in sel]
            ax[j].loglog([r["t_total"] for r in sel], err, mark, label=lab)
    for j, what in enumerate(("frequency", "growth rate")):
        ax[j].set_xlabel("wall time [s] (mesh + assembly + CEA)")
        ax[j].set_ylabel(f"max relative {what} error, k = 2..6")
        ax[j].legend()
    fig.suptitle(f"Ring CEA, {ranks} rank(s)")
    fig.tight_layout()
    casework.save_plot(fig, "ring_convergence", ranks, quick)


if __name__ == "__main__":
    main()
