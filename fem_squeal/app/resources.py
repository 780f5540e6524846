"""Checks before any stage runs: the size of the model and the memory of its largest solve, and the
output folder.

Memory model M(N, ranks, kind) of the brake corner CEA with its preload (the peak RSS summed over
the ranks; ``benchmarks/memory_model.py``): a part linear in the DOFs (mesh, matrices, Krylov vectors)
and the factor's fill-in, ∝ N^(4/3) for nested dissection in 3D, fitted through two one-rank runs of
each factorisation kind (``exact`` in-core MUMPS, ``blr`` block low-rank, ``ooc`` out-of-core);
r ranks hold r^γ times the one-rank memory (duplicated halos and fronts):

    M(N, r, kind) = (a_kind · N + b_kind · N^(4/3)) · r^γ.

exact: 1.568 GiB at 88,869 DOFs and 7.456 GiB at 347,853 (one rank); γ = log₂(9.0/7.456) = 0.27 from
the 9.0 GiB the same 347,853-DOF model took on two ranks (``benchmarks/mpi_scaling.py``; only r = 2 is
measured, the power beyond it is an assumption).  Checked against the 711,351-DOF two-rank run
(22.7 GiB measured, 20.8 predicted).  "How many machines": :func:`machines_needed`.

ooc (MUMPS ICNTL(22) = 1 for the preload and the CEA: the factors go to files in $MUMPS_OOC_TMPDIR,
frequencies equal to the in-core run's to 2e-11): 4.214 GiB at 347,853 DOFs and 18.42 GiB at
1,323,816 (mesh_size 0.0033, one rank, 48 min; eigen-residuals ≤ 3e-14).  The first fit, through
1.080 GiB at 88,869 and the 347,853 point, had b ≈ 0 (12.8 KB per DOF) and predicted 15.8 GiB for
the 1.32M run: 14 % low, as the factorisation's in-core fronts grow; the fit through the two larger
points gives 0.97 and 2.12 GiB at 88,869 and 184,506 DOFs (measured 1.080 and 2.31).
symmetric (the preload stage's peak where preload.jacobian is "symmetric": the frictionless Jacobian's
Cholesky in core, CHOLMOD on one rank; results.json stages[].peak_rss_gib): 4.020 GiB at 347,853 DOFs
and 20.09 GiB at 1,323,816 (one rank, 2026-11-29: its J as products, the freed heap returned before the
factorisation, the parts' stiffnesses not held by a CEA alone; 4.716 and 23.12 GiB before), beside the
ooc run's 18.42: the in-core Cholesky holds more than the out-of-core LU's fronts.  "auto" takes it only
where it fits (:func:`preload_jacobian`).
blr (ICNTL(35) = 2, CNTL(7) = 1e-8, one refinement step: frequencies within 1e-11) lowered no peak:
1.60 against 1.57 GiB at 88,869 DOFs, and above the in-core 7.46 GiB at 347,853 (MUMPS still touches
its full-rank workspace), so it uses the exact fit.
The fits were measured with SLEPc's Krylov–Schur in the CEA.  Its block Arnoldi (the default for
the undamped CEA since 2026-11-27) keeps up to 6·nev vectors and runs only where they take at most
half of the memory still available once the CEA's factorisation is held, shared by the ranks on the
machine (``fem_squeal.fe.eigen.VECTOR_MEMORY_SHARE``, read from MemAvailable when the vectors are
allocated): the prediction here does not count them, and they never take memory the factor needs.
The brake at 348k DOFs on 2 ranks (120 modes, 2 × 1.0 GB) runs it; 1.32M DOFs on one machine keeps
Krylov–Schur.
The DOFs come from the cell estimate of ``geometry.estimate`` and :func:`dofs_per_cell` (P2: fewer
DOFs per tetrahedron as the mesh grows and its surface share falls; fitted on the brake at 0.0056
and 0.003 m, 5.17 and 4.66, and 8 % high at 0.016 m, where it is 5.89).

A run is refused (:class:`~fem_squeal.util.errors.ResourceError`, exit 2, before gmsh or any solver
starts) when M exceeds 90 % of the memory of the machines it runs on, and warned about above 60 %.
The CEA's vectors beyond those the model was measured with count on top (:func:`cea_vectors`, issue 36):
the Krylov–Schur space beyond 120 vectors (``analyses.cea.n_modes``), or the projection's real modes
to its cut and their mass products (``analyses.cea.band_hz`` × ``cut_factor``, the brake corner's
measured mode count :data:`BRAKE_MODE_COUNTS`), so that a band or cut that cannot fit is refused
naming its key.
The same model says how many such machines an N-DOF model needs under MPI.

Out of core where in core does not fit (issue 36: "out-of-core chosen by the memory model"): when the
scene's PETSc options leave MUMPS's ICNTL(22) unset and the in-core factors would be refused while the
``ooc`` fit holds, the run keeps every MUMPS factor in files (:func:`fem_squeal.fe.factorisation.
factors_out_of_core`, in a folder of its own under $MUMPS_OOC_TMPDIR or the system's temporary folder,
removed after the run) and says so; an ICNTL(22) the user gives decides instead.  The files hold the
whole factor, :func:`factor_file_bytes`; a disk that cannot hold them refuses the run before meshing.
Measured (``docs/validation.md``, "Out of core where in core does not fit"): the brake at 711,351 DOFs
on 2 ranks (22.4 GiB in core predicted: refused before) ran in 7.6 min with the same 91 pairs as the
in-core run on one rank; at 1,323,816 DOFs on one rank every pair to 16 kHz took 30.7 min.
"""
from __future__ import annotations

