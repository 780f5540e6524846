"""The spinning disc (issue 20 item 4) two ways: against CalculiX 2.20 and between the two frames.

Model: an annular steel disc (r 0.05–0.15 m, h 0.01 m, E 210 GPa, ν 0.3, ρ 7850 kg/m³), clamped on its
inner cylinder, P2 curved tetrahedra (C3D10) from one gmsh mesh that both codes read (the Abaqus deck
written by ``fem_squeal.app.convert``), spinning at Ω about z.

(b) Rotating frame against ``*COMPLEX FREQUENCY, CORIOLIS``.  What ccx solves (complexfreq.c,
coriolissolve.f of CalculiX): the ``*FREQUENCY, STORAGE=YES`` step's nev real modes Φ of K φ = ω² M φ
(its ``*DLOAD, CENTRIF`` changes nothing there without a preceding static step: measured, the
frequencies are identical with and without it, i.e. no spin softening and no prestress), then the
gyroscopic problem projected on them, (−ω² I + iω Φᵀ G_c Φ + diag ω_j²) q = 0 with
G_c = 2Ω∫ρ (e_z × u)·v, by a Newton iteration per mode that drops an eigenvalue within 2e-3 of one
found already (close doublets appear once).  fem_squeal runs the same model: K, M with ccx's 4-point
rule (``quadrature_degree = 2``, benchmarks/modal_peers.py), ``rotation_matrices(frame="rotating")``
for G_c and no spin softening, (a) projected on its own nev lowest modes like ccx, (b) the full PEP.
Columns: ccx, Δ of the projected and of the full fem_squeal eigenvalue to ccx.

(a) Transport (space-fixed) form against the rotating frame, both with their Ω² terms (−Ω² K_L,
−Ω² M_r) and the default quadrature.  For a k-diameter doublet the continuum relation is
ω_fixed = ω_rot ± kΩ (forward/backward wave).  The mesh is not axisymmetric: at Ω = 0 each doublet
is split by δ₀, and a doublet-pair model gives in either frame ω = c ± ½√(δ₀² + (2gΩ)²) with c the
centre and g the frame's gyroscopic coupling (g_fixed = k + g_rot, the continuum relation).  So the raw
relation holds only to δ₀/2 per eigenvalue (the tolerance), while the centres c and the couplings
g = √(s² − δ₀²)/(2Ω) (s the observed split) obey it to the discretisation error of ∂/∂θ on the mode.

With ``prestress`` (the centrifugal stress stiffening of item 5): ccx runs a ``*STATIC, NLGEOM`` step
under the centrifugal load first and the eigen steps as perturbations about it; fem_squeal adds
K_σ(σ₀) of the linear static response K u_c = Ω² f_c, with and without the spin softening −Ω² M_r.

    .venv/bin/python benchmarks/coriolis_calculix.py [--quick] [--speed 1000] [--workdir DIR]

Writes benchmarks/out/coriolis_calculix[_quick].json and .md.

Measured (default: mesh size 0.015 m, 4996 nodes, nev = 20; the whole run takes ~3 min on 1 rank):

* no prestress, Ω = 1000 rad/s: fem_squeal projected on its 20 modes = ccx to 2.5e-7 (the 7 digits of the
  .dat file) for all 12 eigenvalues ccx prints; the full PEP also agrees to 2.5e-7 except the k = 0
  in-plane mode at 3702 Hz (−2.6e-4: ccx's 20-mode truncation) and the 20th mode (outside the PEP's set).
  Times: ccx 4.4 s (both steps), fem_squeal projected 5.2 s, full PEP 19.7 s.
* centrifugal prestress: ccx includes the spin softening after its NLGEOM static step (its k = 0 in-plane
  mode, −6e-6 with −Ω² M_r, +2.2e-4 without).  With it, fem_squeal's bending modes are 1.3–2.2e-5
  above ccx at Ω = 500 rad/s and 3.3–5.6e-6 at 250 rad/s (the stiffening itself is +7.5e-3 at 500):
  the residual scales with Ω², i.e. with the centrifugal strain ρΩ²r²/E (2e-4 at 500 rad/s), which
  ccx's NLGEOM geometry update carries and a linear prestress does not.
* frames: the raw relation ω_fixed = ω_rot ± kΩ holds within δ₀/2 for every k ≥ 2 at Ω = 50 and
  300 rad/s, with and without the prestress; centres and couplings agree to ≤ 1e-5 kΩ.  The exception is
  k = 1 at Ω = 50 rad/s (coupling 3e-3 kΩ, raw error 1.8 δ₀/2): its forward wave (815.1 Hz) lies 0.7 Hz
  from the k = 0 mode (814.4 Hz), which the non-axisymmetric mesh couples to it (at 300 rad/s: 1.4e-4).
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from casework import ccx_nodes  # noqa: E402
from cea_calculix import read_complex_dat, run_ccx  # noqa: E402

R_IN, R_OUT, H = 0.05, 0.15, 0.01
E, NU, RHO = 2.1e11, 0.3, 7850.0
TWO_PI = 2 * np.pi


def make_mesh(folder: Path, h: float) -> dict:
    """gmsh P2 disc → disc.msh → Abaqus disc.inp (C3D10); the clamp node set (1-based)."""
    from mpi4py import MPI

    from fem_squeal.app.convert import write_mesh_file
    from geometry.annular_disc import annular_disc_model
    from geometry.gmsh_io import write_msh
    from geometry.mesh_file import _facet_nodes, read_mesh_file

    write_msh(MPI.COMM_SELF, annular_disc_model(mean_radius=0.5 * (R_IN + R_OUT), width=R_OUT - R_IN,
                                                thickness=H, mesh_size=h, order=2), folder / "disc.msh")
    mf = read_mesh_file(folder / "disc.msh")
    write_mesh_file(mf, folder / "disc.inp")
    ccx_nodes(folder / "disc.inp")
    clamp = np.unique(np.concatenate([_facet_nodes(mf.cells[c], f) for c, f in mf.surfaces["inner"]]))
    return {"nodes": len(mf.points), "elements": len(mf.cells), "clamp": clamp + 1}


def ccx_deck(mesh: dict, speed: float, nev: int, prestress: bool = False) -> str:
    """``prestress``: a ``*STATIC`` NLGEOM step under the centrifugal load first, the two eigen steps as
    perturbations about it (its stress enters their stiffness)."""
    clamp = [", ".join(str(int(n)) for n in mesh["clamp"][i:i + 8]) for i in range(0, len(mesh["clamp"]), 8)]
    centrif = f"disc, CENTRIF, {speed ** 2:.10e}, 0., 0., 0., 0., 0., 1."
    pert = ", PERTURBATION" if prestress else ""
    static = ["*STEP, NLGEOM", "*STATIC", "*DLOAD", centrif, "*END STEP"] if prestress else []
    lines = ["*INCLUDE, INPUT=disc.inp", "*NSET, NSET=CLAMP", *clamp,
             "*MATERIAL, NAME=STEEL", "*ELASTIC", f"{E:.6e}, {NU}", "*DENSITY", f"{RHO}",
             "*SOLID SECTION, ELSET=disc, MATERIAL=STEEL", "*BOUNDARY", "CLAMP, 1, 3", *static,
             f"*STEP{pert}", "*FREQUENCY, STORAGE=YES", f"{nev}", "*DLOAD", centrif, "*END STEP",
             f"*STEP{pert}", "*COMPLEX FREQUENCY, CORIOLIS", f"{nev}", "*DLOAD", centrif, "*END STEP"]
    return "\n".join(lines) + "\n"


def fem_model(folder: Path, quadrature_degree: int | None):
    from mpi4py import MPI

    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.model import Material, ModelSpec
    from geometry import BUILDERS

    md = BUILDERS["mesh_file"](MPI.COMM_WORLD, file=str(folder / "disc.inp"), format="", scale=1.0,
                               center=[0.0, 0.0, 0.0], axis=[0.0, 0.0, 1.0], id_field="", max_aspect_ratio=10.0,
                               parts={"disc": ["disc"]}, faces={"inner": ["inner"]})
    spec = ModelSpec({"disc": Material(E, NU, RHO)}, clamped=("inner",), quadrature_degree=quadrature_degree)
    return md, spec, assemble_operators(md, spec)


def _dense(A) -> np.ndarray:
    from scipy.sparse import csr_matrix

    ia, ja, a = A.getValuesCSR()
    return csr_matrix((a, ja, ia), shape=A.getSize()).toarray()


def projected(K, M, Gc, speed: float, nev: int) -> np.ndarray:
    """ccx's COMPLEX FREQUENCY: the gyroscopic problem on the nev lowest real modes (dense, λ with Im > 0)."""
    from fem_squeal.fe.eigen import solve_real_modes

    rm = solve_real_modes(K, M, nev, 0.0)
    Phi = np.column_stack([v.array.copy() for v in rm.vectors])
    g = Phi.T @ _dense(Gc) @ Phi * speed
    g = 0.5 * (g - g.T)
    n = len(rm.omega2)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.diag(rm.omega2), -g]])
    lam = np.linalg.eigvals(A)
    return np.sort_complex(lam[lam.imag > 0])


