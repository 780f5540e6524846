"""The CEA's shift-invert eigensolve against scripted peers on the same matrices (issue #23: "the same
lead in the CEA's shift-invert solves").

No peer code computes a full (non-modal) CEA of a frictional brake model: CalculiX and Abaqus project
onto real modes.  What a user would script instead is ARPACK (SciPy ``eigs``) in shift-invert mode
with a sparse LU of K − σM.  So the model is built once by fem_squeal (``scenes/brake_corner_cea.toml``,
linearised about its preload, with friction: K non-symmetric) and written as CSR arrays; then, each
in a fresh process on one thread, the same eigenproblem K x = ν M x (ν = −λ², the undamped linear CEA)
near σ = (2π·7071 Hz)², 60 pairs at tol 1e-10, is solved by

* fem_squeal (``solve_complex_modes``, method linear): MUMPS LU, block Arnoldi on its block solves;
* fem_squeal before (the same with ``cea_block_size = 0``): SLEPc's Krylov–Schur on the same LU;
* SciPy ``eigs`` (ARPACK, ``OPinv`` = SuperLU's solve of K − σM), SuperLU with the
  ``MMD_AT_PLUS_A`` column order (the pattern of a FE matrix is symmetric; ``--permc`` runs others:
  COLAMD, SciPy's default, took 9.6 / 72.9 s against 7.1 / 56.3 s at 50k / 163k DOFs).

Eigenvalues are compared in the band 0–10 kHz (matched pair by pair, relative difference).

    .venv/bin/python benchmarks/cea_peers.py [--mesh-sizes 0.016 0.008] [--repeats 2] [--permc MMD_AT_PLUS_A …]

Writes benchmarks/out/cea_peers_1ranks.md and .json.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402
from modal_peers import threads  # noqa: E402

N_MODES, TARGET_HZ, BAND, TOL = 60, 7071.0, (0.0, 10000.0), 1e-10


def export(mesh_size: str, folder: str) -> dict:
    """The linearised brake's K (with friction) and M as CSR arrays in ``folder``/<stem>.npz."""
    from mpi4py import MPI

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators, linearise
    from fem_squeal.fe.preload import solve_preload

    scene = load_scene(Path(__file__).resolve().parents[1] / "scenes" / "brake_corner_cea.toml",
                       [f"geometry.mesh_size={mesh_size}"])
    ops = assemble_operators(build_mesh(MPI.COMM_WORLD, scene), model_spec(scene))
    lin = linearise(ops, solve_preload(ops).active)
    arrays = {}
    for name, A in (("K", lin.K_total()), ("M", lin.M)):
        ia, ja, a = A.getValuesCSR()
        arrays.update({f"{name}_indptr": ia, f"{name}_indices": ja, f"{name}_data": a})
    stem = f"brake_{float(mesh_size) * 1e4:.0f}"
    np.savez(Path(folder) / f"{stem}.npz", **arrays)
    return {"stem": stem, "mesh_size": float(mesh_size), "dofs": int(len(arrays["K_indptr"]) - 1),
            "nnz": int(len(arrays["K_data"]))}


def _load(path: str):
    import scipy.sparse as sp

    z = np.load(path)
    n = len(z["K_indptr"]) - 1
    return tuple(sp.csr_matrix((z[f"{m}_data"], z[f"{m}_indices"], z[f"{m}_indptr"]), shape=(n, n))
                 for m in ("K", "M"))


def _in_band(lam: np.ndarray) -> np.ndarray:
    f = lam.imag / (2 * np.pi)
    return np.sort_complex(lam[(f >= BAND[0]) & (f <= BAND[1])])


def run_fem(path: str, block: str) -> dict:
    from petsc4py import PETSc

    from fem_squeal.fe.eigen import solve_complex_modes

    K, M = _load(path)
    mats = [PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                                 A.data)) for A in (K, M)]
    t0 = time.perf_counter()
    cm = solve_complex_modes(mats[0], mats[1], None, N_MODES, TARGET_HZ, method="linear", tol=TOL, band_hz=BAND,
                             options=None if block == "block" else {"cea_block_size": 0})
    t = time.perf_counter() - t0
    return {"code": "fem_squeal" if block == "block" else "fem_squeal before",
            "solver": f"MUMPS LU + {cm.algorithm}",
            "t_factor": cm.seconds["factor"], "t_iterations": cm.seconds["solve"], "t_total": t,
            "lam": [[z.real, z.imag] for z in _in_band(cm.eigenvalues)], "max_residual": float(cm.residuals.max())}


