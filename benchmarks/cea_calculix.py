"""Frictional CEA against CalculiX 2.20 on the same mesh: the Ryzhik ring between two rigid plates.

Model (both codes, one gmsh mesh written as an Abaqus deck for ccx and read back by fem_squeal):
ring R 0.05 m, b 0.005 m, h 0.004 m, P2 curved tetrahedra (C3D10), E 3 GPa, ν 0.4, ρ 1400 kg/m³,
pressed between two rigid plates through a penalty k_n (1e13 N/m³, ``--kn``) with sliding friction μ, both
plates sliding in +e_θ relative to the ring.  The ring's inner cylinder is held in x and y
(``boundary.fixed``): a static step needs the ring held against the friction torque.

fem_squeal: ``RigidPlate(face, k_n, μ, +1, k_t)`` on the top and bottom faces (linear penalty, all
closed), CEA of (K + K_f) x = −λ² M x.

CalculiX (the recipe of the issue): the plates are C3D8 annuli whose nodes are all prescribed (rigid),
node-to-surface penalty contact (slave: the ring's face, master: the plate's), PRESSURE-OVERCLOSURE=LINEAR
with slope k_n, *FRICTION μ_static = 1.001 μ with stick slope λ = k_n/10;
step 1 *STATIC presses the plates by d = p/k_n (p = 0.1 MPa), step 2 *STATIC turns them by a small angle (slip
≫ the elastic slip μ p/λ), step 3 *STEP, PERTURBATION with *FREQUENCY and *CHANGE FRICTION back to μ:
every node slides, and the slip-state tangent keeps λ μ/μ_static = λ/F across the sliding direction.
So fem_squeal runs with k_t = λ/F (F = 1.001), and with k_t = 0 (the seed 001 model) for contrast.
The .dat file lists complex eigenfrequencies ω; s = iω, Re(s) = −Im(ω).

    .venv/bin/python benchmarks/cea_calculix.py [--quick] [--mu 0.3] [--kn 1e13] [--workdir DIR] [--deck]

Writes benchmarks/out/cea_calculix[_quick].json and .md.

``--deck``: the deck ccx runs is run as it is by ``fem-squeal run ring_muX.inp`` (the scene of
:mod:`fem_squeal.app.deck`, converted in memory); its eigenvalues against the hand-built model of
:func:`fem_cea` at the run's n_modes and target (the same model: |Δλ|/|λ|), and against ccx's
(unstable pairs, f, Re s).  Writes benchmarks/out/cea_calculix_deck[_quick].json and .md.

Measured (h 3 mm ``--quick``: 1457 C3D10; k_n = 1e13, λ = k_n/10, fem_squeal with k_t = λ/F; ccx 23 s per
μ on a quiet machine; 24 modes, the same 12 unstable pairs in both codes at every μ):

| μ | h | Δf/f | ΔRe(s)/Re(s) | k_t = 0 (seed 001): ΔRe(s)/Re(s) |
|---|---|---|---|---|
| 0.1 | 3 mm | −1.3e-4 … +1.4e-4 | +0.36 … +0.51 % | −28 … −88 % |
| 0.3 | 3 mm | −1.4e-4 … +1.6e-4 | +0.36 … +0.52 % | −28 … −75 % |
| 0.6 | 3 mm | −1.6e-4 … +1.8e-4 | +0.36 … +0.54 % | −28 … −63 % |

Frequencies within 1.8e-4 (target 1e-3) and growth rates within 0.54 % (target 2 %) at all three μ.
Until SLIP was lowered from 2e-4 to 2e-6 the frequencies were off by ≈ −6.5e-3·μ (−4.0e-3 at μ = 0.6):
not a missing friction term but ccx's slip direction tilted by φ = 7.65e-3 rad towards e_r by the
plates' finite rotation (see SLIP).  Found by rebuilding ccx's own stiffness (``*STEP`` with
``SOLVER=MATRIXSTORAGE``, which reproduces its .dat eigenvalues to 1e-7): per contact node and per
k_n a it holds nn 0.999, rr 0.0998 (= λ/(F k_n)), θn −0.2998 (= −μ), and rθ −0.00076 = −φ·0.0998,
rn −0.0023 = −φμ; tilting t₂ by that φ in fem_squeal's forms reproduces the old offset.

``--deck`` (h 3 mm ``--quick``, 24 modes): the deck run by ``fem-squeal run`` equals the hand-built model to
3.4e-15 … 9.5e-15 (max |Δλ|/|λ|) and so finds CalculiX's 12 unstable pairs at μ = 0.1, 0.3, 0.6, Δf/f within
1.8e-4, ΔRe(s)/Re(s) +0.36 … +0.54 %.

History: the earlier runs placed the plates at z ∈ [H, H + T] and [−T, 0] while the ring spans
[−H/2, H/2] (ccx resolved it by a 2 mm rigid shift in the static step) and used ccx's default σ∞:
ccx's LINEAR law is smoothed, p = K d (1/2 + atan(d/ε)/π) with ε = π σ∞/K (springforc_n2f.f), so its
tangent at the press was 0.5–0.86 K (the "effective penalty 0.855 k_n", Re(s) 9–11 % off).  A static
press at k_n = 1e10 now gives the plate force K A d to 0.1 % (156.0 N for 156.0 N).
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from casework import ccx_nodes, ccx_real  # noqa: E402

R, B, H = 0.05, 0.005, 0.004
E, NU, RHO = 3e9, 0.4, 1400.0
KN = 1e13                   # penalty [N/m³] (--kn)
F_STATIC = 1.001            # μ_static / μ of the sliding steps
P_PRESS = 1e5               # contact pressure of the press [Pa]: the plates move by d = p/k_n
#: ccx's LINEAR node-to-face law is smoothed, p = K d (1/2 + atan(d/ε)/π) with ε = π σ∞/K (ccx source
#: springforc_n2f.f): its tangent is K only for d ≫ ε.  σ∞ (the tension at large clearances) = P/1000
#: puts the press d = P/K at d/ε = 1000/π, where the tangent is K to 1e-6; ccx's default σ∞ left the
#: tangent at 0.5–0.86 K (the "effective penalty 0.855 k_n" of the earlier runs)
SIGMA_INF = P_PRESS / 1000
#: slip at the mean radius in the sliding step [m]: ≫ the elastic slip μ p/λ (≤ 6e-8 m at μ = 0.6) so that
#: every node slides, and small, because ccx measures the slip increment as the change of u_slave −
#: u_master at the master's projection point: for a plate turned by u = θ e_z × X the last increment
#: has a radial part (θ_n² − θ_{n−1}²) r e_r, and the slip direction t̂ (with it t₂ = n × t̂, where the
#: cross-slip penalty λ/F acts) leans towards e_r by φ ≈ 1.9 SLIP/R (springforc_n2f.f, springstiff_n2f.f).
#: SLIP = 2e-4 gave φ = 7.65e-3 rad and a frequency offset ≈ −6.5e-3·μ (the "unidentified ccx slip
#: term" of earlier tables); 2e-6 gives φ ≈ 7.6e-5.
SLIP = 2e-6
N_THETA, PLATE_T, PLATE_OVERHANG = 180, 1e-3, 1e-3


def make_mesh(folder: Path, h: float) -> dict:
    from mpi4py import MPI

    from fem_squeal.app.convert import write_mesh_file
    from geometry.annular_disc import annular_disc_model
    from geometry.gmsh_io import write_msh
    from geometry.mesh_file import _facet_nodes, read_mesh_file

    write_msh(MPI.COMM_SELF, annular_disc_model(mean_radius=R, width=B, thickness=H, mesh_size=h, order=2),
              folder / "ring.msh")
    mf = read_mesh_file(folder / "ring.msh")
    write_mesh_file(mf, folder / "ring.inp")
    ccx_nodes(folder / "ring.inp")
    inner = np.unique(np.concatenate([_facet_nodes(mf.cells[c], f) for c, f in mf.surfaces["inner"]]))
    return {"nodes": len(mf.points), "elements": len(mf.cells), "inner": inner + 1}


def plate_lines(first_node: int, first_elem: int, z0: float, z1: float, name: str) -> tuple[list[str], int, int]:
    """A C3D8 annulus r ∈ [R − B/2 − overhang, R + B/2 + overhang], z ∈ [z0, z1], 2 × N_THETA × 1."""
    rs = np.linspace(R - B / 2 - PLATE_OVERHANG, R + B / 2 + PLATE_OVERHANG, 3)
    th = np.linspace(0, 2 * np.pi, N_THETA, endpoint=False)
    nid = {}
    lines = ["*NODE, NSET=N" + name]
    n = first_node
    for k, z in enumerate((z0, z1)):
        for i, r in enumerate(rs):
            for j, t in enumerate(th):
                nid[k, i, j] = n
                lines.append(f"{n}, {ccx_real(r * np.cos(t))}, {ccx_real(r * np.sin(t))}, {ccx_real(z)}")
                n += 1
    lines.append(f"*ELEMENT, TYPE=C3D8, ELSET=E{name}")
    e = first_elem
    for i in range(2):
        for j in range(N_THETA):
            jn = (j + 1) % N_THETA
            # bottom face (z0) 1-2-3-4 counter-clockwise seen from +z, then the top face (z1): face S1 is
            # z0 (outward normal −z), S2 is z1 (outward normal +z)
            c = [nid[0, i, j], nid[0, i + 1, j], nid[0, i + 1, jn], nid[0, i, jn],
                 nid[1, i, j], nid[1, i + 1, j], nid[1, i + 1, jn], nid[1, i, jn]]
            lines.append(f"{e}, " + ", ".join(map(str, c)))
            e += 1
    return lines, n, e


def ccx_deck(mesh: dict, mu: float, kn: float, lam: float, n_modes: int) -> str:
    # the ring spans z ∈ [−H/2, H/2] (geometry.annular_disc is centred on z = 0): the plates touch its faces
    top, n, e = plate_lines(10 ** 6, 10 ** 6, H / 2, H / 2 + PLATE_T, "PTOP")
    bot, n, e = plate_lines(n, e, -H / 2 - PLATE_T, -H / 2, "PBOT")
    inner = [", ".join(str(int(k)) for k in mesh["inner"][i:i + 8]) for i in range(0, len(mesh["inner"]), 8)]
    theta = SLIP / R

    def rotate(name, z_sign):
        # rigid plate: every node prescribed; the second static step turns it by θ about +z
        # (u = θ e_z × x: the plate slides in +e_θ relative to the ring) and keeps the press
        out = []
        rs = np.linspace(R - B / 2 - PLATE_OVERHANG, R + B / 2 + PLATE_OVERHANG, 3)
        th = np.linspace(0, 2 * np.pi, N_THETA, endpoint=False)
        start = {"PTOP": 10 ** 6, "PBOT": 10 ** 6 + 6 * N_THETA}[name]
        k = start
        for _z in range(2):
            for r in rs:
                for t in th:
                    x, y = r * np.cos(t), r * np.sin(t)
                    out += [f"{k}, 1, 1, {ccx_real(-theta * y)}", f"{k}, 2, 2, {ccx_real(theta * x)}"]
                    k += 1
        return out

    lines = ["*INCLUDE, INPUT=ring.inp", *top, *bot, "*NSET, NSET=INNERN", *inner,
             "*SURFACE, NAME=MTOP, TYPE=ELEMENT", "EPTOP, S1",
             "*SURFACE, NAME=MBOT, TYPE=ELEMENT", "EPBOT, S2",
             "*MATERIAL, NAME=RING", "*ELASTIC", f"{E:.6e}, {NU}", "*DENSITY", f"{RHO}",
             "*MATERIAL, NAME=STEEL", "*ELASTIC", "2.1e11, 0.3", "*DENSITY", "7850.",
             "*SOLID SECTION, ELSET=disc, MATERIAL=RING",
             "*SOLID SECTION, ELSET=EPTOP, MATERIAL=STEEL", "*SOLID SECTION, ELSET=EPBOT, MATERIAL=STEEL",
             "*SURFACE INTERACTION, NAME=SI", "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR",
             f"{kn:.6e}, {SIGMA_INF:.6e}",
             "*FRICTION", f"{F_STATIC * mu:.8g}, {lam:.6e}",
             "*CONTACT PAIR, INTERACTION=SI, TYPE=NODE TO SURFACE", "top, MTOP", "bottom, MBOT",
             "*BOUNDARY", "INNERN, 1, 2", "NPTOP, 1, 2", "NPBOT, 1, 2",
             "*STEP", "*STATIC", "0.25, 1.0",
             "*BOUNDARY", f"NPTOP, 3, 3, {-P_PRESS / kn:.6e}", f"NPBOT, 3, 3, {P_PRESS / kn:.6e}",
             "*END STEP",
             "*STEP", "*STATIC", "0.1, 1.0", "*BOUNDARY", *rotate("PTOP", -1), *rotate("PBOT", 1), "*END STEP",
             "*STEP, PERTURBATION", "*CHANGE FRICTION, INTERACTION=SI", "*FRICTION", f"{mu:.8g}, {lam:.6e}",
             "*FREQUENCY", f"{n_modes}", "*END STEP"]
    return "\n".join(lines) + "\n"


def run_ccx(folder: Path, job: str) -> float:
    t = time.perf_counter()
    with open(folder / f"{job}.log", "w") as out:
        p = subprocess.run(["ccx", "-i", job], cwd=folder, stdout=out, stderr=subprocess.STDOUT,
                           env={"OMP_NUM_THREADS": "2", "CCX_NPROC_EQUATION_SOLVER": "1",
                                "PATH": "/usr/bin:/bin"})
    if p.returncode != 0:
        tail = (folder / f"{job}.log").read_text()[-3000:]
        raise RuntimeError(f"ccx -i {job} failed (exit {p.returncode}):\n{tail}")
    return time.perf_counter() - t


def read_complex_dat(path: Path) -> np.ndarray:
    """s = iω from ccx's complex eigenfrequency table: its rows are (mode, Re ω [rad/time],
    Re ω/2π [cycles/time], Im ω [rad/time]), so s = −Im ω + i Re ω."""
    text = path.read_text()
    i = text.find("E I G E N V A L U E   O U T P U T")
    j = text.find("P A R T I C I P A T I O N", i)
    if i < 0:
        raise RuntimeError(f"{path}: no eigenvalue output")
    rows = [line.split() for line in text[i:j if j > 0 else None].splitlines()]
    rows = [[float(v) for v in r[1:]] for r in rows if len(r) == 4 and re.fullmatch(r"\d+", r[0])]
    t = np.array(rows)
    return -t[:, 2] + 1j * t[:, 0]


def fem_cea(folder: Path, mu: float, kn: float, kt: float, n_modes: int, target_hz: float) -> np.ndarray:
    from mpi4py import MPI

    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.model import FixedFace, Material, ModelSpec, RigidPlate
    from geometry import BUILDERS

    md = BUILDERS["mesh_file"](MPI.COMM_WORLD, file=str(folder / "ring.inp"), format="", scale=1.0,
                               center=[0.0, 0.0, 0.0], axis=[0.0, 0.0, 1.0], id_field="", max_aspect_ratio=10.0,
                               parts={"disc": ["disc"]},
                               faces={"top": ["top"], "bottom": ["bottom"], "inner": ["inner"]})
    spec = ModelSpec({"disc": Material(E, NU, RHO)},
                     tuple(RigidPlate(f, kn, mu, 1, kt) for f in ("top", "bottom")),
                     fixed=(FixedFace("inner", ("x", "y")),))
    ops = assemble_operators(md, spec)
    cm = solve_complex_modes(ops.K_total(), ops.M, None, n_modes, target_hz)
    return cm.eigenvalues


def deck_run(folder: Path, job: str) -> tuple[np.ndarray, dict]:
    """``fem-squeal run JOB.inp`` (in this process): its eigenvalues s = Re + 2πi f (Im s > 0) and the
    scene's cea section."""
    from fem_squeal.app.cli import main as cli
    from fem_squeal.app.deck import deck_scene

    out = folder / f"{job}_fem"
    code = cli(["--cache-dir", str(folder / "cache"), "--log-level", "warning", "run", str(folder / f"{job}.inp"),
                "-o", str(out), "--no-fields", "--no-report"])
    if code != 0:
        raise RuntimeError(f"fem-squeal run {job}.inp: exit {code}")
    modes = json.loads((out / "results.json").read_text())["complex_modes"]
    lam = np.array([m["real_part"] + 2j * np.pi * m["freq_hz"] for m in modes])
    return lam, deck_scene(folder / f"{job}.inp").raw["analyses"]["cea"]


