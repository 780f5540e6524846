"""Stress test: the contact penalty k_n over 9 decades on the ring (seed 003), 1e8 … 1e16 N/m³.

For each k_n, in a fresh process: the penalty ratio r = k_n h / C₁₁ and whether the run warns
(:mod:`fem_squeal.fe.penalty`, warning above r = 1e3); the CEA (every mode in 100–5000 Hz) with its
largest relative residual (40 modes nearest 2.5 kHz, all of the band); the condition number of
the shift-inverted operator K − σM (κ₁ by Hager's estimator, :func:`fem_squeal.fe.penalty.condition_number_1`)
and ‖K‖₁;
the number of *penalty modes* in the band (modes whose strain energy is more than half in the
penalty layer: the ring bouncing on the plates' springs, physical for a soft layer but not
part of the elastic ring's spectrum); the in-plane flutter pairs k = 2..6 (frequency and growth
rate of k = 2) and the largest change of their eigenvalues from the previous decade.

    .venv/bin/python benchmarks/stress_penalty.py [--quick] [--ranks 2]

Expected (module docstring of fem_squeal.fe.penalty): the eigenvalues saturate once r ≫ 1 (changes
O(1/r) per decade) while the condition number keeps growing ∝ k_n.
"""
from __future__ import annotations

import argparse
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
KNS = [1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16]
SHIFT_HZ = 2500.0
N_MODES = 40       # every mode of the 100–5000 Hz band, so that penalty modes cannot hide


def run_case(kn: float, mesh_size: float) -> dict:
    from mpi4py import MPI
    from petsc4py import PETSc

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.descriptors import CircumferentialBasis
    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.penalty import condition_number_1, penalty_ratios, penalty_warnings

    comm = MPI.COMM_WORLD
    scene = load_scene(ROOT / "scenes" / "ryzhik_ring.toml",
                       [f"geometry.mesh_size={mesh_size}", f"interfaces.top_plate.kn={kn}",
                        f"interfaces.bottom_plate.kn={kn}"])
    md = build_mesh(comm, scene)
    spec = model_spec(scene)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True):
        ops = assemble_operators(md, spec)
    ratios = penalty_ratios(md, spec)
    warned = bool(penalty_warnings(ratios))
    Kt = ops.K_total()
    # the penalty's own stiffness: K(k_n) − K(0) (the same sparsity: the volume forms are shared)
    scene0 = load_scene(ROOT / "scenes" / "ryzhik_ring.toml",
                        [f"geometry.mesh_size={mesh_size}", "interfaces.top_plate.kn=0",
                         "interfaces.bottom_plate.kn=0"])
    with warnings.catch_warnings(record=True):
        ops0 = assemble_operators(md, model_spec(scene0))
    Kpen = ops.K.duplicate(copy=True)
    Kpen.axpy(-1.0, ops0.K, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)

    # κ₁ of K − σM, the operator the shift-and-invert eigensolve factorises
    A = Kt.duplicate(copy=True)
    A.axpy(-(2 * np.pi * SHIFT_HZ) ** 2, ops.M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    cond = condition_number_1(A)
    normK = Kt.norm(PETSc.NormType.NORM_1)
    A.destroy()

    t1 = time.perf_counter()
    cea = scene["analyses"]["cea"]
    cm = solve_complex_modes(Kt, ops.M, None, N_MODES, SHIFT_HZ, band_hz=tuple(cea["band_hz"]),
                             max_residual=1.0)
    t2 = time.perf_counter()
    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    pairs, n_pen, shares = {}, 0, []
    for lam, xr, xi in zip(cm.eigenvalues, cm.vectors_re, cm.vectors_im):
        e_pen = _energy(Kpen, xr, xi)
        e_tot = _energy(Kt, xr, xi)
        share = e_pen / e_tot if e_tot > 0 else 0.0
        shares.append(share)
        n_pen += share > 0.5
        d = basis.describe(xr, xi)
        if lam.real > 0 and d.in_plane_share > 0.99 and 2 <= d.nodal_diameter <= 6:
            pairs[d.nodal_diameter] = [lam.real, lam.imag]
    rss = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, op=MPI.MAX) / 1024
    return {"kn": kn, "mesh_size": mesh_size, "ranks": comm.size,
            "dofs": ops.V.dofmap.index_map.size_global * 3, "ratio": max(r.ratio for r in ratios),
            "warned": warned, "cond": cond, "norm1_K": normK, "max_residual": float(np.max(cm.residuals)),
            "n_modes": len(cm.eigenvalues), "penalty_modes": int(n_pen), "penalty_shares": shares,
            "freqs_hz": list(np.asarray(cm.eigenvalues).imag / (2 * np.pi)), "unstable_pairs": pairs,
            "t_assembly_condition": t1 - t0, "t_eig": t2 - t1, "peak_rss_mb_per_rank": rss}