import math
import os
import socket
import tempfile
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from fem_squeal.util.errors import InputError, ResourceError
from fem_squeal.util.storage import free_bytes
from geometry.estimate import ESTIMATORS

GIB = 2.0 ** 30
#: P2/P1 displacement DOFs per tetrahedron: measured 6.3 (ring), 5.7-5.9 (brake) for P2; P1 has about
#: one vertex per 5 cells in the bulk and more in thin parts
DOFS_PER_CELL = {1: 0.9}


def dofs_per_cell(cells: float, degree: int) -> float:
    """DOFs per tetrahedron of a vector P1 (0.9) or P2 space: 3.98 + 48.3 cells^(−1/3) for P2 (the
    boundary's share of nodes falls as cells^(−1/3)), fitted on the brake corner at 67,285 and 361,758
    cells (347,853 and 1,684,788 DOFs)."""
    return DOFS_PER_CELL[degree] if degree != 2 else 3.98 + 48.3 * cells ** (-1.0 / 3.0)


REFUSE_SHARE, WARN_SHARE = 0.9, 0.6
#: one-rank peak memory [GiB] measured at two sizes (DOFs) per factorisation kind (benchmarks/memory_model.py)
MEMORY_POINTS = {"exact": ((88_869, 1.568), (347_853, 7.456)), "ooc": ((347_853, 4.214), (1_323_816, 18.42)),
                 "symmetric": ((347_853, 4.020), (1_323_816, 20.09))}
#: memory ∝ ranks^γ at a fixed size: 9.0 GiB on 2 ranks against 7.456 GiB on 1 at 347,853 DOFs
RANK_EXPONENT = math.log2(9.0 / 7.456)
FILL_EXPONENT = 4.0 / 3.0


def _fit(kind: str) -> tuple[float, float]:
    """(a, b) [bytes] of a N + b N^(4/3) through the two measured points of ``kind``."""
    (n1, m1), (n2, m2) = MEMORY_POINTS[kind]
    p = FILL_EXPONENT
    b = (m2 - m1 * n2 / n1) / (n2 ** p - n1 ** (p - 1) * n2)
    return (m1 - b * n1 ** p) / n1 * GIB, b * GIB