def main_deck(args, folder: Path, mesh: dict, lam_st: float) -> dict:
    """``--deck``: ccx and ``fem-squeal run`` on the same deck, and the hand-built model at the run's settings."""
    res = {"h": 0.003 if args.quick else 0.002, "nodes": mesh["nodes"], "elements": mesh["elements"],
           "kn": args.kn,
           "lambda": lam_st, "F": F_STATIC, "runs": []}
    for mu in args.mu:
        job = f"ring_mu{mu:g}".replace(".", "p")
        (folder / f"{job}.inp").write_text(ccx_deck(mesh, mu, args.kn, lam_st, args.n_modes))
        t = time.perf_counter()
        lam_deck, cea = deck_run(folder, job)
        t_deck = time.perf_counter() - t
        lam_hand = fem_cea(folder, mu, args.kn, lam_st / F_STATIC, cea["n_modes"], cea["target_hz"])
        up = lam_deck[lam_deck.imag > 0]
        same = max(float(np.min(np.abs(lam_hand - v)) / abs(v)) for v in up)
        t = time.perf_counter()
        run_ccx(folder, job)
        t_ccx = time.perf_counter() - t
        s_ccx = read_complex_dat(folder / f"{job}.dat")
        rows = compare(s_ccx, lam_deck)
        unstable_ccx = int(np.sum((s_ccx.imag > 0) & (s_ccx.real > 0)))
        unstable_fem = int(np.sum(up.real > 1e-6 * np.abs(up)))
        pairs_same = all((r["re_ccx"] > 0) == (r["re_fem"] > 1e-6 * abs(r["f_fem"]) * 2 * np.pi) for r in rows)
        run = {"mu": mu, "deck_seconds": t_deck, "ccx_seconds": t_ccx, "deck_vs_hand_max_rel": same,
               "unstable_ccx": unstable_ccx, "unstable_fem": unstable_fem, "unstable_pairs_same": pairs_same,
               "rows": rows}
        res["runs"].append(run)
        print(deck_table(run), flush=True)
    out = ROOT / "benchmarks" / "out"
    out.mkdir(exist_ok=True)
    name = f"cea_calculix_deck{'_quick' if args.quick else ''}"
    (out / f"{name}.json").write_text(json.dumps(res, indent=1))
    (out / f"{name}.md").write_text(deck_summary(res) + "\n")
    print(deck_summary(res))
    return res


