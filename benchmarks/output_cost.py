"""Cost of the CEA's mode descriptors and field output against its eigensolve (issue #23: ≤ 25 %).

On the brake corner (``scenes/brake_corner_cea.toml`` model, linearised with every contact point
closed, ``--mesh-size`` 0.016 ≈ 50k P2 DOFs) the CEA's modes in 0-10 kHz are solved once, then in the
same process, on the same modes:

* descriptors per mode (the previous code, ``_describe_per_vector``: a MatMult and a VecDot per
  vector and matrix) against the batched ``describe_all`` / ``strain_energy_shares_all``
  (one sparse-times-dense product per matrix and block of 16 modes), with the largest difference;
* fields with dolfinx's ``XDMFFile.write_function`` (a per-node evaluation each) and a zlib VTU, as
  before, against ``write_modes_xdmf`` (PETSc HDF5, values taken from the coordinate space) and the
  uncompressed VTU of ``write_vtu``.

    .venv/bin/python benchmarks/output_cost.py [--mesh-size 0.016] [--ranks 1]

Writes benchmarks/out/output_cost_<ranks>ranks.md and .json.
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

ROOT = Path(__file__).resolve().parents[1]


def _old_fields(comm, tmp: Path, V, modes) -> None:
    """The previous writers: XDMFFile.write_function per field, VTU with zlib."""
    import meshio
    from dolfinx import fem
    from dolfinx.io import XDMFFile

    from fem_squeal.fe.output import field_rows, vtu_mesh

    fr, fi = fem.Function(V, name="mode_re"), fem.Function(V, name="mode_im")
    with XDMFFile(comm, str(tmp / "old.xdmf"), "w") as x:
        x.write_mesh(V.mesh)
        for j, pair in enumerate(modes):
            for f, vec in zip((fr, fi), pair):
                f.x.array[: vec.getLocalSize()] = vec.array_r
                f.x.scatter_forward()
                x.write_function(f, float(j))
    rows = field_rows(V, [v for pair in modes for v in pair])
    W = next(rows)
    layout = vtu_mesh(comm, W)
    from fem_squeal.fe.output import _gather_rows

    data = {f"m{j}": _gather_rows(comm, W, r) for j, r in enumerate(rows)}
    if comm.rank == 0:
        points, cells, kind = layout
        meshio.write(tmp / "old.vtu", meshio.Mesh(points, [(kind, cells)], point_data=data), file_format="vtu")


def _describe_per_vector(basis, K_parts, groups, xr, xi):
    """The previous descriptors of one mode: a MatMult and a VecDot per vector and matrix (M, M_z, each
    K_p), the harmonic sums by a complex product per mode."""
    from mpi4py import MPI

    from fem_squeal.fe.descriptors import ModeDescriptors

    t = xr.duplicate()
    sums = {}
    for name, A in (("M", basis.M), ("Mz", basis.Mz), *K_parts.items()):
        e = 0.0
        for x in (xr, xi):
            A.mult(x, t)
            e += x.dot(t)
            if name == "M":
                sums.setdefault("mu", []).append(basis._cyl(t.array))
        sums[name] = e
    t.destroy()
    mu = sums["mu"][0] + 1j * sums["mu"][1]
    phase = basis.cs[: len(basis.k)] - 1j * basis.cs[len(basis.k):]
    cp = basis.comm.allreduce(phase @ mu.T, op=MPI.SUM) / basis.mass
    cm = basis.comm.allreduce(np.conj(phase) @ mu.T, op=MPI.SUM) / basis.mass
    pp, pm = (np.abs(cp) ** 2).sum(axis=1), (np.abs(cm) ** 2).sum(axis=1)
    power = basis.mass * (pp + pm)
    power[0] = basis.mass * pp[0]
    k = int(np.argmax(power))
    tau = 0.0 if k == 0 or pp[k] + pm[k] == 0 else float((pm[k] - pp[k]) / (pm[k] + pp[k]))
    d = ModeDescriptors(float(1.0 - sums["Mz"] / sums["M"]), k, float(power[k] / sums["M"]), tau,
                        0 if abs(tau) < 0.5 else int(np.sign(tau)))
    total = sum(sums[p] for p in K_parts)
    shares = {g: sum(sums[p] for p in parts if p in K_parts) / total for g, parts in groups.items()}
    return d, shares


def run_case(mesh_size: str) -> dict:
    from mpi4py import MPI

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators, linearise
    from fem_squeal.fe.descriptors import CircumferentialBasis, strain_energy_shares_all
    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.output import write_modes_xdmf, write_vtu
    from geometry.tags import COMPONENT_GROUPS

    comm = MPI.COMM_WORLD
    scene = load_scene(ROOT / "scenes" / "brake_corner_cea.toml", [f"geometry.mesh_size={mesh_size}"])
    md = build_mesh(comm, scene)
    ops = linearise(assemble_operators(md, model_spec(scene), parts=True, describe_part="disc"))
    basis = CircumferentialBasis(ops.V, *ops.M_parts["disc"])
    groups = COMPONENT_GROUPS.get("brake_corner")
    t0 = time.perf_counter()
    cm = solve_complex_modes(ops.K_total(), ops.M, ops.C, 60, 7071.0, band_hz=(0.0, 10000.0))
    t_eig = time.perf_counter() - t0
    modes = list(zip(cm.vectors_re, cm.vectors_im))
    t0 = time.perf_counter()
    old_d, old_e = zip(*[_describe_per_vector(basis, ops.K_parts, groups, a, b) for a, b in modes])
    t_old_desc = time.perf_counter() - t0
    t0 = time.perf_counter()
    new_d = basis.describe_all(modes)
    new_e = strain_energy_shares_all(ops.K_parts, modes, groups)
    t_new_desc = time.perf_counter() - t0
    # every descriptor is a share or index in [−1, 1] or an integer: absolute differences
    diff = max(max(abs(x - y) for x, y in zip(a, b)) for a, b in zip(old_d, new_d))
    diff = max(diff, max(abs(a[k] - b[k]) for a, b in zip(old_e, new_e) for k in a))
    nd_same = all(a.nodal_diameter == b.nodal_diameter and a.travelling_direction == b.travelling_direction
                  for a, b in zip(old_d, new_d))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(comm.bcast(tmp, root=0))
        t0 = time.perf_counter()
        _old_fields(comm, tmp, ops.V, modes)
        t_old_out = time.perf_counter() - t0
        t0 = time.perf_counter()
        write_modes_xdmf(comm, tmp / "new.xdmf", ops.V, modes)
        write_vtu(comm, tmp / "new.vtu", ops.V, {f"m{j}_{p}": x for j, pair in enumerate(modes)
                                                 for p, x in zip(("re", "im"), pair)})
        t_new_out = time.perf_counter() - t0
    return {"mesh_size": float(mesh_size), "ranks": comm.size, "dofs": ops.K.getSize()[0], "modes": len(modes),
            "eigensolve_s": t_eig, "descriptors_before_s": t_old_desc, "descriptors_after_s": t_new_desc,
            "fields_before_s": t_old_out, "fields_after_s": t_new_out, "max_descriptor_difference": diff,
            "same_diameters_and_directions": nd_same}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs=1, metavar="MESH_SIZE")
    ap.add_argument("--mesh-size", default="0.016")
    ap.add_argument("--ranks", type=int, default=1)
    a = ap.parse_args()
    if a.case:
        casework.report(run_case(a.case[0]))
        return
    r = casework.spawn(__file__, [a.mesh_size], a.ranks)
    e = r["eigensolve_s"]
    lines = [f"CEA output cost, brake corner {r['dofs']} DOFs, {r['modes']} modes, {r['ranks']} rank(s); "
             f"eigensolve {e:.2f} s", "",
             "| part | before s | after s | before / eigensolve | after / eigensolve |", "|---|---|---|---|---|"]
    for name in ("descriptors", "fields"):
        b, n = r[f"{name}_before_s"], r[f"{name}_after_s"]
        lines.append(f"| {name} | {b:.2f} | {n:.2f} | {b / e:.0%} | {n / e:.0%} |")
    b = r["descriptors_before_s"] + r["fields_before_s"]
    n = r["descriptors_after_s"] + r["fields_after_s"]
    lines += [f"| total | {b:.2f} | {n:.2f} | {b / e:.0%} | {n / e:.0%} |", "",
              "largest descriptor difference (per-mode vs batched; shares and indices in [−1, 1]): "
              f"{r['max_descriptor_difference']:.1e}; "
              f"nodal diameters and directions identical: {r['same_diameters_and_directions']}"]
    casework.save("output_cost", lines, [r], a.ranks, False)


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