def solve_memory(dofs: float, ranks: int = 1, kind: str = "exact") -> float:
    """Bytes the largest solve of an N-DOF model needs, summed over ``ranks`` MPI ranks, with the
    factorisation ``kind`` (module docstring)."""
    a, b = _fit(kind if kind in MEMORY_POINTS else "exact")     # blr: no lower peak measured (module docstring)
    return (a * dofs + b * dofs ** FILL_EXPONENT) * max(ranks, 1) ** RANK_EXPONENT


def factorisation_kind(scene: dict) -> str:
    """``ooc`` or ``blr`` when the scene's PETSc options ask MUMPS for them in both factorisations of
    the run (``preload_mat_mumps_icntl_22`` and ``cea_st_mat_mumps_icntl_22``, or ``..._icntl_35``), as
    measured; else ``exact`` (a factorisation left in-core sets the peak)."""
    opts = {k.lstrip("-"): str(v).lower() for k, v in scene.get("solver", {}).get("petsc_options", {}).items()}

    def both(icntl: int) -> bool:
        return all(opts.get(f"{p}mat_mumps_icntl_{icntl}", "0") not in ("0", "false")
                   for p in ("preload_", "cea_st_"))
    return "ooc" if both(22) else "blr" if both(35) else "exact"


#: bytes of MUMPS's out-of-core files measured at two sizes of the brake corner (DOFs, bytes): the
#: preload's LU at 711,351 DOFs on 2 ranks and at 1,323,816 on one (the largest of the run's factors,
#: ``du`` of the run's folder each second, 2026-11-29): 10.60 and 26.23 GB, ∝ N^1.46 between them (the
#: in-core entries at 347,853 DOFs, INFOG(9) 455M × 8 bytes, lie 2.4 % under the power)
FACTOR_FILES = ((711_351, 10.595e9), (1_323_816, 26.229e9))


def factor_file_bytes(dofs: float) -> float:
    """Bytes of MUMPS's out-of-core files for an N-DOF model (all ranks) by the power through
    :data:`FACTOR_FILES` (MUMPS deletes a factor's files when it is destroyed, and the run holds one
    large factor at a time)."""
    (n1, b1), (n2, b2) = FACTOR_FILES
    return b1 * (dofs / n1) ** (math.log(b2 / b1) / math.log(n2 / n1))


def storage_given(scene: dict) -> bool:
    """Whether the scene's PETSc options set MUMPS's ICNTL(22) (in or out of core) for any solver:
    then the user decides, and the memory model does not."""
    return any(k.lstrip("-").endswith("mat_mumps_icntl_22")
               for k in scene.get("solver", {}).get("petsc_options", {}))


def factor_folder_parent() -> str:
    """Where out-of-core factor files go: $MUMPS_OOC_TMPDIR (MUMPS's own variable) or the system's
    temporary folder."""
    return os.environ.get("MUMPS_OOC_TMPDIR") or tempfile.gettempdir()


#: real modes of the brake corner below f [Hz]: 90 below 16 kHz and 159 below 24 kHz (163,506 DOFs; 157 at
#: 78,072: converged in the mesh), N = 159 (f / 24 kHz)^1.40 through the two (issue 36's benchmark runs)
BRAKE_MODE_COUNTS = ((16000.0, 90), (24000.0, 159))
#: Krylov–Schur vectors of the CEA runs the memory model was fitted on (2 × 60 modes)
MODEL_VECTORS = 120


def modes_below_estimate(builder: str, f_hz: float) -> float | None:
    """Real modes below ``f_hz`` of a ``builder``'s model (the brake corner's power law through
    :data:`BRAKE_MODE_COUNTS`); None where no count was measured."""
    if builder != "brake_corner":
        return None
    (f1, n1), (f2, n2) = BRAKE_MODE_COUNTS
    return n2 * (f_hz / f2) ** (math.log(n2 / n1) / math.log(f2 / f1))


