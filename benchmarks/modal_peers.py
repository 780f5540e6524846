"""Modal analysis against peers on the same mesh: fem_squeal, CalculiX (ccx, C3D10) and scikit-fem (P2).

Problem: annular disc, r 0.06..0.14 m, thickness 0.012 m, steel (E 210 GPa, ν 0.3, ρ 7850 kg/m³),
all displacements fixed on the inner cylinder r = 0.06; the lowest 20 modes; quadratic tetrahedra.

Same mesh: each mesh is generated ONCE by gmsh (``geometry.annular_disc``, curved second-order
tetrahedra) and saved as ``.msh``.  fem_squeal (``builder = "mesh_file"``) and scikit-fem (meshio ->
``MeshTet2``) read that file; CalculiX reads the Abaqus deck that ``fem_squeal.app.convert`` writes
from it (C3D10, the same node and element numbers; coordinates re-printed in 20 characters because
ccx reads at most 20 per field: fixed-point with 17 decimals, i.e. to 1e-17 m).  The clamp is the
mesh's ``inner`` surface in all three: fem_squeal clamps its facets, scikit-fem the DOFs of the same
facets, ccx the node set of their 6 nodes each; the free-DOF counts are checked to be equal.

Solvers and tolerances (all three factor K: shift σ = 0; ccx uses σ = 1 rad²/s²):
- fem_squeal: ``solve_real_modes`` (SLEPc Krylov–Schur, shift-and-invert, MUMPS LU), tol 1e-10 (its
  default; relative residual), ncv = max(2 nev, nev + 16).
- CalculiX 2.20 (Debian build: SPOOLES + ARPACK): ``*FREQUENCY`` with nev modes; ARPACK tol 1e-2 and
  ncv = 5 nev are hard-coded in ccx (scipy's ARPACK at that tol and ncv converges these eigenvalues to
  1e-15, so the loose tol costs nothing here).  Eigenvalues are read from the .dat file, which prints
  7 significant digits (0.1170078E+09): rounding of up to 4e-7 in λ, 2.5e-7 in frequency.  On N > 1
  threads ccx runs twice: every thread variable at N, and the same with CCX_NPROC_EQUATION_SOLVER=1
  (SPOOLES' threaded solves, called once per Lanczos step, were up to 20× slower than its serial ones
  here); the faster one is its time.
- scikit-fem 12: P2 vector element on MeshTet2, ``condense``, scipy ``eigsh`` in shift-invert mode with
  tol 1e-10 and an explicit SuperLU factor of K (``splu``, MMD_AT_PLUS_A ordering, symmetric mode;
  about 2× faster than eigsh's own default COLAMD factor on these meshes).  SuperLU is serial: more
  threads do not help scikit-fem, so its 1-thread time stands for both columns.

Quadrature: fem_squeal's default is the degree the form compiler estimates on the curved (P2)
geometry: 7 for the mass (exact: u·v·det J is a polynomial of degree 7) and 5 for the stiffness.
scikit-fem is run with the same degrees (``intorder`` 7 and 5).  ccx integrates C3D10 stiffness AND
mass with 4 points (degree 2), which under-integrates the mass; that alone makes ccx's frequencies
differ (1e-4 on the coarsest mesh, shrinking with h).  To show that it is the only difference,
scikit-fem (``intorder`` 2) and fem_squeal are also run with that 4-point rule ("4-pt" rows).
fem_squeal's 4-pt runs set ``discretisation.quadrature_degree = 2`` (it goes into the integrals'
metadata; before this benchmark it was silently ignored by FFCx 0.5 as a form-compiler parameter).

Timings (mesh generation excluded; every case a fresh process; threads pinned with OMP_NUM_THREADS,
OMP_THREAD_LIMIT, OPENBLAS_NUM_THREADS, CCX_NPROC_*; fem_squeal 1 thread per rank):
- read: fem_squeal reading the .msh + quality check + distribution; scikit-fem meshio + MeshTet2; ccx:
  a run of the same deck without ``*STEP`` (parse only).
- assembly, eigensolve: in-process wall times (fem_squeal: K, M and the axial mass it also
  assembles; scikit-fem: bases, K, M, condense).  ccx: not separable, its "solve" is its end-to-end
  time minus its parse-only time.
- end-to-end = read + assembly + eigensolve (ccx: the wall time of the ccx process; it also computes
  stresses per mode and writes .frd/.dat, which it cannot be told not to).
- process: wall time of the whole process as seen from here, including the Python interpreter,
  imports and ``mpirun`` for fem_squeal and scikit-fem.
The dolfinx JIT cache is warmed by one untimed fem_squeal run per quadrature variant first.

Meshes: 20, 10, 6, 4 and 3.2 mm (7k to 437k free DOFs); the finest is the reference of the errors.
fem_squeal and ccx run on all of them; scikit-fem up to 300k DOFs (at 255k it took 2 min and 7 GB),
its 4-point run up to 100k.

    .venv/bin/python benchmarks/modal_peers.py [--quick] [--ranks 2] [--workdir DIR]
    .venv/bin/python benchmarks/modal_peers.py --render benchmarks/out/modal_peers_2ranks.json --ranks 2

``--speed`` (issue #23): real modes against the fastest peer, every code on one thread (OpenMP's
thread limit included: see ``thread_env``), on the 10, 6
and 4 mm meshes (26k, 87k, 260k DOFs; ``--sizes``), 20 modes, ``--repeats`` interleaved runs (the
fastest kept): fem_squeal with its defaults (CHOLMOD on one rank, block Lanczos), with SLEPc's Krylov–Schur
instead (``real_block_size = 0``) and as before #23 (MUMPS LDLᵀ, tol 1e-10, purified: the
reference of Δf); GetFEM 5.4 (Debian ``python3-getfem``: P2 on the imported
curved mesh, CHOLMOD from scikit-sparse, scipy ``eigsh`` shift-invert with the factor as ``OPinv``);
scikit-fem with the same CHOLMOD + ``eigsh``; CalculiX.  The peers' ``eigsh`` tol is fem_squeal's
(SPEED_TOL).  Writes benchmarks/out/modal_peers_speed_1ranks.md and .json.

``--ranks N``: fem_squeal also on N ranks and ccx also on N threads (``--ranks 1``: serial only; the
serial runs are part of every invocation, so ``--ranks 2`` alone gives the whole comparison).
``--quick``: the 20 mm mesh only, 10 modes, it is its own reference (about 10 s).  ``--render``: re-write
the tables and the plot from a saved .json.  Writes benchmarks/out/modal_peers_<N>ranks[_quick].md,
.json and .png (end-to-end time against error, log-log).  About 20 min for ``--ranks 2`` (2 cores).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402
from casework import ccx_nodes  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

R_IN, R_OUT, THICKNESS = 0.06, 0.14, 0.012
E, NU, RHO = 210e9, 0.3, 7850.0
N_MODES, QUICK_MODES = 20, 10
SIZES = (0.02, 0.01, 0.006, 0.004, 0.0032)   # 7k .. 437k free DOFs; the finest is the reference
QUICK_SIZES = (0.02,)                    # --quick: one mesh, it is its own reference
EIG_TOL = 1e-10                          # fem_squeal (its default) and scikit-fem
SAME = 1e-5                              # "the same frequencies": max relative difference
SKFEM_MAX_DOFS = 300_000                 # scikit-fem (same quadrature as fem_squeal) up to here
SKFEM_4PT_MAX_DOFS = 100_000             # the 4-point scikit-fem run (explanation only) on small meshes
AUTO, FOUR_POINT = 0, 2                  # fem_squeal quadrature: form-compiler estimate / degree 2
SKFEM_AUTO = (5, 7)                      # scikit-fem intorder (stiffness, mass) = fem_squeal's estimate
SPEED_SIZES = (0.01, 0.006, 0.004)       # --speed: 26k, 87k, 260k DOFs (the meshes of issue #23)
SPEED_TOL = 1e-7                         # --speed: the peers' eigsh tol = fem_squeal's default (REAL_MODE_TOL)
# fem_squeal before issue #23: MUMPS LDLᵀ, tol 1e-10, purified eigenvectors (the --speed reference)
OLD_DEFAULTS = {"real_st_pc_factor_mat_solver_type": "mumps", "real_eps_purify": True}
SKFEM_4PT = (2, 2)


# ---------------------------------------------------------------- files of one mesh

def stem(h: float) -> str:
    return f"disc_{h * 1e3:g}mm".replace(".", "p")


def ccx_deck(mesh_inp: str, clamp_nodes: np.ndarray, n_modes: int | None) -> str:
    """The CalculiX input: the mesh deck included, the clamp node set, steel, and *FREQUENCY (none
    for the parse-only run)."""
    nodes = [", ".join(str(int(n) + 1) for n in clamp_nodes[i:i + 8]) for i in range(0, len(clamp_nodes), 8)]
    lines = [f"*INCLUDE, INPUT={mesh_inp}", "*NSET, NSET=CLAMP", *nodes,
             "*MATERIAL, NAME=STEEL", "*ELASTIC", f"{E:.6e}, {NU}", "*DENSITY", f"{RHO}",
             "*SOLID SECTION, ELSET=disc, MATERIAL=STEEL", "*BOUNDARY", "CLAMP, 1, 3"]
    if n_modes:
        lines += ["*STEP", "*FREQUENCY", f"{n_modes}", "*END STEP"]
    return "\n".join(lines) + "\n"


def make_mesh(h: float, folder: str, n_modes: int) -> dict:
    """gmsh -> <stem>.msh; Abaqus deck <stem>.inp (C3D10) from it; the ccx decks; sizes."""
    from mpi4py import MPI

    from fem_squeal.app.convert import write_mesh_file
    from geometry.annular_disc import annular_disc_model
    from geometry.gmsh_io import write_msh
    from geometry.mesh_file import _facet_nodes, read_mesh_file

    d, s = Path(folder), stem(h)
    t0 = time.perf_counter()
    model = annular_disc_model(mean_radius=0.5 * (R_IN + R_OUT), width=R_OUT - R_IN, thickness=THICKNESS,
                               mesh_size=h, order=2)
    write_msh(MPI.COMM_SELF, model, d / f"{s}.msh")
    t1 = time.perf_counter()
    mf = read_mesh_file(d / f"{s}.msh")
    write_mesh_file(mf, d / f"{s}.inp")
    ccx_nodes(d / f"{s}.inp")
    clamp = np.unique(np.concatenate([_facet_nodes(mf.cells[c], f) for c, f in mf.surfaces["inner"]]))
    (d / f"{s}_ccx.inp").write_text(ccx_deck(f"{s}.inp", clamp, n_modes))
    (d / f"{s}_ccx_read.inp").write_text(ccx_deck(f"{s}.inp", clamp, None))
    return {"h": h, "stem": s, "nodes": len(mf.points), "elements": len(mf.cells),
            "dofs": 3 * len(mf.points), "free_dofs": 3 * (len(mf.points) - len(clamp)),
            "t_gmsh": t1 - t0, "t_convert": time.perf_counter() - t1}


def scene_text(msh_name: str, n_modes: int, quadrature: int, petsc_options: dict | None = None) -> str:
    return f"""title = "clamped annular disc (benchmarks/modal_peers.py)"