def run_scipy(path: str, permc: str) -> dict:
    import scipy.sparse.linalg as sla

    K, M = _load(path)
    sigma = (2 * np.pi * TARGET_HZ) ** 2
    t0 = time.perf_counter()
    lu = sla.splu((K - sigma * M).tocsc(), permc_spec=permc)
    t1 = time.perf_counter()
    nu, _ = sla.eigs(K, N_MODES, M, sigma=sigma, which="LM", tol=TOL,
                     OPinv=sla.LinearOperator(K.shape, matvec=lu.solve, dtype=float))
    t2 = time.perf_counter()
    lam = 1j * np.sqrt(nu.astype(complex))
    return {"code": "SciPy eigs", "solver": f"SuperLU ({permc}) + ARPACK", "t_factor": t1 - t0,
            "t_iterations": t2 - t1, "t_total": t2 - t0, "lam": [[z.real, z.imag] for z in _in_band(lam)],
            "max_residual": float("nan")}


def compare(ref: list, got: list) -> tuple[int, float]:
    """(pairs of ``got`` matched in ``ref``, their largest relative difference)."""
    a = np.array([complex(*z) for z in ref])
    diffs = [float(np.min(np.abs(a - complex(*z))) / abs(complex(*z))) for z in got]
    return len(diffs), max(diffs) if diffs else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs="+")
    ap.add_argument("--mesh-sizes", type=float, nargs="+", default=[0.016, 0.008])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--permc", nargs="+", default=["MMD_AT_PLUS_A"], help="SuperLU column orders to run")
    a = ap.parse_args()
    if a.case:
        kind, *args = a.case
        casework.report({"export": lambda: export(*args), "fem": lambda: run_fem(*args),
                         "scipy": lambda: run_scipy(*args)}[kind]())
        return
    title = "## CEA shift-invert eigensolve against SciPy/ARPACK, linearised brake corner, 1 rank, 1 thread"
    rows, lines = [], [title, "", f"{N_MODES} pairs of K x = ν M x nearest σ = (2π·{TARGET_HZ:g} Hz)², "
                       f"tol {TOL:g}; the same matrices for every code; fresh process per run, interleaved "
                       "repeats, fastest kept.  "
                       "Δλ: largest relative difference of the eigenvalues in 0–10 kHz against fem_squeal before "
                       "(SLEPc Krylov–Schur on MUMPS).  Times in s.", "",
                       "| DOFs | code | solver | factor | iterations | total | modes in band | Δλ |",
                       "|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="cea_peers_") as tmp, threads(1):
        for h in a.mesh_sizes:
            mesh = casework.spawn(__file__, ["export", str(h), tmp], 1)
            path = str(Path(tmp) / f"{mesh['stem']}.npz")
            cases = {"fem_squeal": ["fem", path, "block"], "fem_squeal before": ["fem", path, "ks"],
                     **{f"SciPy eigs {p}": ["scipy", path, p] for p in a.permc}}
            got: dict[str, list[dict]] = {k: [] for k in cases}
            for rep in range(a.repeats):
                for name, args in cases.items():
                    r = casework.spawn(__file__, args, 1)
                    got[name].append(r)
                    print(f"{mesh['stem']} #{rep} {name}: {r['t_total']:.2f} s", file=sys.stderr, flush=True)
            best = {k: min(v, key=lambda r: r["t_total"]) for k, v in got.items()}
            ref = best["fem_squeal before"]["lam"]
            for name, r in best.items():
                n, d = compare(ref, r["lam"])
                rows.append({**mesh, **{k: v for k, v in r.items() if k != "lam"}, "name": name, "modes": n,
                             "max_rel_diff": d, "lam": r["lam"]})
                lines.append(f"| {mesh['dofs']} | {name} | {r['solver']} | {r['t_factor']:.2f} | "
                             f"{r['t_iterations']:.2f} | {r['t_total']:.2f} | {n} | {d:.1e} |")
            peers = [r for k, r in best.items() if not k.startswith("fem_squeal")]
            fastest = min(peers, key=lambda r: r["t_total"])
            lines.append(f"| {mesh['dofs']} | **ratio** | fastest peer ÷ fem_squeal | | "
                         f"{fastest['t_iterations'] / best['fem_squeal']['t_iterations']:.2f}× | | "
                         f"**{fastest['t_total'] / best['fem_squeal']['t_total']:.2f}×** | | |")
    casework.save("cea_peers", lines, rows, 1, False)


if __name__ == "__main__":
    main()