def cea_vectors(scene: dict) -> tuple[float, str] | None:
    """(vectors of the model's size the CEA keeps beyond the memory model's, what sets them and how):
    the projection (``method = "projection"``) its real modes to cut_factor × the band top and their
    mass products, 2 N (:func:`modes_below_estimate`; the Lanczos space, the static corrections and
    the enrichment come on top: a lower bound); the other methods Krylov–Schur's max(2 nev, nev + 16)
    beyond :data:`MODEL_VECTORS`.  None without a CEA or a count."""
    cea = scene.get("analyses", {}).get("cea")
    if cea is None:
        return None
    if cea.get("method") == "projection":
        top, factor = float(cea["band_hz"][1]), float(cea.get("cut_factor", 1.5))
        n = modes_below_estimate(scene["geometry"]["builder"], factor * top)
        if n is None:
            return None
        return 2.0 * n, (f"analyses.cea.band_hz: its top {top:g} Hz × cut_factor {factor:g} needs the real modes "
                         f"below {factor * top:.0f} Hz, about {n:.0f} of them (the brake corner's, N ∝ f^1.4)")
    nev = int(cea.get("n_modes", 20))
    return float(max(max(2 * nev, nev + 16) - MODEL_VECTORS, 0)), \
        f"analyses.cea.n_modes: {nev} modes keep {max(2 * nev, nev + 16)} Krylov vectors"


def machine_memory() -> float:
    """Physical memory of this machine [bytes]."""
    return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


@dataclass(frozen=True)
class Estimate:
    """What a scene's model will take: cells, DOFs, memory of the largest solve, and what is there."""
    cells: float
    dofs: float
    memory_gib: float          # of the largest solve on one rank (r ranks: r^γ times this, solve_memory)
    available_gib: float       # physical memory of the machines of this run
    machines: int              # machines like this one the model needs, one rank each (90 % of each usable)
    factors: str = "in core"   # where MUMPS keeps its factors: "in core", "out of core" (the user's options),
    #                            "out of core (memory model)": chosen because in core does not fit

    def as_dict(self) -> dict:
        return asdict(self)


def estimate(scene: dict, nodes: int = 1) -> Estimate | None:
    """The size of ``scene``'s model before its mesh is built (None for a mesh file or a lumped scene:
    the file fixes the size, the mesh stage reports it).  Independent of the run's rank count."""
    geo = scene.get("geometry")
    if geo is None or geo["builder"] not in ESTIMATORS:
        return None
    params = {k: v for k, v in geo.items() if k != "builder"}
    cells = sum(ESTIMATORS[geo["builder"]](**params).values())
    dofs = cells * dofs_per_cell(cells, scene.discretisation.degree)
    kind, machine = factorisation_kind(scene), machine_memory()
    return Estimate(cells, dofs, solve_memory(dofs, 1, kind) / GIB, nodes * machine / GIB,
                    machines_needed(dofs, machine, 1, kind))


def machines_needed(dofs: float, machine: float, ranks_per_machine: int = 1, kind: str = "exact") -> int:
    """The fewest machines of ``machine`` bytes each (90 % usable) an N-DOF model fits on under MPI,
    with ``ranks_per_machine`` ranks on each (every further rank adds its share of memory)."""
    # M₁ (m k)^γ ≤ 0.9 m·machine  ⇔  m ≥ (M₁ k^γ / (0.9 machine))^(1/(1−γ))
    one = solve_memory(dofs, ranks_per_machine, kind)
    return max(1, math.ceil((one / (REFUSE_SHARE * machine)) ** (1.0 / (1.0 - RANK_EXPONENT)) * (1 - 1e-12)))