def full(K, M, C, n: int, target_hz: float) -> np.ndarray:
    from fem_squeal.fe.eigen import solve_complex_modes

    return solve_complex_modes(K, M, C, n, target_hz, method="pep").eigenvalues


def run_ccx_case(folder: Path, mesh: dict, speed: float, nev: int, prestress: bool) -> tuple[np.ndarray, float]:
    job = "spin_pre" if prestress else "spin"
    (folder / f"{job}.inp").write_text(ccx_deck(mesh, speed, nev, prestress))
    t = run_ccx(folder, job)
    text = (folder / f"{job}.dat").read_text()
    i = text.rfind("E I G E N V A L U E   O U T P U T")     # the complex step's table (the last one)
    (folder / f"{job}_complex.dat").write_text(text[i:])
    return read_complex_dat(folder / f"{job}_complex.dat"), t


def calculix_table(folder: Path, mesh: dict, speed: float, nev: int, prestress: bool = False) -> dict:
    """ccx against fem_squeal's rotating frame: K (+ K_σ of the centrifugal static state with
    ``prestress``), Ω G_c; projected on nev modes like ccx, and the full PEP.  With ``prestress`` the
    projected problem is also solved with the spin softening −Ω² M_r (which ccx does not add)."""
    from petsc4py import PETSc

    from fem_squeal.fe.assembly import geometric_stiffness, rotation_matrices, static_displacement

    s_ccx, t_ccx = run_ccx_case(folder, mesh, speed, nev, prestress)
    t0 = time.perf_counter()
    md, spec, ops = fem_model(folder, 2)
    rot = rotation_matrices(ops, md, spec, ["disc"], "rotating")
    K = ops.K
    if prestress:
        f = rot.f.copy()
        f.scale(speed ** 2)
        Ks = geometric_stiffness(ops, md, spec, static_displacement(ops.K, f))
        K = ops.K.copy()
        K.axpy(1.0, Ks, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    t1 = time.perf_counter()
    lam_p = projected(K, ops.M, rot.G, speed, nev)
    t2 = time.perf_counter()
    C = rot.G.copy()
    C.scale(speed)
    top = float(np.max(s_ccx.imag)) / TWO_PI
    lam_f = full(K, ops.M, C, nev + 16, 0.5 * top)
    t3 = time.perf_counter()
    lam_s = None
    if prestress:
        Ksoft = K.copy()
        Ksoft.axpy(-speed ** 2, rot.S, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        lam_s = projected(Ksoft, ops.M, rot.G, speed, nev)
    rows = []
    for s in s_ccx[s_ccx.imag > 0]:
        p = lam_p[np.argmin(np.abs(lam_p - s))]
        f = lam_f[np.argmin(np.abs(lam_f - s))]
        row = {"f_ccx": s.imag / TWO_PI, "f_proj": p.imag / TWO_PI, "f_full": f.imag / TWO_PI,
               "d_proj": p.imag / s.imag - 1, "d_full": f.imag / s.imag - 1}
        if lam_s is not None:
            q = lam_s[np.argmin(np.abs(lam_s - s))]
            row.update(f_soft=q.imag / TWO_PI, d_soft=q.imag / s.imag - 1)
        rows.append(row)
    return {"speed": speed, "nev": nev, "prestress": prestress, "ccx_seconds": t_ccx,
            "fem_assembly_seconds": t1 - t0, "fem_projected_seconds": t2 - t1, "fem_full_seconds": t3 - t2,
            "rows": rows}


def _describe(ops, cm):
    from fem_squeal.fe.descriptors import CircumferentialBasis

    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    return [basis.describe(a, b) for a, b in zip(cm.vectors_re, cm.vectors_im)]


def frames_table(folder: Path, speed: float, n: int, prestress: bool = False) -> dict:
    """(a): fixed vs rotating frame with their Ω² terms (and both with the same K_σ of the centrifugal
    static state with ``prestress``), per k-diameter doublet (module doc)."""
    from petsc4py import PETSc

    from fem_squeal.fe.assembly import geometric_stiffness, rotation_matrices, static_displacement
    from fem_squeal.fe.eigen import solve_complex_modes

    md, spec, ops = fem_model(folder, None)
    out = {}
    t0 = time.perf_counter()
    rots = {fr: rotation_matrices(ops, md, spec, ["disc"], fr) for fr in ("fixed", "rotating")}
    Ks = None
    if prestress:
        f = rots["fixed"].f.copy()
        f.scale(speed ** 2)
        Ks = geometric_stiffness(ops, md, spec, static_displacement(ops.K, f))
    for frame, om in (("rest", 0.0), ("rotating", speed), ("fixed", speed)):
        r = rots["fixed" if frame == "rest" else frame]
        K = ops.K.copy()
        K.axpy(-om ** 2, r.S, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        if Ks is not None:
            K.axpy(1.0 if om > 0 else 0.0, Ks, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        C = r.G.copy()
        C.scale(om)
        cm = solve_complex_modes(K, ops.M, C, n, 1500.0, method="pep")
        out[frame] = (cm.eigenvalues.imag / TWO_PI,
                      [(d.nodal_diameter, d.travelling_index) for d in _describe(ops, cm)])
    t1 = time.perf_counter()
    rows = []
    for k in range(1, 6):
        pick = {fr: sorted((f, tau) for f, (kk, tau) in zip(*out[fr]) if kk == k) for fr in out}
        if any(len(p) != 2 for p in pick.values()):
            continue
        (r1, t1_), (r2, t2_) = pick["rotating"]
        (f1, tf1), (f2, tf2) = pick["fixed"]
        d0 = pick["rest"][1][0] - pick["rest"][0][0]
        kf = k * speed / TWO_PI
        # rotating frame: the mode with τ > 0 travels forward (+θ); fixed: forward = rot forward + kΩ
        r_fw, r_bw = (r1, r2) if t1_ > t2_ else (r2, r1)
        f_fw, f_bw = (f2, f1) if tf2 > tf1 else (f1, f2)
        raw = max(abs(f_fw - (r_fw + kf)), abs(f_bw - (r_bw - kf)))
        c_r, c_f = 0.5 * (r1 + r2), 0.5 * (f1 + f2)
        g_r = np.sign(r_fw - r_bw) * np.sqrt(max((r2 - r1) ** 2 - d0 ** 2, 0.0)) / 2
        g_f = np.sqrt(max((f2 - f1) ** 2 - d0 ** 2, 0.0)) / 2
        rows.append({"k": k, "f_rest": pick["rest"][0][0], "delta0": d0, "kOmega_hz": kf,
                     "f_rot": [r_bw, r_fw], "f_fixed": [f_bw, f_fw], "raw_error": raw, "tolerance": d0 / 2,
                     "centre_error": c_f - c_r, "coupling_error": g_f - (kf + g_r),
                     "coupling_rel": (g_f - (kf + g_r)) / kf})
    return {"speed": speed, "prestress": prestress, "seconds": t1 - t0, "rows": rows}


def tables(res: dict) -> str:
    lines = []
    for c in res["calculix"]:
        soft = c["prestress"]
        lines += [f"(b) rotating frame vs ccx *COMPLEX FREQUENCY, CORIOLIS: Ω = {c['speed']:g} rad/s, "
                  f"{'centrifugal prestress (ccx: *STATIC, NLGEOM first)' if soft else 'no prestress'}, "
                  f"nev = {c['nev']}, {res['nodes']} nodes; ccx {c['ccx_seconds']:.1f} s, fem_squeal assembly "
                  f"{c['fem_assembly_seconds']:.1f} s, projected {c['fem_projected_seconds']:.1f} s, "
                  f"full PEP {c['fem_full_seconds']:.1f} s", "",
                  "| f ccx [Hz] | f fem projected [Hz] | Δ/f projected | f fem full [Hz] | Δ/f full |"
                  + (" Δ/f projected with −Ω²M_r |" if soft else ""),
                  "|---|---|---|---|---|" + ("---|" if soft else "")]
        for r in c["rows"]:
            full = f"{r['f_full']:.4f} | {r['d_full']:+.1e}" if abs(r["d_full"]) < 1e-3 else \
                "not among the PEP's modes | –"
            lines.append(f"| {r['f_ccx']:.4f} | {r['f_proj']:.4f} | {r['d_proj']:+.1e} | {full} |"
                         + (f" {r['d_soft']:+.1e} |" if soft else ""))
        lines.append("")
    for a in res["frames"]:
        lines += [f"(a) fixed (transport) vs rotating frame, Ω = {a['speed']:g} rad/s, "
                  f"{'both with the centrifugal K_σ' if a['prestress'] else 'no prestress'} "
                  f"({a['seconds']:.1f} s): errors in Hz", "",
                  "| k | f(Ω=0) | δ₀ | kΩ/2π | rot bw, fw | fixed bw, fw | raw error | δ₀/2 | centre error "
                  "| coupling error | rel. to kΩ |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in a["rows"]:
            lines.append(f"| {r['k']} | {r['f_rest']:.3f} | {r['delta0']:.2e} | {r['kOmega_hz']:.3f} | "
                         f"{r['f_rot'][0]:.3f}, {r['f_rot'][1]:.3f} | {r['f_fixed'][0]:.3f}, "
                         f"{r['f_fixed'][1]:.3f} | {r['raw_error']:.1e} | {r['tolerance']:.1e} | "
                         f"{r['centre_error']:+.1e} | {r['coupling_error']:+.1e} | {r['coupling_rel']:+.1e} |")
        lines.append("")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--speed", type=float, default=1000.0, help="Ω [rad/s] of the ccx comparison")
    ap.add_argument("--prestress-speeds", type=float, nargs="+", default=[500.0, 250.0],
                    help="Ω [rad/s] of the prestressed ccx cases")
    ap.add_argument("--frame-speeds", type=float, nargs="+", default=[50.0, 300.0])
    ap.add_argument("--nev", type=int, default=20)
    ap.add_argument("--mesh-size", type=float, default=None)
    ap.add_argument("--workdir", default=None)
    args = ap.parse_args()
    h = args.mesh_size or (0.025 if args.quick else 0.015)
    folder = Path(args.workdir or tempfile.mkdtemp(prefix="coriolis_ccx_"))
    folder.mkdir(parents=True, exist_ok=True)
    mesh = make_mesh(folder, h)
    res = {"h": h, "nodes": mesh["nodes"], "elements": mesh["elements"],
           "calculix": [calculix_table(folder, mesh, args.speed, args.nev)]
           + [calculix_table(folder, mesh, om, args.nev, prestress=True) for om in args.prestress_speeds],
           "frames": [frames_table(folder, om, 12, pre) for om in args.frame_speeds for pre in (False, True)]}
    text = tables(res)
    print(text)
    out = ROOT / "benchmarks" / "out"
    out.mkdir(exist_ok=True)
    name = f"coriolis_calculix{'_quick' if args.quick else ''}"
    (out / f"{name}.json").write_text(json.dumps(res, indent=1, default=float))
    (out / f"{name}.md").write_text(f"h = {h}, {mesh['nodes']} nodes, {mesh['elements']} C3D10\n\n{text}\n")
    print(folder)


if __name__ == "__main__":
    if shutil.which("ccx") is None:
        sys.exit("ccx not found: apt-get install -y calculix-ccx")
    main()