[geometry]
builder = "mesh_file"
file = "{msh_name}"
[geometry.parts]
disc = ["disc"]
[geometry.faces]
inner = ["inner"]
[materials.disc]
E = {E!r}
nu = {NU!r}
rho = {RHO!r}
[boundary]
clamped = ["inner"]
[discretisation]
degree = 2
quadrature_degree = {quadrature}
[analyses.real_modes]
n_modes = {n_modes}
target_hz = 0.0
tol = {EIG_TOL!r}
""" + ("[solver.petsc_options]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in petsc_options.items())
       if petsc_options else "")


# ---------------------------------------------------------------- the three codes

def run_fem(scene_file: str, tol: str = "scene") -> dict:
    """fem_squeal on the scene's mesh file: read + distribute, assemble, eigensolve (timed apart).
    ``tol``: "scene" (the scene's ``analyses.real_modes.tol``), "default" (solve_real_modes' own
    defaults: its tolerance and solver options) or a number."""
    import resource

    from mpi4py import MPI

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.eigen import solve_real_modes

    comm = MPI.COMM_WORLD
    scene = load_scene(scene_file)
    spec = model_spec(scene)
    rm_opts = scene["analyses"]["real_modes"]
    comm.barrier()
    t0 = time.perf_counter()
    md = build_mesh(comm, scene)
    comm.barrier()
    t1 = time.perf_counter()
    ops = assemble_operators(md, spec)
    comm.barrier()
    t2 = time.perf_counter()
    kw = {} if tol == "default" else {"tol": rm_opts["tol"] if tol == "scene" else float(tol)}
    rm = solve_real_modes(ops.K, ops.M, rm_opts["n_modes"], rm_opts["target_hz"],
                          options=scene["solver"]["petsc_options"], **kw)
    comm.barrier()
    t3 = time.perf_counter()
    bs, im = ops.V.dofmap.index_map_bs, ops.V.dofmap.index_map
    clamped = comm.allreduce(int(np.count_nonzero(np.asarray(ops.bc_dofs) < im.size_local * bs)), op=MPI.SUM)
    rss = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, op=MPI.SUM) / 1024
    return {"code": "fem_squeal", "quadrature": spec.quadrature_degree or "auto", "parallel": comm.size,
            "dofs": im.size_global * bs, "free_dofs": im.size_global * bs - clamped,
            "t_read": t1 - t0, "t_assembly": t2 - t1, "t_eig": t3 - t2, "t_e2e": t3 - t0,
            "t_factor": rm.seconds.get("factor", float("nan")), "solver": rm.solver, "tol": tol,
            "freqs": rm.freqs_hz.tolist(), "max_residual": float(np.max(rm.residuals)), "rss_mb": rss}


def run_skfem(msh: str, n_modes: int, q_stiffness: int, q_mass: int, tol: float = EIG_TOL,
              factor: str = "auto") -> dict:
    """scikit-fem: P2 on the quadratic mesh, K and M with the given intorders, eigsh shift-invert
    with an explicit factor of K: ``factor`` "cholmod" (scikit-sparse), "superlu" or "auto" (CHOLMOD
    when scikit-sparse is installed)."""
    import logging
    import resource

    logging.getLogger("skfem").setLevel(logging.ERROR)   # "Failure to parse tags": triangle6 sets, unused
    import meshio
    from scipy.sparse.linalg import LinearOperator, eigsh, splu
    from skfem import Basis, BilinearForm, ElementTetP2, ElementVector, asm, condense
    from skfem.helpers import dot
    from skfem.io.meshio import from_meshio
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    t0 = time.perf_counter()
    m = meshio.read(msh)
    mesh = from_meshio(m)
    # the clamped facets: the mesh's "inner" triangles, in skfem's vertex numbering (vertices first)
    tets = m.cells_dict["tetra10"]
    tri = m.cells_dict["triangle6"][m.cell_sets_dict["inner"]["triangle6"]][:, :3]
    vertices = np.unique(tets[:, :4])
    n = len(vertices)

    def key(a):
        a = np.sort(np.asarray(a, dtype=np.int64), axis=1)
        return (a[:, 0] * n + a[:, 1]) * n + a[:, 2]

    facets = np.flatnonzero(np.isin(key(mesh.facets.T), key(np.searchsorted(vertices, tri))))
    if len(facets) != len(tri):
        raise RuntimeError(f"skfem: found {len(facets)} of {len(tri)} clamped facets")
    t1 = time.perf_counter()
    e = ElementVector(ElementTetP2())
    bk = Basis(mesh, e, intorder=q_stiffness)
    bm = bk if q_mass == q_stiffness else Basis(mesh, e, intorder=q_mass)
    K = asm(linear_elasticity(*lame_parameters(E, NU)), bk)
    M = asm(BilinearForm(lambda u, v, w: RHO * dot(u, v)), bm)
    D = bk.get_dofs(facets=facets).all()
    Kc, Mc = condense(K, M, D=D, expand=False)
    t2 = time.perf_counter()
    if factor == "auto":
        factor = "cholmod" if have_module("sksparse") else "superlu"
    if factor == "cholmod":
        from sksparse.cholmod import cholesky

        solve = cholesky(Kc.tocsc())
    else:
        solve = splu(Kc.tocsc(), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True}).solve
    tf = time.perf_counter()
    op = LinearOperator(Kc.shape, matvec=solve, dtype=float)
    w, X = eigsh(Kc, n_modes, Mc, sigma=0.0, which="LM", tol=tol, OPinv=op)
    t3 = time.perf_counter()
    order = np.argsort(w)
    w, X = w[order], X[:, order]
    normK = abs(Kc).sum(axis=1).max()
    res = [np.linalg.norm(Kc @ x - lam * (Mc @ x)) / (normK * np.linalg.norm(x)) for lam, x in zip(w, X.T)]
    return {"code": "scikit-fem", "quadrature": f"{q_stiffness}/{q_mass}", "parallel": 1,
            "dofs": K.shape[0], "free_dofs": Kc.shape[0], "t_read": t1 - t0, "t_assembly": t2 - t1,
            "t_eig": t3 - t2, "t_factor": tf - t2, "t_e2e": t3 - t0, "freqs": (np.sqrt(w) / (2 * np.pi)).tolist(),
            "solver": f"{factor} + eigsh", "tol": tol,
            "max_residual": float(max(res)), "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def run_getfem(msh: str, n_modes: int, tol: float) -> dict:
    """GetFEM (Debian python3-getfem): the gmsh file imported, classical P2 vector FEM on the curved
    P2 geometry, ``asm_linear_elasticity`` with IM_TETRAHEDRON(5) (degree 5, as fem_squeal's K) and
    ``asm_mass_matrix`` with IM_TETRAHEDRON(8) (GetFEM has no degree-7 rule; both integrate the
    degree-7 mass exactly); the clamped DOFs removed; CHOLMOD (scikit-sparse) factor of K and scipy
    ``eigsh`` shift-invert (σ = 0) with that factor as ``OPinv``: the configuration of issue #23."""
    import resource

    import getfem as gf
    import scipy.sparse as sp
    from scipy.sparse.linalg import LinearOperator, eigsh
    from sksparse.cholmod import cholesky

    t0 = time.perf_counter()
    m = gf.Mesh("import", "gmsh", msh)

    def radii(region):
        p = m.pts()[:, m.pid_in_faces(m.region(region))]
        return np.hypot(p[0], p[1])

    # GetFEM numbers the imported regions by gmsh entity; the clamp is the one on r = R_IN
    inner = [r for r in m.regions() if np.allclose(radii(r), R_IN, rtol=0.0, atol=1e-9)]
    if len(inner) != 1:
        raise RuntimeError(f"getfem: {len(inner)} regions on r = {R_IN}")
    t1 = time.perf_counter()
    mfu = gf.MeshFem(m, 3)
    mfu.set_classical_fem(2)
    mfd = gf.MeshFem(m, 1)
    mfd.set_classical_fem(0)
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    nd = mfd.nbdof()
    Kg = gf.asm_linear_elasticity(gf.MeshIm(m, gf.Integ("IM_TETRAHEDRON(5)")), mfu, mfd,
                                  np.full(nd, lam), np.full(nd, mu))
    Mg = gf.asm_mass_matrix(gf.MeshIm(m, gf.Integ("IM_TETRAHEDRON(8)")), mfu)

    def csc(A):
        A.to_csc()
        jc, ir = A.csc_ind()
        return sp.csc_matrix((A.csc_val(), ir, jc), shape=A.size())

    K, M = csc(Kg), RHO * csc(Mg)
    free = np.setdiff1d(np.arange(mfu.nbdof()), mfu.basic_dof_on_region(inner[0]))
    Kc, Mc = K[free][:, free].tocsc(), M[free][:, free].tocsc()
    t2 = time.perf_counter()
    factor = cholesky(Kc)
    tf = time.perf_counter()
    w, X = eigsh(Kc, n_modes, Mc, sigma=0.0, which="LM", tol=tol,
                 OPinv=LinearOperator(Kc.shape, matvec=factor, dtype=float))
    t3 = time.perf_counter()
    order = np.argsort(w)
    w, X = w[order], X[:, order]
    normK = abs(Kc).sum(axis=1).max()
    res = [np.linalg.norm(Kc @ x - lmb * (Mc @ x)) / (normK * np.linalg.norm(x)) for lmb, x in zip(w, X.T)]
    return {"code": "GetFEM", "quadrature": "5/8", "parallel": 1, "dofs": mfu.nbdof(), "free_dofs": len(free),
            "t_read": t1 - t0, "t_assembly": t2 - t1, "t_factor": tf - t2, "t_eig": t3 - t2, "t_e2e": t3 - t0,
            "freqs": (np.sqrt(w) / (2 * np.pi)).tolist(), "solver": "cholmod + eigsh", "tol": tol,
            "max_residual": float(max(res)), "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def thread_env(threads: int) -> dict[str, str]:
    """The thread counts of every code's libraries.  OMP_THREAD_LIMIT too: CHOLMOD (SuiteSparse 5,
    in every code here) asks for 4 OpenMP threads in its factorisation whatever OMP_NUM_THREADS
    says; fem_squeal switches them off itself (fem_squeal.util.blas.serial_openmp), the peers'
    CHOLMOD needs the limit (GetFEM's factorisation at 26k DOFs: 0.27 s without it, 0.12 s with)."""
    n = str(threads)
    return {"OMP_NUM_THREADS": n, "OMP_THREAD_LIMIT": n, "OPENBLAS_NUM_THREADS": n, "MKL_NUM_THREADS": n,
            "CCX_NPROC_EQUATION_SOLVER": n, "CCX_NPROC_STIFFNESS": n, "CCX_NPROC_RESULTS": n,
            "NUMBER_OF_CPUS": n}


@contextlib.contextmanager
def threads(n: int):
    """``os.environ`` with the thread counts pinned (casework.spawn passes os.environ on)."""
    old = {k: os.environ.get(k) for k in thread_env(n)}
    os.environ.update(thread_env(n))
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def parse_ccx_dat(dat: Path) -> np.ndarray:
    """Eigenvalues [rad²/s²] of the EIGENVALUE OUTPUT block of a ccx .dat file."""
    vals, inside = [], False
    for line in dat.read_text().splitlines():
        if "E I G E N V A L U E   O U T P U T" in line:
            inside, vals = True, []
            continue
        if not inside:
            continue
        parts = line.split()
        if len(parts) >= 5 and parts[0].isdigit():
            vals.append(float(parts[1]))
        elif vals and parts:         # the next block (participation factors) ends the table
            break
    return np.array(vals)


def _ccx_process(folder: Path, job: str, n_threads: int, spooles_threads: int | None = None
                 ) -> tuple[float, float, str]:
    """Run ``ccx -i job`` in ``folder``: wall time [s], peak RSS [MB], log text."""
    env = dict(os.environ, **thread_env(n_threads))
    if spooles_threads is not None:
        env["CCX_NPROC_EQUATION_SOLVER"] = str(spooles_threads)
    log = folder / f"{job}.log"
    t0 = time.perf_counter()
    with open(log, "w") as out:
        proc = subprocess.Popen(["ccx", "-i", job], cwd=folder, stdout=out, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    text = log.read_text(errors="replace")
    if proc.returncode != 0 or "*ERROR" in text:
        tail = "\n".join(text.splitlines()[-20:])
        raise RuntimeError(f"ccx -i {job} failed (exit {proc.returncode}):\n{tail}")
    return wall, usage.ru_maxrss / 1024, text


def run_ccx(folder: Path, s: str, n_modes: int, n_threads: int, spooles_threads: int | None = None) -> dict:
    """ccx on ``n_threads`` (OMP_NUM_THREADS, OPENBLAS_NUM_THREADS, CCX_NPROC_*); ``spooles_threads``
    overrides CCX_NPROC_EQUATION_SOLVER (SPOOLES' threaded solve is slow in ccx's ARPACK loop)."""
    wall, rss, text = _ccx_process(folder, f"{s}_ccx", n_threads, spooles_threads)
    lam = parse_ccx_dat(folder / f"{s}_ccx.dat")
    if len(lam) != n_modes:
        raise RuntimeError(f"ccx: {len(lam)} eigenvalues in {s}_ccx.dat, expected {n_modes}")
    lines = text.splitlines()
    neq = next((int(lines[i + 1]) for i, ln in enumerate(lines) if ln.strip() == "number of equations"), -1)
    return {"code": "CalculiX", "quadrature": "4-pt", "parallel": n_threads,
            "variant": "" if spooles_threads in (None, n_threads) else f"SPOOLES on {spooles_threads}",
            "free_dofs": neq,
            "t_e2e": wall, "t_process": wall, "freqs": (np.sqrt(lam) / (2 * np.pi)).tolist(), "rss_mb": rss}


def ccx_read_time(folder: Path, s: str) -> float:
    return _ccx_process(folder, f"{s}_ccx_read", 1)[0]


def spawn(args: list[str], ranks: int = 1) -> dict:
    """A case in a fresh process (1 thread per rank); adds its process wall time."""
    with threads(1):
        t0 = time.perf_counter()
        r = casework.spawn(__file__, [str(a) for a in args], ranks)
        r["t_process"] = time.perf_counter() - t0
    return r


# ---------------------------------------------------------------- comparison

def rel_diff(a, b) -> float:
    """Largest relative difference of two frequency lists, each sorted (degenerate pairs)."""
    a, b = np.sort(np.asarray(a)), np.sort(np.asarray(b))
    n = min(len(a), len(b))
    return float(np.max(np.abs(a[:n] / b[:n] - 1.0)))


def label(r: dict) -> str:
    unit = "rank" if r["code"] == "fem_squeal" else "thread"
    q = {"auto": "default (M 7, K 5)", 2: "4-pt", "5/7": "K 5, M 7", "2/2": "4-pt",
         "4-pt": "4-pt"}[r["quadrature"]]
    v = f" ({r['variant']})" if r.get("variant") else ""
    return f"{r['code']} | {q} | {r['parallel']} {unit}{'s' if r['parallel'] > 1 else ''}{v}"


def short(r: dict) -> str:
    return label(r).replace(" | ", ", ")


def compare(meshes: list[dict], runs: dict, ref: dict, n_par: int) -> tuple[list[str], list[dict]]:
    """Markdown tables and the target summary."""
    L = ["### Runs", "",
         "Times in s; solve = assembly + eigensolve (ccx: end-to-end − its parse-only time); end-to-end = "
         "read + assembly + eigensolve (ccx: its process); process = whole process incl. Python start-up, "
         "imports and mpirun.  err: max over the modes of |f/f_ref − 1| (sorted frequencies).  Δ same mesh: "
         "max |f/f_fem − 1| against fem_squeal on 1 rank with the same quadrature (ccx: against the 4-pt "
         "fem_squeal run, and in brackets against the default one).", "",
         "| h [mm] | free DOFs | code | quadrature | parallel | read | assembly | eigensolve | solve | "
         "end-to-end | process | peak RSS [MB] | err vs ref | Δ same mesh |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    summary = []
    for mesh in meshes:
        rs = runs[mesh["stem"]]
        fem_auto = next(r for r in rs if r["code"] == "fem_squeal" and r["quadrature"] == "auto"
                        and r["parallel"] == 1)
        fem_4pt = next((r for r in rs if r["code"] == "fem_squeal" and r["quadrature"] == 2), None)
        for r in rs:
            r["err_ref"] = rel_diff(r["freqs"], ref["freqs"])
            four = r["quadrature"] in (2, "2/2", "4-pt")
            base = fem_4pt if four and fem_4pt is not None else fem_auto
            r["diff_same_mesh"] = rel_diff(r["freqs"], base["freqs"])
            r["diff_fem_default"] = rel_diff(r["freqs"], fem_auto["freqs"])
            r.setdefault("t_solve", r["t_e2e"] - r.get("t_read", 0.0))
            same = f"{r['diff_same_mesh']:.1e}"
            if four and base is not fem_auto:
                same += f" ({r['diff_fem_default']:.1e})"
            t = {k: f"{r[k]:.2f}" if k in r else "—" for k in ("t_read", "t_assembly", "t_eig")}
            L.append(f"| {mesh['h'] * 1e3:g} | {r['free_dofs']} | {label(r)} | {t['t_read']} | "
                     f"{t['t_assembly']} | {t['t_eig']} | {r['t_solve']:.2f} | {r['t_e2e']:.2f} | "
                     f"{r['t_process']:.2f} | {r['rss_mb']:.0f} | {r['err_ref']:.2e} | {same} |")
        for par in sorted({1, n_par}):
            fems = [r for r in rs if r["code"] == "fem_squeal" and r["parallel"] == par]
            peers = [r for r in rs if r["code"] != "fem_squeal" and r["parallel"] <= par]
            for fem in fems:
                agreeing = [p for p in peers if rel_diff(p["freqs"], fem["freqs"]) <= SAME]
                summary.append({"h": mesh["h"], "free_dofs": mesh["free_dofs"], "parallel": par, "fem": fem,
                                "peers": peers, "agreeing": agreeing})
    return L, summary


def summary_table(summary: list[dict]) -> list[str]:
    L = ["### Target: fem_squeal ≥ 2× faster than the fastest peer on the same mesh with the same "
         f"frequencies (max relative difference ≤ {SAME:g})", "",
         "Judged on end-to-end time (read + assembly + eigensolve; for ccx the whole process, which is what "
         "can be measured for it); the solve-only ratio (ccx: estimated) is given too.  A peer counts when "
         "its 20 sorted frequencies agree within the tolerance with that fem_squeal run's; the fastest "
         "peer of any agreement is listed for completeness.  With N ranks, fem_squeal meets each peer's "
         "best run on up to N threads (scikit-fem is serial: SuperLU).", "",
         "| h [mm] | free DOFs | ranks / threads | fem_squeal quadrature | fem_squeal end-to-end [s] | "
         "fastest agreeing peer | its end-to-end [s] | speed-up end-to-end | speed-up solve | ≥ 2×? | "
         "fastest peer overall (Δf) | speed-up end-to-end |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        fem = s["fem"]
        q = "default" if fem["quadrature"] == "auto" else "4-pt"
        if s["agreeing"]:
            p = min(s["agreeing"], key=lambda r: r["t_e2e"])
            sp, ss = p["t_e2e"] / fem["t_e2e"], p["t_solve"] / fem["t_solve"]
            ok = "yes" if sp >= 2 else "no"
            agree = (f"{short(p)} | {p['t_e2e']:.2f} | {sp:.2f}× | "
                     f"{ss:.2f}× | {ok}")
            s.update(peer=p["code"], speedup_e2e=sp, speedup_solve=ss, met=sp >= 2)
        else:
            agree = f"{'none agrees' if s['peers'] else 'peers not run'} | — | — | — | n/a"
            s.update(peer=None, speedup_e2e=None, speedup_solve=None, met=None)
        if s["peers"]:
            p = min(s["peers"], key=lambda r: r["t_e2e"])
            overall = (f"{short(p)} ({rel_diff(p['freqs'], fem['freqs']):.1e}) | "
                       f"{p['t_e2e'] / fem['t_e2e']:.2f}×")
        else:
            overall = "— | —"
        L.append(f"| {s['h'] * 1e3:g} | {s['free_dofs']} | {s['parallel']} | {q} | {fem['t_e2e']:.2f} | "
                 f"{agree} | {overall} |")
    L.append("")
    for par in sorted({s["parallel"] for s in summary}):
        for quad, what in (("auto", "default quadrature"), (2, "4-point rule, as ccx")):
            got = [s for s in summary if s["parallel"] == par and s["fem"]["quadrature"] == quad
                   and s["met"] is not None]
            if got:
                L.append(f"- fem_squeal on {par} rank{'s' if par > 1 else ''}, {what}: speed-up "
                         + ", ".join(f"{s['speedup_e2e']:.2f}× ({s['h'] * 1e3:g} mm, {s['peer']})" for s in got)
                         + f"; ≥ 2× on {sum(s['met'] for s in got)} of {len(got)} meshes.")
    return L


def frequency_table(mesh: dict, rs: list[dict], ref: dict, ref_mesh: dict) -> list[str]:
    cols = [r for r in rs if r["parallel"] == 1]
    L = [f"### Frequencies [Hz] on the {mesh['h'] * 1e3:g} mm mesh ({mesh['free_dofs']} free DOFs) and the "
         f"reference ({ref_mesh['h'] * 1e3:g} mm, {ref_mesh['free_dofs']} free DOFs)", "",
         "| mode | reference | " + " | ".join(short(r) for r in cols) + " |",
         "|---" * (len(cols) + 2) + "|"]
    fr = [np.sort(r["freqs"]) for r in cols]
    for i, f0 in enumerate(np.sort(ref["freqs"])):
        L.append(f"| {i + 1} | {f0:.3f} | " + " | ".join(f"{f[i]:.3f}" if i < len(f) else "—" for f in fr) + " |")
    return L


def plot(meshes: list[dict], runs: dict, ranks: int, quick: bool, n_par: int) -> None:
    from fem_squeal.app.plots import pyplot

    plt = pyplot()

    fig, ax = plt.subplots(figsize=(7, 5))
    styles = {"fem_squeal": ("C0", "o"), "CalculiX": ("C3", "s"), "scikit-fem": ("C2", "^")}
    series: dict[tuple, dict] = {}     # (code, parallel, quadrature) -> mesh -> fastest (time, error)
    if len(meshes) > 1:                # the reference mesh: its "errors" are only same-mesh differences
        meshes = [m for m in meshes if m["h"] > min(m["h"] for m in meshes)]
    for mesh in meshes:
        for r in runs[mesh["stem"]]:
            if r["err_ref"] < 1e-12:
                continue
            q = "4-pt" if r["quadrature"] in (2, "2/2") else ""
            pts = series.setdefault((r["code"], r["parallel"], q), {})
            pts[mesh["stem"]] = min(pts.get(mesh["stem"], (np.inf, 0.0)), (r["t_e2e"], r["err_ref"]))
    for (code, par, q), by_mesh in sorted(series.items()):
        pts = sorted(by_mesh.values())
        c, mk = styles[code]
        unit = "rank" if code == "fem_squeal" else "thread"
        ax.loglog(*zip(*pts), marker=mk, color=c, ls="-" if par == 1 else "--", mfc="none" if q else c,
                  label=f"{code}, {par} {unit}{'s' if par > 1 else ''}{', ' + q if q else ''}")
    ax.set_xlabel("end-to-end wall time (read + assembly + eigensolve) [s]")
    ax.set_ylabel("max relative frequency error (20 modes) vs finest fem_squeal")
    ax.set_title("Clamped annular disc, P2 / C3D10, same meshes")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    casework.save_plot(fig, "modal_peers", ranks, quick)
    plt.close(fig)


# ---------------------------------------------------------------- driver

def have_module(name: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(name) is not None


def have_skfem() -> bool:
    return have_module("skfem")


def fem_case(workdir: Path, s: str, n_modes: int, quadrature: int, ranks: int) -> dict:
    scene = workdir / f"{s}_q{quadrature}.toml"
    scene.write_text(scene_text(f"{s}.msh", n_modes, quadrature))
    return spawn(["fem", scene], ranks)


def run_all(sizes: list[float], n_modes: int, n_par: int, workdir: Path) -> tuple[list[dict], dict]:
    """Every mesh once, then on each: fem_squeal (default quadrature on 1 and n_par ranks, 4-point on 1),
    ccx (1 thread; n_par threads in its two settings), scikit-fem (same degrees as fem_squeal up to
    SKFEM_MAX_DOFS; 4-point up to SKFEM_4PT_MAX_DOFS)."""
    use_ccx, use_skfem = shutil.which("ccx") is not None, have_skfem()
    t_start = time.perf_counter()
    meshes = [spawn(["mesh", h, workdir, n_modes]) for h in sizes]
    # warm the dolfinx JIT cache (forms depend on the element and quadrature, not on the mesh size)
    for q in (AUTO, FOUR_POINT):
        fem_case(workdir, meshes[0]["stem"], n_modes, q, 1)
    runs: dict[str, list[dict]] = {}
    for mesh in meshes:
        s, msh = mesh["stem"], str(workdir / f"{mesh['stem']}.msh")
        rs = [fem_case(workdir, s, n_modes, AUTO, 1)]
        if n_par > 1:
            rs.append(fem_case(workdir, s, n_modes, AUTO, n_par))
        rs.append(fem_case(workdir, s, n_modes, FOUR_POINT, 1))
        if use_ccx:
            t_read = ccx_read_time(workdir, s)
            for n, spooles in [(1, None)] + ([(n_par, None), (n_par, 1)] if n_par > 1 else []):
                r = run_ccx(workdir, s, n_modes, n, spooles)
                r.update(t_read=t_read, t_solve=r["t_e2e"] - t_read)
                rs.append(r)
        if use_skfem and mesh["dofs"] <= SKFEM_MAX_DOFS:
            rs.append(spawn(["skfem", msh, n_modes, *SKFEM_AUTO]))
        if use_skfem and mesh["dofs"] <= SKFEM_4PT_MAX_DOFS:
            rs.append(spawn(["skfem", msh, n_modes, *SKFEM_4PT]))
        for r in rs:
            r["h"], r["dofs"] = mesh["h"], mesh["dofs"]
            if r["free_dofs"] != mesh["free_dofs"]:
                raise RuntimeError(f"{label(r)} on {s}: {r['free_dofs']} free DOFs, the mesh has "
                                   f"{mesh['free_dofs']}: not the same problem")
        runs[s] = rs
        print(f"{s}: {mesh['free_dofs']} free DOFs, {len(rs)} runs, "
              f"{time.perf_counter() - t_start:.0f} s so far", file=sys.stderr, flush=True)
    return meshes, runs


def speed_cases(workdir: Path, mesh: dict, n_modes: int) -> dict[str, object]:
    """--speed: each code's timed run on one mesh, as a function of no arguments, one thread each."""
    s, msh = mesh["stem"], str(workdir / f"{mesh['stem']}.msh")
    old = workdir / f"{s}_old.toml"
    old.write_text(scene_text(f"{s}.msh", n_modes, AUTO, OLD_DEFAULTS))
    new = workdir / f"{s}_q{AUTO}.toml"
    new.write_text(scene_text(f"{s}.msh", n_modes, AUTO))
    ks = workdir / f"{s}_ks.toml"       # the same defaults with SLEPc's Krylov–Schur for block Lanczos
    ks.write_text(scene_text(f"{s}.msh", n_modes, AUTO, {"real_block_size": 0}))
    cases = {"fem_squeal": lambda: spawn(["fem", new, "default"]),
             "fem_squeal before": lambda: spawn(["fem", old, "1e-10"]),
             "fem_squeal Krylov-Schur": lambda: spawn(["fem", ks, "default"])}
    if have_module("getfem") and have_module("sksparse"):
        cases["GetFEM"] = lambda: spawn(["getfem", msh, n_modes, SPEED_TOL])
    if have_skfem() and have_module("sksparse"):
        cases["scikit-fem"] = lambda: spawn(["skfem", msh, n_modes, *SKFEM_AUTO, SPEED_TOL, "cholmod"])
    if shutil.which("ccx") is not None:
        t_read = ccx_read_time(workdir, s)

        def ccx():
            r = run_ccx(workdir, s, n_modes, 1)
            r.update(t_read=t_read, t_assembly=float("nan"), t_factor=float("nan"), t_eig=r["t_e2e"] - t_read,
                     solver="SPOOLES + ARPACK")
            return r
        cases["CalculiX"] = ccx
    return cases


def run_speed(sizes: list[float], n_modes: int, repeats: int, workdir: Path, codes: list[str] | None = None
              ) -> tuple[list[dict], dict]:
    """Every code on every mesh, ``repeats`` times, interleaved (code after code, then again), so that
    a change of the machine's load hits all codes alike; the fastest repeat of each code is kept.
    ``codes``: the peers to run (fem_squeal's own cases always run)."""
    meshes = [spawn(["mesh", h, workdir, n_modes]) for h in sizes]
    fem_case(workdir, meshes[0]["stem"], n_modes, AUTO, 1)       # warm the JIT cache
    runs: dict[str, list[dict]] = {}
    for mesh in meshes:
        cases = {k: v for k, v in speed_cases(workdir, mesh, n_modes).items()
                 if codes is None or k.startswith("fem_squeal") or k in codes}
        got: dict[str, list[dict]] = {name: [] for name in cases}
        for rep in range(repeats):
            for name, case in cases.items():
                r = case()
                r["name"], r["h"], r["dofs"], r["rep"] = name, mesh["h"], mesh["dofs"], rep
                if r["free_dofs"] != mesh["free_dofs"]:
                    raise RuntimeError(f"{name} on {mesh['stem']}: {r['free_dofs']} free DOFs, the mesh has "
                                       f"{mesh['free_dofs']}: not the same problem")
                got[name].append(r)
                print(f"{mesh['stem']} #{rep} {name}: {speed_total(r):.2f} s", file=sys.stderr, flush=True)
        runs[mesh["stem"]] = [r for rs in got.values() for r in rs]
    return meshes, runs


def _s(v: float) -> str:
    return "—" if v != v else f"{v:.2f}"


def speed_total(r: dict) -> float:
    """assembly + factorisation + eigensolve (ccx: its process minus its parse-only run)."""
    return r["t_eig"] if r["code"] == "CalculiX" else r["t_assembly"] + r["t_eig"]


def render_speed(meshes: list[dict], runs: dict, n_modes: int, repeats: int) -> None:
    """The --speed tables: per mesh and code the fastest repeat's times, its frequency difference
    against fem_squeal before #23 (tol 1e-10) on the same mesh, and the ratios to the fastest peer."""
    L = [f"## Real modes against the fastest peer: clamped disc, {n_modes} modes, curved P2, 1 thread each", "",
         f"Same gmsh meshes for every code; {repeats} interleaved repeats, the fastest kept (spread in brackets: "
         "slowest/fastest total).  Times in s.  factor: the factorisation of K (σ = 0); eigensolve: the "
         "iterations after it (ccx: its process minus its parse-only run, not separable).  total = assembly + "
         "factor + eigensolve (reading the mesh excluded).  Δf: max relative frequency difference against "
         "fem_squeal before #23 (MUMPS LDLᵀ, tol 1e-10, purified) on the same mesh; \"same frequencies\" is "
         f"Δf ≤ {SAME:g}.  Peers' eigsh tol {SPEED_TOL:g} (fem_squeal's default; both are relative Ritz "
         "residuals of the shift-inverted operator).  Ratio: the fastest agreeing peer's time / fem_squeal's.", "",
         "| free DOFs | code | solver | assembly | factor | eigensolve | factor + eigensolve | total | Δf | "
         "peak RSS [MB] |", "|---|---|---|---|---|---|---|---|---|---|"]
    rows, summary = [], []
    for mesh in meshes:
        rs = runs[mesh["stem"]]
        ref = min((r for r in rs if r["name"] == "fem_squeal before"), key=speed_total)
        best = {}
        for name in dict.fromkeys(r["name"] for r in rs):
            mine = [r for r in rs if r["name"] == name]
            b = dict(min(mine, key=speed_total))
            b["spread"] = max(map(speed_total, mine)) / speed_total(b)
            b["t_eig_min"] = min(r["t_eig"] for r in mine)   # factor + eigensolve: its own fastest repeat
            b["df"] = rel_diff(b["freqs"], ref["freqs"])
            best[name] = b
            eig = b["t_eig"] - (0.0 if b["code"] == "CalculiX" else b["t_factor"])
            L.append(f"| {mesh['free_dofs']} | {name} | {b['solver']} | {_s(b['t_assembly'])} | "
                     f"{_s(b['t_factor'])} | {eig:.2f} | {b['t_eig']:.2f} | {speed_total(b):.2f} "
                     f"({b['spread']:.2f}) | {b['df']:.1e} | {b['rss_mb']:.0f} |")
        fem = best["fem_squeal"]
        peers = [b for n, b in best.items() if not n.startswith("fem_squeal") and b["df"] <= SAME]
        row = {"free_dofs": mesh["free_dofs"], "fem_total": speed_total(fem), "fem_eig": fem["t_eig_min"],
               "before_total": speed_total(best["fem_squeal before"]), "fem_df": fem["df"]}
        if peers:
            p_tot, p_eig = min(peers, key=speed_total), min(peers, key=lambda b: b["t_eig_min"])
            row.update(peer_total=p_tot["name"], peer_total_s=speed_total(p_tot),
                       peer_eig=p_eig["name"], peer_eig_s=p_eig["t_eig_min"])
        summary.append(row)
        rows += [{"kind": "run", **r} for r in rs]
    L += ["", "### Ratios (fastest agreeing peer / fem_squeal; target ≥ 2)", "",
          "Each time the fastest of its code's repeats (factor + eigensolve: its own fastest repeat).", "",
          "| free DOFs | fem_squeal total (before #23) | fastest peer, total | ratio total | ratio before | "
          "fem_squeal factor + eigensolve | fastest peer, factor + eigensolve | ratio | fem_squeal Δf |",
          "|---|---|---|---|---|---|---|---|---|"]
    for row in summary:
        if "peer_total" not in row:
            L.append(f"| {row['free_dofs']} | {row['fem_total']:.2f} ({row['before_total']:.2f}) | no peer agrees "
                     "| — | — | — | — | — | — |")
            continue
        L.append(f"| {row['free_dofs']} | {row['fem_total']:.2f} ({row['before_total']:.2f}) | "
                 f"{row['peer_total']} {row['peer_total_s']:.2f} | "
                 f"{row['peer_total_s'] / row['fem_total']:.2f}× | "
                 f"{row['peer_total_s'] / row['before_total']:.2f}× | {row['fem_eig']:.2f} | {row['peer_eig']} "
                 f"{row['peer_eig_s']:.2f} | {row['peer_eig_s'] / row['fem_eig']:.2f}× | {row['fem_df']:.1e} |")
    rows += [{"kind": "mesh", **m} for m in meshes] + [{"kind": "summary", **r} for r in summary]
    casework.save("modal_peers_speed", L, rows, 1, False)


def render(meshes: list[dict], runs: dict, n_modes: int, n_par: int, ranks: int, quick: bool) -> None:
    """Tables (printed and saved), JSON rows and the plot."""
    ref_mesh = min(meshes, key=lambda m: m["h"])
    ref = next(r for r in runs[ref_mesh["stem"]] if r["code"] == "fem_squeal" and r["parallel"] == 1
               and r["quadrature"] == "auto")
    skipped = [f"scikit-fem above {SKFEM_MAX_DOFS // 1000}k DOFs (serial SuperLU: 2 min and 7 GB at 255k, "
               "extrapolated 6 min and 14 GB at 437k)", f"its 4-point run above {SKFEM_4PT_MAX_DOFS // 1000}k"]
    L = [f"## Modal analysis against peers: clamped annular disc, {n_modes} modes, P2 / C3D10 "
         f"({'quick' if quick else 'full'}, parallel runs on {n_par})", "",
         f"Disc r {R_IN}..{R_OUT} m, thickness {THICKNESS} m, steel E {E:.3g} Pa, ν {NU}, ρ {RHO:g} kg/m³, "
         "clamped on r = 0.06.  Same gmsh mesh (curved P2) for every code; mesh generation is not timed.  "
         f"Reference: fem_squeal (default quadrature, 1 rank) on the finest mesh, {ref_mesh['h'] * 1e3:g} mm "
         f"({ref_mesh['free_dofs']} free DOFs){' — the only mesh of the quick run' if quick else ''}.  "
         f"Not run: {'; '.join(skipped)}.  "
         f"Eigen-solver tolerances: fem_squeal and scikit-fem {EIG_TOL:g}, ccx ARPACK 1e-2 (fixed in ccx).  "
         "2-core machine; every time is a single run.", ""]
    tables, summary = compare(meshes, runs, ref, n_par)
    L += tables + [""] + summary_table(summary) + [""]
    peer_meshes = [m for m in meshes if any(r["code"] != "fem_squeal" for r in runs[m["stem"]])]
    show = max((m for m in peer_meshes if any(r["code"] == "scikit-fem" for r in runs[m["stem"]])),
               key=lambda m: m["dofs"], default=ref_mesh)
    L += frequency_table(show, runs[show["stem"]], ref, ref_mesh)
    rows = [{"kind": "mesh", **m} for m in meshes] + \
        [{"kind": "run", **r} for m in meshes for r in runs[m["stem"]]] + \
        [{"kind": "summary", "fem_parallel": s["fem"]["parallel"], "fem_quadrature": s["fem"]["quadrature"],
          "fem_e2e": s["fem"]["t_e2e"], **{k: v for k, v in s.items() if k not in ("fem", "peers", "agreeing")}}
         for s in summary]
    casework.save("modal_peers", L, rows, ranks, quick)
    plot(meshes, runs, ranks, quick, n_par)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs="+")
    ap.add_argument("--ranks", type=int, default=1, help="fem_squeal ranks and ccx threads of the parallel runs")
    ap.add_argument("--quick", action="store_true", help=f"one mesh ({QUICK_SIZES[0]} m), {QUICK_MODES} modes")
    ap.add_argument("--workdir", help="keep the meshes and solver files here (default: a temporary folder)")
    ap.add_argument("--render", metavar="JSON", help="only re-write the tables and plot from a saved .json")
    ap.add_argument("--speed", action="store_true", help="real modes against the fastest peer (issue #23): "
                    "26k, 87k, 260k DOFs, every code on 1 thread, interleaved repeats")
    ap.add_argument("--repeats", type=int, default=3, help="--speed: repeats of each code")
    ap.add_argument("--codes", nargs="+", help="--speed: the peers to run (GetFEM, scikit-fem, CalculiX; "
                    "default all)")
    ap.add_argument("--sizes", type=float, nargs="+", help=f"--speed: mesh sizes [m] (default {SPEED_SIZES})")
    a = ap.parse_args()
    if a.case:
        kind, *args = a.case
        if kind == "mesh":
            casework.report(make_mesh(float(args[0]), args[1], int(args[2])))
        elif kind == "fem":
            casework.report(run_fem(*args))
        elif kind == "skfem":
            casework.report(run_skfem(args[0], int(args[1]), int(args[2]), int(args[3]),
                                      *([float(args[4]), args[5]] if len(args) > 4 else [])))
        elif kind == "getfem":
            casework.report(run_getfem(args[0], int(args[1]), float(args[2])))
        else:
            raise SystemExit(f"unknown case {kind}")
        return
    n_modes = QUICK_MODES if a.quick else N_MODES
    t_start = time.perf_counter()
    if a.speed and a.render:
        rows = json.loads(Path(a.render).read_text())
        meshes = [{k: v for k, v in r.items() if k != "kind"} for r in rows if r["kind"] == "mesh"]
        runs = {m["stem"]: [r for r in rows if r["kind"] == "run" and r["h"] == m["h"]] for m in meshes}
        render_speed(meshes, runs, n_modes, 1 + max(r["rep"] for rs in runs.values() for r in rs))
        return
    if a.speed:
        with contextlib.ExitStack() as stack:
            workdir = Path(a.workdir or stack.enter_context(tempfile.TemporaryDirectory(prefix="modal_speed_")))
            workdir.mkdir(parents=True, exist_ok=True)
            meshes, runs = run_speed(list(a.sizes or SPEED_SIZES), n_modes, a.repeats, workdir.resolve(),
                                     a.codes)
        render_speed(meshes, runs, n_modes, a.repeats)
        print(json.dumps({"wall_s": time.perf_counter() - t_start}), file=sys.stderr)
        return
    if a.render:
        rows = json.loads(Path(a.render).read_text())
        meshes = [{k: v for k, v in r.items() if k != "kind"} for r in rows if r["kind"] == "mesh"]
        runs = {m["stem"]: [r for r in rows if r["kind"] == "run" and r["h"] == m["h"]] for m in meshes}
        n_modes = len(runs[meshes[0]["stem"]][0]["freqs"])
        n_par = max(r["parallel"] for rs in runs.values() for r in rs)
    else:
        n_par = a.ranks
        sizes = list(QUICK_SIZES if a.quick else SIZES)
        with contextlib.ExitStack() as stack:
            if a.workdir:
                workdir = Path(a.workdir).resolve()
                workdir.mkdir(parents=True, exist_ok=True)
            else:
                workdir = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="modal_peers_")))
            meshes, runs = run_all(sizes, n_modes, n_par, workdir)
    render(meshes, runs, n_modes, n_par, a.ranks, a.quick)
    print(json.dumps({"wall_s": time.perf_counter() - t_start}), file=sys.stderr)


if __name__ == "__main__":
    main()