def _energy(K, xr, xi) -> float:
    y = K.createVecLeft()
    e = 0.0
    for x in (xr, xi):
        K.mult(x, y)
        e += x.dot(y)
    y.destroy()
    return float(e)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs=2)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--quick", action="store_true", help="coarse mesh, 4 decades")
    a = ap.parse_args()
    if a.case:
        casework.report(run_case(float(a.case[0]), float(a.case[1])))
        return
    h = 0.003 if a.quick else 0.002
    kns = [1e8, 1e11, 1e14, 1e16] if a.quick else KNS
    rows = [casework.spawn(__file__, [repr(kn), repr(h)], a.ranks) for kn in kns]
    lines = [f"Ring (seed 003), P2 curved, mesh size {h} m ({rows[0]['dofs']} DOFs), {a.ranks} rank(s). "
             "Ratio r = kn·h/C11 (warning above 1e3); κ₁ = 1-norm condition estimate of K − σM, "
             "σ = (2π·2500 Hz)²; "
             "res = largest CEA residual ‖(λ²M+K)x‖/(‖K‖‖x‖); penalty modes = modes in 100–5000 Hz with "
             "> 50 % of their strain energy in the penalty layer; Δλ = largest relative change of the k = 2..6 "
             "flutter eigenvalues from the previous row.", "",
             "| kn [N/m³] | r | warns | ‖K‖₁ | κ₁(K − σM) | res | modes in band | penalty modes | flutter pairs | "
             "k=2: f [Hz] / Re λ [1/s] | Δλ | eigensolve [s] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    prev = None
    for r in rows:
        p = {int(k): complex(*v) for k, v in r["unstable_pairs"].items()}
        dl = "–"
        if prev is not None and set(p) and set(p) == set(prev):
            dl = f"{max(abs(p[k] - prev[k]) / abs(p[k]) for k in p):.1e}"
        k2 = f"{p[2].imag / (2 * np.pi):.1f} / {p[2].real:.2f}" if 2 in p else "–"
        warns = "yes" if r["warned"] else "no"
        lines.append(f"| {r['kn']:.0e} | {r['ratio']:.2g} | {warns} | {r['norm1_K']:.1e} | "
                     f"{r['cond']:.1e} | {r['max_residual']:.1e} | {r['n_modes']} | {r['penalty_modes']} | "
                     f"{sorted(p)} | {k2} | {dl} | {r['t_eig']:.2f} |")
        prev = p
    casework.save("stress_penalty", lines, rows, a.ranks, a.quick)
    from fem_squeal.app.plots import pyplot

    plt = pyplot()

    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    kn = [r["kn"] for r in rows]
    ax[0].loglog(kn, [r["cond"] for r in rows], "o-", label="κ₁(K − σM)")
    ax[0].loglog(kn, [max(r["max_residual"], 1e-17) for r in rows], "s-", label="largest CEA residual")
    ax[0].set_xlabel("kn [N/m³]")
    ax[0].legend()
    for k in range(2, 7):
        ax[1].semilogx(kn, [r["unstable_pairs"].get(str(k), [np.nan])[0] for r in rows], "o-", label=f"k = {k}")
    ax[1].set_xlabel("kn [N/m³]")
    ax[1].set_ylabel("growth rate Re λ [1/s]")
    ax[1].legend()
    fig.tight_layout()
    casework.save_plot(fig, "stress_penalty", a.ranks, a.quick)


if __name__ == "__main__":
    main()
