"""Real modes to the projection CEA's cut (issue 36): one shift near 0 against spectrum slicing and SLEPc's
own spectrum slicing, on the same K and M, in one process (the machine is shared: compare within a run).

Runs ``scenes/brake_corner_cea.toml`` with ``geometry.mesh_size`` set, ``analyses.cea.band_hz = [0, 16000]``
and ``analyses.cea.method = "projection"`` up to the projection's real-mode stage, and there solves the
modes below its cut (cut_factor × 16 kHz) by each method asked:

- ``single``: :func:`fem_squeal.fe.projection.modes_below` as the projection calls it (one rank: CHOLMOD
  near 0 and block Lanczos with a threshold; N ranks: the shared band-centre factorisation first);
- ``sliceN``: :func:`fem_squeal.fe.eigen.slicing.sliced_modes` with N slices (MUMPS LDLᵀ per slice,
  inertia-checked);
- ``ks``: ``single`` with ``cea_projection_block_size = 0`` (Krylov–Schur on the same factorisation, its
  count grown until a mode lies above the cut: the path block Lanczos falls back to where its vectors
  do not fit the memory rule);
- ``slepcN``: SLEPc's Krylov–Schur with ``EPSSetInterval(0, λ_cut)`` (spectrum slicing) on MUMPS
  LDLᵀ with ICNTL(13) = 1 for its inertia, ``EPSKrylovSchurSetDimensions(N, 2N, N)``.

Reports seconds, modes and the largest relative difference of the eigenvalues from the first method's.

    .venv/bin/python benchmarks/real_mode_slicing.py --mesh-size 0.012 --methods single slice3 slepc40
    .venv/bin/python benchmarks/real_mode_slicing.py --mesh-size 0.00415 --methods single ks --n-start 91
    mpirun -n 2 .venv/bin/python benchmarks/real_mode_slicing.py --mesh-size 0.012 --methods single slice3

Writes benchmarks/out/real_mode_slicing_<ranks>ranks.md and .json.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


class _Reached(Exception):
    """The projection reached its real-mode stage: K, M and the cut are in ``args``."""


def operators(mesh_size: str):
    """(K, M, f_cut_hz) of the projection CEA's real-mode stage of the brake corner at ``mesh_size``."""
    from mpi4py import MPI

    import fem_squeal.fe.projection.projected_cea as pc
    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    def reached(K, M, f_cut_hz, **_):
        raise _Reached(K, M, f_cut_hz)

    scene = load_scene(ROOT / "scenes" / "brake_corner_cea.toml",
                       [f"geometry.mesh_size={mesh_size}", "analyses.cea.band_hz=[0.0, 16000.0]",
                        "analyses.cea.method=projection"])
    saved, pc.modes_below = pc.modes_below, reached
    try:
        with tempfile.TemporaryDirectory() as tmp:
            run_scene(scene, MPI.COMM_WORLD.bcast(tmp), MPI.COMM_WORLD, write_fields=False,
                      log=lambda *a, **k: None, report=False)
    except _Reached as got:
        K, M, cut = got.args
        return K.copy(), M.copy(), cut
    finally:
        pc.modes_below = saved
    raise RuntimeError("the projection did not reach its real-mode stage")


def slepc_slicing(K, M, f_cut_hz: float, nev: int, tol: float):
    """ω² of every mode in [−0.01 λ_cut, λ_cut] by SLEPc's spectrum slicing."""
    import numpy as np
    from slepc4py import SLEPc

    from fem_squeal.fe.eigen import TWO_PI
    from fem_squeal.fe.factorisation import scoped_options

    lam_cut = (TWO_PI * f_cut_hz) ** 2
    opts = {"sl_st_ksp_type": "preonly", "sl_st_pc_type": "cholesky", "sl_st_pc_factor_mat_solver_type": "mumps",
            "sl_st_mat_mumps_icntl_13": "1", "sl_st_mat_mumps_icntl_24": "1"}
    with scoped_options(opts):
        eps = SLEPc.EPS().create(K.getComm())
        eps.setOptionsPrefix("sl_")
        eps.setOperators(K, M)
        eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
        eps.setType(SLEPc.EPS.Type.KRYLOVSCHUR)
        eps.setInterval(-0.01 * lam_cut, lam_cut)
        eps.setWhichEigenpairs(SLEPc.EPS.Which.ALL)
        eps.setKrylovSchurDimensions(nev, 2 * nev, nev)
        eps.setTolerances(tol, 200)
        eps.getST().setType(SLEPc.ST.Type.SINVERT)
        eps.setFromOptions()
        try:
            eps.solve()
            return np.array(sorted(eps.getEigenvalue(i).real for i in range(eps.getConverged())))
        finally:
            eps.destroy()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh-size", default="0.012", help="geometry.mesh_size [m] (0.012: 78k DOFs, 0.008: 163k)")
    ap.add_argument("--methods", nargs="+", default=["single", "slice3"])
    ap.add_argument("--n-start", type=int, default=128, help="modes_below's first count (its guess)")
    a = ap.parse_args()
    import numpy as np
    from mpi4py import MPI

    from fem_squeal.fe.eigen.slicing import sliced_modes
    from fem_squeal.fe.projection import shifted

    comm = MPI.COMM_WORLD
    K, M, cut = operators(a.mesh_size)
    n = K.getSize()[0]
    lines = [f"Brake corner, {n} DOFs, real modes to {cut:.0f} Hz, {comm.size} rank(s).", "",
             "| method | modes | seconds | ratio to first | max rel. diff of ω² from first |",
             "|---|---|---|---|---|"]
    rows, ref = [], None
    for m in a.methods:
        shared = None
        if m in ("single", "ks") and comm.size > 1:     # the shared band-centre factorisation (not timed)
            shared = shifted.ShiftedSolver(K, M, -(2 * np.pi * 8000.0) ** 2, None, "cea_projection_static_")
        t0 = MPI.Wtime()
        if m in ("single", "ks"):
            w2, _ = shifted.modes_below(K, M, cut, n_start=a.n_start, prefix="cea_projection_", solver=shared,
                                        slices=0, options={"cea_projection_block_size": 0} if m == "ks" else None)
        elif m.startswith("slice"):
            rm, _ = sliced_modes(K, M, cut, int(m[5:]), tol=shifted.BASIS_MODE_TOL,
                                 max_residual=shifted.BASIS_MODE_RESIDUAL,
                                 progress=True)
            w2 = np.full(0, np.nan) if rm is None else rm.omega2
            for v in rm.vectors if rm is not None else ():
                v.destroy()
        else:
            w2 = slepc_slicing(K, M, cut, int(m[5:] or 40), shifted.BASIS_MODE_TOL)
        seconds = comm.allreduce(MPI.Wtime() - t0, op=MPI.MAX)
        if shared is not None:
            shared.destroy()
        w2 = np.sort(w2)
        ref = (w2, seconds) if ref is None else ref
        diff = float(np.max(np.abs(w2 - ref[0]) / np.abs(ref[0]))) if w2.size == ref[0].size else float("nan")
        rows.append({"method": m, "dofs": n, "ranks": comm.size, "modes": int(w2.size), "seconds": seconds,
                     "max_rel_diff": diff, "omega2": w2.tolist()})
        lines.append(f"| {m} | {w2.size} | {seconds:.1f} | {seconds / ref[1]:.2f} | {diff:.1e} |")
        if comm.rank == 0:
            print(lines[-1], flush=True)
    if comm.rank == 0:
        casework.save("real_mode_slicing", lines, rows, comm.size, False)


if __name__ == "__main__":
    main()
