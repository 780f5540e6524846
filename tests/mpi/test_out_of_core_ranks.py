"""Out-of-core factors chosen by the memory model on 2 ranks (issue 36): rank 0 names the run's folder
for both, both ranks' MUMPS write their factor files there, the folder is gone afterwards, and the
eigenvalues are those of one rank in core."""
from __future__ import annotations

import re

import numpy as np
from support.memory import between_the_fits
from support.ranks import assert_same_spectrum, two_rank_signature

SETS = ["geometry.mesh_size=0.003"]


def _ring_run(comm, outdir, memory=None) -> dict:
    from support.paths import ROOT

    from fem_squeal.app import resources
    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    scene = load_scene(ROOT / "scenes" / "ryzhik_ring.toml", SETS)
    if memory is not None:      # a machine too small for the in-core factors on comm.size ranks
        machine = between_the_fits(scene, comm.size)[2]
        resources.machine_memory = lambda: machine
    lines: list[str] = []
    res = run_scene(scene, outdir, comm, write_fields=False, report=False,
                    log=lambda *a, **k: lines.append(" ".join(map(str, a))))
    lam = np.array([m["real_part"] + 2j * np.pi * m["freq_hz"] for m in res["complex_modes"]])
    # the CEA's block width, as its log line says it (rank 0 logs)
    width = [int(m.group(1)) for m in (re.search(r"block Arnoldi, (\d+) columns", t) for t in lines) if m]
    return {"factors": res["solver"]["factors"], "cea_re": lam.real.tolist(), "cea_im": lam.imag.tolist(),
            "blocks": comm.bcast(width[0] if width else None, root=0),
            "nev": scene.analyses["cea"]["n_modes"]}


def signature() -> dict:
    """The 2-rank out-of-core run: where the factors were, the files each rank saw in the run's folder
    while it ran (polled), what is left, the eigenvalues."""
    import os
    import shutil
    import tempfile
    import threading
    from pathlib import Path

    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    base = Path(comm.bcast(tempfile.mkdtemp() if comm.rank == 0 else None, root=0))
    os.environ["MUMPS_OOC_TMPDIR"] = str(base)
    seen, done = set(), threading.Event()

    def poll():
        while not done.wait(0.002):
            try:        # a folder may go while it is listed (the run's own, removed at its end)
                seen.update(p.name.split("_")[1] for p in base.glob("fem_squeal_factors.*/mumps_*"))
            except FileNotFoundError:
                pass
    watcher = threading.Thread(target=poll)
    watcher.start()
    try:
        out = _ring_run(comm, base / "out", memory=True)
    finally:
        done.set()
        watcher.join()
    writers = sorted(set().union(*comm.allgather(seen)))     # MUMPS names its files mumps_<rank>_...
    out.update(writers=writers, left=sorted(p.name for p in base.iterdir() if p.name != "out"))
    comm.barrier()
    if comm.rank == 0:
        shutil.rmtree(base)
    return out


def test_out_of_core_on_two_ranks_as_one_rank_in_core(mpirun, tmp_path):
    """Both ranks' factors in the run's one folder, nothing left, and the eigenvalues of one rank in
    core within 1e-8 relative (the rank-count rule; the two runs' factors are exact, and each pair
    converges to 1e-10 on the shifted operator)."""
    from mpi4py import MPI

    from fem_squeal.fe.eigen.block_krylov import OUT_OF_CORE_BLOCK, block_size

    sig = two_rank_signature(mpirun, "test_out_of_core_ranks", tmp_path / "sig.json")
    assert sig["factors"] == "out of core (memory model)"
    assert sig["writers"] == ["0", "1"] and sig["left"] == []
    one = _ring_run(MPI.COMM_SELF, tmp_path / "one")
    assert one["factors"] == "in core"
    # wider blocks where every solve reads the factor back from the files, on both ranks alike
    assert sig["blocks"] == OUT_OF_CORE_BLOCK and one["blocks"] == block_size(one["nev"]) < OUT_OF_CORE_BLOCK
    assert_same_spectrum(sig, one, "cea_", 1e-8)