def deck_table(run: dict) -> str:
    df = [r["df"] for r in run["rows"]]
    unst = [r for r in run["rows"] if r["re_ccx"] > 0]
    dre = [r["dre"] for r in unst]
    return (f"μ {run['mu']}: deck run vs hand-built model max |Δλ|/|λ| {run['deck_vs_hand_max_rel']:.1e}; "
            "unstable "
            f"ccx {run['unstable_ccx']}, fem {run['unstable_fem']}, the same pairs: {run['unstable_pairs_same']}; "
            f"Δf/f {min(df):+.1e} … {max(df):+.1e}; ΔRe/Re (unstable) "
            f"{min(dre, default=0):+.2%} … {max(dre, default=0):+.2%}")


def deck_summary(res: dict) -> str:
    lines = ["| μ | deck run vs hand-built: max abs(Δλ)/abs(λ) | unstable pairs ccx / fem (same) | Δf/f | "
             "ΔRe(s)/Re(s), unstable |", "|---|---|---|---|---|"]
    for run in res["runs"]:
        df = [r["df"] for r in run["rows"]]
        dre = [r["dre"] for r in run["rows"] if r["re_ccx"] > 0]
        lines.append(f"| {run['mu']} | {run['deck_vs_hand_max_rel']:.1e} | {run['unstable_ccx']} / "
                     f"{run['unstable_fem']} ({'yes' if run['unstable_pairs_same'] else 'NO'}) | {min(df):+.1e} … "
                     f"{max(df):+.1e} | {min(dre, default=0):+.2%} … {max(dre, default=0):+.2%} |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--mu", type=float, nargs="+", default=[0.3])
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--n-modes", type=int, default=24)
    ap.add_argument("--kn", type=float, default=KN)
    ap.add_argument("--stick-slope", type=float, default=0.1, help="λ/k_n (CalculiX's stick slope)")
    ap.add_argument("--deck", action="store_true", help="run the ccx deck as it is with fem-squeal run")
    args = ap.parse_args()
    h = 0.003 if args.quick else 0.002
    folder = Path(args.workdir or tempfile.mkdtemp(prefix="cea_ccx_"))
    folder.mkdir(parents=True, exist_ok=True)
    mesh = make_mesh(folder, h)
    lam_st = args.stick_slope * args.kn
    if args.deck:
        main_deck(args, folder, mesh, lam_st)
        print(folder)
        return
    res = {"h": h, "nodes": mesh["nodes"], "elements": mesh["elements"], "kn": args.kn, "lambda": lam_st,
           "F": F_STATIC, "runs": []}
    for mu in args.mu:
        job = f"ring_mu{mu:g}".replace(".", "p")
        (folder / f"{job}.inp").write_text(ccx_deck(mesh, mu, args.kn, lam_st, args.n_modes))
        t = run_ccx(folder, job)
        s_ccx = read_complex_dat(folder / f"{job}.dat")
        run = {"mu": mu, "ccx_seconds": t, "ccx_re": s_ccx.real.tolist(), "ccx_im": s_ccx.imag.tolist()}
        target = float(np.max(s_ccx.imag)) / (2 * np.pi) * 0.6
        for label, kt in (("kt", lam_st / F_STATIC), ("kt0", 0.0)):
            lam = fem_cea(folder, mu, args.kn, kt, args.n_modes + 6, target)
            run[label] = compare(s_ccx, lam)
        res["runs"].append(run)
        print(f"mu {mu}: ccx {t:.1f} s", flush=True)
        print(table(run), flush=True)
    out = ROOT / "benchmarks" / "out"
    out.mkdir(exist_ok=True)
    name = f"cea_calculix{'_quick' if args.quick else ''}"
    (out / f"{name}.json").write_text(json.dumps(res, indent=1))
    (out / f"{name}.md").write_text("\n\n".join(f"μ = {r['mu']}, k_n = {args.kn:g}, λ = {lam_st:g}, h = {h}\n\n"
                                                 + table(r) for r in res["runs"]) + "\n")
    print(folder)