def _what_fits(est: Estimate, ranks: int, nodes: int, kind: str, auto: bool = False) -> str:
    """Where a model refused on ``ranks`` ranks over ``nodes`` machines would fit: fewer ranks on these
    machines (each rank adds its share of memory, r^γ), or more machines with as many ranks each.
    ``auto``: in-core ``kind`` factors that the run would put out of core where only that fits."""
    usable = REFUSE_SHARE * est.available_gib * GIB
    per = -(-ranks // nodes)
    kinds = (kind, "ooc") if auto else (kind,)
    least = min(machines_needed(est.dofs, est.available_gib * GIB / nodes, per, k) for k in kinds)
    more = f"it needs {least} such machines with {per} rank(s) each under MPI"
    for k in kinds:
        fewer = [r for r in range(ranks - 1, 0, -1) if solve_memory(est.dofs, r, k) <= usable]
        if fewer:
            how = "" if k == kind else " out of core (chosen by itself there)"
            return f"on {fewer[0]} rank(s) it needs {solve_memory(est.dofs, fewer[0], k) / GIB:.3g} GiB{how}, " \
                f"which fits; or {more}"
    return more


def _free_bytes(folder: str) -> float | None:
    """Free bytes on the disk of ``folder``; None if it is no folder."""
    return float(free_bytes(folder)) if os.path.isdir(folder) else None


def machines_of(comm) -> int:
    """How many machines the ranks of ``comm`` run on (collective)."""
    return len(set(comm.allgather(socket.gethostname())))


def preload_jacobian(jacobian: str, dofs: float, ranks: int, machines: int, out_of_core: bool,
                     continued: bool = False) -> tuple[str, str | None]:
    """The preload's Jacobian (``preload.jacobian``) for an N-DOF model on ``ranks`` ranks over ``machines``
    machines like this one: "auto" is "symmetric" where the LU's factors go to files by the memory model's
    choice (``out_of_core``; an ICNTL(22) of the user's decides instead) and the preload's peak with the
    Cholesky in core (kind ``symmetric``) fits in :data:`REFUSE_SHARE` of the memory, and no pressure
    continuation follows (``continued``: there the LU's Woodbury columns serve the later pressures, and
    GMRES on the Cholesky was 2.3× slower: the tapered brake at 78k DOFs, 10 pressures, 25.8 s against
    11.2 s, ``benchmarks/preload_continuation.py``); else "update".  The others stay.  Returns it and a
    warning where "symmetric" is asked for and its peak is not predicted to fit."""
    need, memory = solve_memory(dofs, ranks, "symmetric"), machines * machine_memory()
    fits = need <= REFUSE_SHARE * memory
    if jacobian == "auto":
        return ("symmetric" if out_of_core and fits and not continued else "update"), None
    if jacobian == "symmetric" and not fits:
        return jacobian, (f"preload.jacobian: 'symmetric' keeps the frictionless Jacobian's Cholesky in core, "
                          f"about {need / GIB:.3g} GiB at its peak on {ranks} rank(s) for {dofs:.3g} DOFs, more "
                          f"than {100 * REFUSE_SHARE:.0f} % of the {memory / GIB:.3g} GiB of this run; 'auto' "
                          "would take 'update' here")
    return jacobian, None


def check_resources(scene: dict, comm) -> tuple[Estimate | None, list[str]]:
    """:func:`estimate` on the machines of ``comm``; raises :class:`ResourceError` naming the mesh size
    when the largest solve cannot fit, returns warnings when it is close."""
    nodes = machines_of(comm)
    est = comm.bcast(estimate(scene, nodes) if comm.rank == 0 else None, root=0)
    if est is None:
        return None, []
    geo = scene.geometry
    kind = factorisation_kind(scene)
    need = solve_memory(est.dofs, comm.size, kind) / GIB
    usable = REFUSE_SHARE * est.available_gib
    auto = kind == "exact" and not storage_given(scene)        # the memory model may choose out of core
    out_of_core = solve_memory(est.dofs, comm.size, "ooc") / GIB
    notes = []
    if kind == "ooc":
        est = replace(est, factors="out of core")
    elif auto and need > usable and out_of_core <= usable:
        in_core, kind, need = need, "ooc", out_of_core
        est = replace(est, memory_gib=solve_memory(est.dofs, 1, kind) / GIB, factors="out of core (memory model)",
                      machines=machines_needed(est.dofs, est.available_gib * GIB / nodes, 1, kind))
        files, machine = factor_file_bytes(est.dofs) / 1e9, est.available_gib
        notes.append(f"the factors go out of core: in core the largest solve needs about {in_core:.3g} GiB on "
                     f"{comm.size} rank(s), more than {100 * REFUSE_SHARE:.0f} % of the {machine:.3g} GiB of this "
                     f"run; out of core {need:.3g} GiB and about {files:.3g} GB of files under "
                     f"{factor_folder_parent()} (MUMPS_OOC_TMPDIR), read back by every solve (slower); a "
                     "*_mat_mumps_icntl_22 option of the scene's decides instead")
    (n_ref, m_ref) = MEMORY_POINTS.get(kind, MEMORY_POINTS["exact"])[1]
    what = (f"geometry.mesh_size: {geo['mesh_size']:g} m gives about {est.cells:.3g} elements and "
            f"{est.dofs:.3g} DOFs (P{scene.discretisation['degree']}); its largest solve needs about "
            f"{need:.3g} GiB on {comm.size} rank(s) ({m_ref:g} GiB at {n_ref / 1e3:.0f}k DOFs on one rank "
            f"with {kind} factors, fill-in ∝ DOFs^(4/3))")
    vectors = cea_vectors(scene) if need <= usable else None
    if vectors is not None and need + 8.0 * vectors[0] * est.dofs / GIB > usable:
        extra = 8.0 * vectors[0] * est.dofs / GIB
        raise ResourceError(f"{vectors[1]}: {extra:.3g} GiB of vectors of {est.dofs:.3g} DOFs on top of the "
                            f"{need:.3g} GiB of the largest solve, more than {100 * REFUSE_SHARE:.0f} % of the "
                            f"{est.available_gib:.3g} GiB of the {nodes} machine(s) of this run; lower it")
    if need > usable:
        also = f" (out of core {out_of_core:.3g} GiB, which does not fit either)" if auto else ""
        raise ResourceError(f"{what}{also}, more than {100 * REFUSE_SHARE:.0f} % of the {est.available_gib:.3g} "
                            f"GiB of the {nodes} machine(s) of this run: "
                            f"{_what_fits(est, comm.size, nodes, kind, auto)}; or use a larger mesh_size")
    if est.factors == "out of core (memory model)":
        folder, files = factor_folder_parent(), factor_file_bytes(est.dofs) / nodes
        free = comm.bcast(_free_bytes(folder) if comm.rank == 0 else None, root=0)
        if free is None:
            raise ResourceError(f"MUMPS_OOC_TMPDIR={folder}: not a folder this run can use for the out-of-core "
                                "factor files; point it to an existing folder")
        if files > free:
            raise ResourceError(f"{what}: out of core, the factor files need about {files / 1e9:.3g} GB under "
                                f"{folder}, which has {free / 1e9:.3g} GB free; point MUMPS_OOC_TMPDIR to a "
                                "larger disk, run on more machines, or use a larger mesh_size")
    if need > WARN_SHARE * est.available_gib:
        notes.append(f"{what}: close to the {est.available_gib:.3g} GiB of this run's machine(s)")
    return est, notes


def check_outdir(outdir: Path) -> None:
    """Create ``outdir`` (with its parents) and check that a file can be written there, before any stage
    runs; :class:`InputError` names the folder and the reason."""
    try:
        outdir.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=outdir, prefix=".write-test."):
            pass
    except OSError as e:
        raise InputError(f"output folder {outdir}: cannot be created or written ({e.strerror or e})") from None
