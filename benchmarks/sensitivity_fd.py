"""Full-model eigenvalue sensitivities of the brake corner against central finite differences of full CEAs.

dλ/dp = −yᴴ(λ∂C + ∂K)x / yᴴ(2λM + C)x with x the CEA's right eigenvector and y the left one (the
transposed problem at the same shift, :func:`fem_squeal.fe.eigen.solve_left_vectors`), for the
unstable modes of the brake at the nominal point, and p = μ (every frictional interface), E of the
disc, k_n of the inner pad interface and η of the inner lining (one-sided differences: η ≥ 0; the
full CEA with η is the real problem of twice the size, :func:`fem_squeal.fe.projection.full_modes`).
For each parameter and relative step h: the worst |dλ/dp − FD|·|p|/|λ| over the modes (per 100 %
of p; per unit of η), with the time of the sensitivities (one CEA + one transposed CEA for all
parameters) against the 2 CEAs per parameter and step of the differences.  The FD error falls as
h² (h for η) until round-off of the two solves (~1e-10/h) takes over.  The reduced model's
derivatives (the same modes, a basis of modes up to 2.5 × 10 kHz) are listed beside.

    mpirun -n 2 .venv/bin/python benchmarks/sensitivity_fd.py [--quick]

--quick: geometry.mesh_size = 0.016 and two steps.
Writes benchmarks/out/sensitivity_fd_<ranks>ranks[_quick].md and .json.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="coarse mesh (0.016), steps 1e-3 and 1e-4")
    ap.add_argument("--max-modes", type=int, default=4, help="at most this many unstable modes")
    args = ap.parse_args()
    from mpi4py import MPI

    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.projection import (
        ParametricOperators,
        build_basis,
        common_mu,
        full_modes,
        full_sensitivities,
        reduce,
    )
    from fem_squeal.reduced.sensitivity import sensitivities
    from fem_squeal.reduced.sweep import solve_points
    from fem_squeal.util.blas import limit_threads_for

    comm = MPI.COMM_WORLD
    limit_threads_for(comm)
    scene, spec, ops, pre = casework.linearised_brake(comm, args.quick)
    mu0 = common_mu(spec)
    par = ParametricOperators(ops, spec, mu0, ["disc", "lining_inner"], preload=pre)
    band = (500.0, 10000.0)
    names = ["mu", "E.disc", "kn.pad_inner", "eta.lining_inner"]
    nominal = {"mu": mu0, "E.disc": par.E0["disc"], "kn.pad_inner": par.contacts["pad_inner"][0].kn,
               "eta.lining_inner": 0.0}

    K, C = par.matrices({})
    cm = solve_complex_modes(K, ops.M, C, scene["analyses"]["cea"]["n_modes"], 5000.0, band_hz=band,
                             options=scene["solver"]["petsc_options"])
    lam_u = cm.eigenvalues[cm.eigenvalues.real > 1e-6 * np.abs(cm.eigenvalues)]
    lam_u = lam_u[np.argsort(-lam_u.real)][:args.max_modes]
    for A in (K, C, *cm.vectors_re, *cm.vectors_im):
        if A is not None:
            A.destroy()
    t = MPI.Wtime()
    sens = full_sensitivities(par, lam_u, names, band)
    t_sens = comm.allreduce(MPI.Wtime() - t, op=MPI.MAX)

    basis = build_basis(ops, par, 25000.0)
    model = reduce(ops, par, basis, pre)
    lam_r = solve_points(model, {})[0]
    idx = [int(np.argmin(np.abs(lam_r - s.eigenvalue))) for s in sens]
    red = {s.index: s for s in sensitivities(model, None, names, idx)}

    steps = (1e-3, 1e-4) if args.quick else (1e-2, 1e-3, 1e-4, 1e-5)
    rows = []
    for p in names:
        v = nominal[p]
        for h_rel in steps:
            h = h_rel * (abs(v) if v else 1.0)
            pairs = (h, 0.0) if p.startswith("eta.") else (h, -h)
            t = MPI.Wtime()
            worst = 0.0
            for s in sens:
                fs = 1.01 * s.eigenvalue.imag / (2 * np.pi)   # a shift off the eigenvalue
                lam = [full_modes(par, {p: v + d}, 4, fs, band_hz=band) for d in pairs]
                near = [x[np.argmin(np.abs(x - s.eigenvalue))] for x in lam]
                fd = (near[0] - near[1]) / (pairs[0] - pairs[1])
                worst = max(worst, abs(s.d_lambda[p] - fd) * (abs(v) if v else 1.0) / abs(s.eigenvalue))
            t_fd = comm.allreduce(MPI.Wtime() - t, op=MPI.MAX)
            worst_red = max(abs(s.d_lambda[p] - red[i].d_lambda[p]) * (abs(v) if v else 1.0) / abs(s.eigenvalue)
                            for s, i in zip(sens, idx))
            rows.append({"parameter": p, "value": v, "step_rel": h_rel, "fd_error": worst, "fd_seconds": t_fd,
                         "reduced_error": worst_red, "sensitivity_seconds": t_sens,
                         "derivatives": {f"{s.eigenvalue.imag / 2 / np.pi:.1f} Hz": [s.d_lambda[p].real,
                                                                                     s.d_lambda[p].imag]
                                         for s in sens}})
    modes = ", ".join(f"{s.eigenvalue.imag / 2 / np.pi:.0f} Hz (Re λ {s.eigenvalue.real:+.3g})" for s in sens)
    match = max(s.left_mismatch for s in sens)
    lines = [f"# Full-model sensitivities against central differences, brake corner "
             f"({ops.K.getSize()[0]} DOFs, {comm.size} rank(s), {len(sens)} unstable modes: {modes})",
             "", f"sensitivities of all {len(names)} parameters: {t_sens:.1f} s (one CEA, one transposed CEA); "
             f"left-vector match ≤ {match:.1e}; reduced basis {model.size} vectors", "",
             "| parameter | step h/p | max |dλ/dp − FD|·|p|/|λ| | FD time [s] | FD/sens. time | reduced − full |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['parameter']} | {r['step_rel']:.0e} | {r['fd_error']:.2e} | {r['fd_seconds']:.1f} | "
                     f"{r['fd_seconds'] / t_sens:.1f} | {r['reduced_error']:.1e} |")
    lines.append("")
    lines.append("η: per unit η (p = 0), one-sided difference; the others per 100 % of p, central.")
    if comm.rank == 0:
        casework.save("sensitivity_fd", lines, rows, comm.size, args.quick)


if __name__ == "__main__":
    main()
