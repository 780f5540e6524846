"""What the contact costs a factorisation (issue 36): the brake corner's shifted stiffness factorised with
and without the contact's couplings, on ``--ranks`` ranks, every case a fresh process.

Cases, each a fresh factorisation (MUMPS: its own counts, RINFOG(3) flops and INFOG(9) factor entries):

- ``K``: the assembled K (no contact), LU of K − σM at the CEA's shift (the band centre in ω²);
- ``preload J``: K + K_c + K_f with every touching point closed (the preload's first Jacobian), LU;
- ``CEA K, union``: the preloaded state's K + K_c + K_f − σM with the open points' couplings stored as
  zeros (the pattern before 2026-11-29), LU;
- ``CEA K``: the same without them (``linearise``'s pattern since), LU;
- ``frictionless, substructured``: K + K_c of the state + |σ'|M by the substructured CHOLMOD of the
  coupling's real modes (σ' = −(2π·0.05·f_cut)², f_cut 1.25 × the band top), with its interface rows;
  and K alone the same way.

Seconds are the fastest of ``--repeats`` (interleaved); this machine's spread between repeats of one
factorisation is 20–40 % (docs/validation.md), the counts are exact.

    .venv/bin/python benchmarks/contact_factorisation.py [--mesh-size 0.0056] [--repeats 2] [--ranks 2]
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

SCENE = Path(__file__).resolve().parent.parent / "scenes" / "brake_corner_cea.toml"
BAND_TOP_HZ = 16000.0
CASES = ("K", "preload J", "CEA K, union", "CEA K", "K, substructured", "frictionless CEA K, substructured")
NEEDS_PRELOAD = ("CEA K, union", "CEA K", "frictionless CEA K, substructured")


def _shifted(terms: list, M, sigma: float, destroy: bool = True):
    """Σ terms − σM as a new matrix; the terms after the first destroyed (``destroy``)."""
    from petsc4py import PETSc  # heavy: in the case's process

    A = terms[0].copy()
    for B in terms[1:]:
        if B is not None:
            A.axpy(1.0, B, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            if destroy:
                B.destroy()
    if sigma != 0.0:
        A.axpy(-sigma, M, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    return A


def mumps_lu(A) -> dict:
    """MUMPS LU of ``A``: seconds (analysis + factorisation) and MUMPS's counts."""
    from petsc4py import PETSc  # heavy: in the case's process

    comm = A.getComm().tompi4py()
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOperators(A)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    comm.Barrier()
    t = time.perf_counter()
    pc.setUp()
    comm.Barrier()
    seconds = time.perf_counter() - t
    F = pc.getFactorMatrix()
    out = {"seconds": seconds, "flops": F.getMumpsRinfog(3), "entries": int(F.getMumpsInfog(9)),
           "nnz": int(A.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"])}
    ksp.destroy()
    return out


def substructured(A, M, sigma: float) -> dict:
    """The substructured CHOLMOD factorisation of A − σM (the real modes' on N ranks): seconds, its
    parts' seconds and the interface rows."""
    from fem_squeal.fe.csr import local_rows  # heavy: in the case's process
    from fem_squeal.fe.ordering import node_block_size  # heavy: in the case's process
    from fem_squeal.fe.substructured import SubstructuredCholesky  # heavy: in the case's process

    comm = A.getComm().tompi4py()
    rows = (local_rows(A) - sigma * local_rows(M)).tocsr()
    rows.eliminate_zeros()
    comm.Barrier()
    t = time.perf_counter()
    f = SubstructuredCholesky(rows, A.getOwnershipRanges(), node_block_size(A), comm)
    comm.Barrier()
    out = {"seconds": time.perf_counter() - t, "interface_rows": int(f.interface_rows),
           **{f"{k}_s": v for k, v in f.seconds.items()}}
    f.close()
    return out


def run_case(name: str, mesh_size: float) -> dict:
    """One case in this process (its factorisation's memory is the process's, returned at its exit)."""
    import numpy as np  # heavy: in the case's process
    from mpi4py import MPI  # heavy: in the case's process

    from fem_squeal.app.analyses.mesh import build_mesh  # heavy: in the case's process
    from fem_squeal.app.scene import load_scene, model_spec  # heavy: in the case's process
    from fem_squeal.fe.assembly import assemble_operators, contact_matrices, linearise  # heavy: case
    from fem_squeal.fe.csr import drop_zeros  # heavy: in the case's process
    from fem_squeal.fe.preload import solve_preload  # heavy: in the case's process

    comm = MPI.COMM_WORLD
    scene = load_scene(SCENE, [f"geometry.mesh_size={mesh_size}"])
    ops = assemble_operators(build_mesh(comm, scene), model_spec(scene), parts=False)
    M = drop_zeros(ops.M)
    info = {"dofs": ops.K.getSize()[0], "ranks": comm.size,
            "points": {it.name: comm.allreduce(len(op.weight)) for it, op in ops.contacts}}
    sigma = (2 * np.pi * BAND_TOP_HZ / np.sqrt(2.0)) ** 2            # the CEA's default shift
    sigma_real = -(2 * np.pi * 0.05 * 1.25 * BAND_TOP_HZ) ** 2        # the coupling's real modes
    if name in NEEDS_PRELOAD:
        pre = solve_preload(ops)
        info["closed"] = {n: comm.allreduce(int(a.sum())) for n, a in pre.active.items()}
        state = {it.name: it.kn * pre.active[it.name].astype(float) for it, _ in ops.contacts}
        lin = linearise(ops, pre.active, friction=name != "frictionless CEA K, substructured")
    if name == "K":
        A = _shifted([ops.K], M, sigma)
    elif name == "preload J":
        A = _shifted([ops.K, *contact_matrices(ops, None)], M, 0.0)
    elif name == "CEA K, union":
        A = _shifted([ops.K, *contact_matrices(ops, state)], M, sigma)
    elif name == "CEA K":
        A = _shifted([lin.K, lin.Kf], M, sigma, destroy=False)
    elif name == "K, substructured":
        A = ops.K
    else:
        A = lin.K
    if name.endswith("substructured"):
        return {"case": name, "solver": "CHOLMOD substructured", **substructured(A, M, sigma_real), **info}
    return {"case": name, "solver": "MUMPS LU", **mumps_lu(A), **info}


def run(mesh_size: float, repeats: int, ranks: int) -> list[dict]:
    """Every case ``repeats`` times, each in a fresh process on ``ranks`` ranks (interleaved; the
    fastest kept)."""
    best: dict[str, dict] = {}
    for rep in range(repeats):
        for name in CASES:
            r = casework.spawn(__file__, [name, str(mesh_size)], ranks, env={"OPENBLAS_NUM_THREADS": "1"})
            print(f"#{rep} {name}: {r['seconds']:.2f} s", file=sys.stderr, flush=True)
            if name not in best or r["seconds"] < best[name]["seconds"]:
                best[name] = r
    return [best[n] for n in CASES]


def table(rows: list[dict]) -> list[str]:
    info = next(r for r in rows if "closed" in r)
    out = [f"{info['dofs']} DOFs, {info['ranks']} rank(s); closed points {info['closed']} of {info['points']}",
           "",
           "| case | solver | seconds | flops | factor entries | interface rows |",
           "|---|---|---:|---:|---:|---:|"]
    for r in rows:
        flops = f"{r['flops']:.3g}" if "flops" in r else ""
        entries = f"{r['entries'] / 1e6:.0f}M" if "entries" in r else ""
        out.append(f"| {r['case']} | {r['solver']} | {r['seconds']:.2f} | {flops} | {entries} | "
                   f"{r.get('interface_rows', '')} |")
    return out


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--case":
        casework.report(run_case(sys.argv[2], float(sys.argv[3])))
        return
    a = casework.brake_args()
    rows = run(a.mesh_size, a.repeats, a.ranks)
    casework.save("contact_factorisation", table(rows), rows, a.ranks, False)


if __name__ == "__main__":
    main()
