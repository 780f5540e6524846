"""Shims with a loss factor η(f) (issue 39): the reduced fixed point in frequency per mode against the full
nonlinear eigenproblem T(λ) = λ²M + λC + K + i η(|Im λ|/2π) K_part on the same mesh.

The layered test model of the unit tests (two blocks pressed together through a frictional contact,
tests/support/blocks.py; 2670 DOFs): the upper block is the "shim" with η(f) rising from 0.02 at 100 Hz to
0.3 at 2000 Hz.  The reduced model: frictionless modes below ``--cut`` Hz with the friction static
corrections (build_basis) and the loss static corrections K⁻¹ K_shim Φ.  Each band mode's reduced fixed point
(fem_squeal.reduced.loss_fixed_point) is lifted (x₀ = Φy) and the full NEP solved from it by residual
inverse iteration on the real form of twice the size (fem_squeal.fe.projection.loss_nep).  The same
comparison at a constant η = 0.1 (the linear QEP, also through loss_nep) separates the basis error from the
fixed point: the two columns agree when the fixed point adds no error of its own.

``--snapshot-eta 0.1``: the basis also holds the full band eigenvectors (Re, Im) of the linear QEP at that
constant η (a training point: the product's greedy reduced-basis step,
fem_squeal.fe.projection.snapshot_step, as analyses.reduced.loss_snapshot takes it at the tables' nominal η;
the η = 0.1 rows are then exact by construction and only the η(f) rows, η 0.04–0.08, test it).

    .venv/bin/python benchmarks/loss_factor_nep.py [--cut 3000] [--band 200 560] [--snapshot-eta 0.1]

Prints a table and writes benchmarks/out/loss_factor_nep.md.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cut", type=float, default=3000.0, help="basis cut frequency [Hz]")
    ap.add_argument("--band", type=float, nargs=2, default=[200.0, 560.0], help="band of the modes compared [Hz]")
    ap.add_argument("--snapshot-eta", type=float, default=None,
                    help="enrich the basis by the full band eigenvectors at this constant η (module docstring)")
    args = ap.parse_args()
    from mpi4py import MPI
    from support.blocks import two_blocks

    from fem_squeal.fe.assembly import assemble_operators, linearise
    from fem_squeal.fe.dense import apply, matmul_f
    from fem_squeal.fe.factorisation import LU, factor_solver
    from fem_squeal.fe.model import GroundSpring, Interface, Material, ModelSpec, Pressure
    from fem_squeal.fe.preload import solve_preload
    from fem_squeal.fe.projection import ParametricOperators, build_basis, reduce, snapshot_step
    from fem_squeal.fe.projection.loss_nep import full_loss_nep
    from fem_squeal.reduced.eigensolve import TWO_PI, quadratic_eigs
    from fem_squeal.reduced.laws.loss_factor import LossTable
    from fem_squeal.reduced.operating_matrix import LossFactors, condition_fixed_point, matrices_at

    comm = MPI.COMM_WORLD
    kn, kt, mu = 1e12, 3e9, 0.3
    t0 = time.perf_counter()
    spec = ModelSpec({"lower": Material(2e10, 0.3, 7000.0), "upper": Material(5e9, 0.25, 2500.0)},
                     clamped=("lower_bottom",),
                     interfaces=(Interface("pad", "slave", "master", "contact", kn=kn, kt=kt, mu=mu),),
                     ground_springs=(GroundSpring("upper_sides", 0.0, 1e9),),
                     pressures=(Pressure("upper_top", 1e6),))
    ops = assemble_operators(two_blocks(comm), spec, parts=True)
    pre = solve_preload(ops)
    lin = linearise(ops, pre.active)
    par = ParametricOperators(lin, spec, mu, ["lower", "upper"], preload=pre)
    basis = build_basis(lin, par, args.cut, extra=pre.u.array_r.copy()[:, None], n_start=10)
    ksp = factor_solver(lin.K, LU, "bench_loss_")            # loss static corrections K⁻¹ K_shim Φ
    KP = apply(par.K_parts["upper"], basis.Phi)
    b, z = lin.K.createVecs()
    Z = np.empty_like(KP)
    for j in range(KP.shape[1]):
        b.array[:] = KP[:, j]
        ksp.solve(b, z)
        Z[:, j] = z.array_r
    ksp.destroy()
    extra = [pre.u.array_r.copy()[:, None], Z]
    basis = build_basis(lin, par, args.cut, extra=np.column_stack(extra), n_start=10)
    model = reduce(lin, par, basis, pre)
    if args.snapshot_eta is not None:        # one greedy step: the full band eigenvectors at a training η
        model, basis, _ = snapshot_step(lin, par, model, basis, [{"eta.upper": args.snapshot_eta}],
                                        tuple(args.band), None, lambda b: reduce(lin, par, b, pre))
    setup = time.perf_counter() - t0
    n_dofs = lin.K.getSize()[0]

    rising = LossTable([100.0, 2000.0], [20.0], [[0.02, 0.3]], reference_frequency=500.0, name="shim")
    flat = LossTable([100.0, 2000.0], [20.0], [[0.1, 0.1]], name="shim")
    rows = []
    for label, table in (("η(f)", rising), ("η = 0.1", flat)):
        law = table.at_temperature(20.0)
        t = time.perf_counter()
        if table.varies_with_frequency:
            _, res = condition_fixed_point(model, {}, 1.0, LossFactors({"upper": table}, tuple(args.band),
                                                                       tol=1e-13), 20.0)
            lams, its, conv = res.eigenvalues, res.iterations, res.converged
        else:
            K, C = matrices_at(model, {"eta.upper": 0.1}, 1.0)
            lam = quadratic_eigs(K[None], None if C is None else C[None])[0]
            f = lam.imag / TWO_PI
            lams = lam[(f >= args.band[0]) & (f <= args.band[1])]
            its, conv = np.ones(lams.size, int), np.ones(lams.size, bool)
        t_red = time.perf_counter() - t
        for q, lr in enumerate(lams):
            eta = float(law(abs(lr.imag) / TWO_PI))
            K, C = matrices_at(model, {"eta.upper": eta}, 1.0)
            ls, Y = quadratic_eigs(K[None], None if C is None else C[None], vectors=True)
            y = Y[0][:, np.argmin(np.abs(ls[0] - lr))]
            x0 = matmul_f(basis.Phi, np.column_stack([y.real, y.imag]))
            t = time.perf_counter()
            full = full_loss_nep(par, {}, {"upper": law}, lr, x0[:, 0] + 1j * x0[:, 1])
            rows.append({"case": label, "f_hz": lr.imag / TWO_PI, "eta": eta, "reduced": lr,
                         "full": full.eigenvalue,
                         "rel": abs(full.eigenvalue - lr) / abs(full.eigenvalue), "fp_iterations": int(its[q]),
                         "fp_converged": bool(conv[q]), "nep_iterations": full.iterations,
                         "nep_converged": full.converged, "backward_error": full.backward_error,
                         "nep_s": time.perf_counter() - t, "reduced_s": t_red})
    snap = "" if args.snapshot_eta is None else f", with the full band eigenvectors at η = {args.snapshot_eta:g}"
    lines = [f"# Loss factor η(f) of a shim: reduced fixed point vs full NEP ({n_dofs} DOFs, reduced size "
             f"{model.size}, basis cut {args.cut:g} Hz{snap}, set-up {setup:.1f} s)", "",
             "| case | f [Hz] | η at f | reduced λ | full NEP λ | rel. diff | FP it. | NEP it. "
             "| NEP backward error |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['f_hz']:.3f} | {r['eta']:.5f} | {r['reduced']:.9e} | {r['full']:.9e} | "
                     f"{r['rel']:.1e} | {r['fp_iterations']}{'' if r['fp_converged'] else ' (not conv.)'} | "
                     f"{r['nep_iterations']}{'' if r['nep_converged'] else ' (not conv.)'} | "
                     f"{r['backward_error']:.1e} |")
    for label in ("η(f)", "η = 0.1"):
        sel = [r for r in rows if r["case"] == label]
        lines.append(f"\n{label}: max rel. diff {max(r['rel'] for r in sel):.2e} over {len(sel)} modes")
    if comm.rank == 0:
        print("\n".join(lines))
        out = ROOT / "benchmarks" / "out"
        out.mkdir(exist_ok=True)
        name = "loss_factor_nep" + ("" if args.snapshot_eta is None else "_snapshots")
        (out / f"{name}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