def compare(s_ccx: np.ndarray, lam: np.ndarray) -> list[dict]:
    """Each ccx eigenvalue (Im s > 0) with the nearest fem_squeal one: frequencies and Re(s)."""
    rows = []
    for s in s_ccx[s_ccx.imag > 0]:
        k = int(np.argmin(np.abs(lam - s)))
        f0, f1 = s.imag / (2 * np.pi), lam[k].imag / (2 * np.pi)
        rows.append({"f_ccx": f0, "re_ccx": s.real, "f_fem": f1, "re_fem": lam[k].real,
                     "df": f1 / f0 - 1, "dre": (lam[k].real - s.real) / max(abs(s.real), 1e-300)})
    return rows


def table(run: dict) -> str:
    lines = ["| f ccx [Hz] | Re s ccx | f fem kt [Hz] | Re s fem kt | Δf/f | ΔRe/Re | Re s fem kt=0 "
             "| ΔRe/Re kt=0 |",
             "|---|---|---|---|---|---|---|---|"]
    for a, b in zip(run["kt"], run["kt0"]):
        lines.append(f"| {a['f_ccx']:.2f} | {a['re_ccx']:.2f} | {a['f_fem']:.2f} | {a['re_fem']:.2f} | "
                     f"{a['df']:+.1e} | {a['dre']:+.1e} | {b['re_fem']:.2f} | {b['dre']:+.1e} |")
    return "\n".join(lines)


if __name__ == "__main__":
    if shutil.which("ccx") is None:
        sys.exit("ccx not found: apt-get install -y calculix-ccx")
    main()
