"""The segmented-pad demo (seed 004) on 2 ranks, checking itself (default suite), and the same results
on 1 and 2 ranks (``-m slow``: the serial run doubles the cost, 39 s of the fresh-clone suite)."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest
from support.paths import ROOT
from support.processes import clean_env

# the velocity pair (0.001, 0.033) at 5 mm/s is the scene's own v_s, v_d: the same run as the speed 0.005
PAD_QUICK = ["--set=analyses.segmented_pad.t_end=0.15", "--set=analyses.segmented_pad.speeds=[0.005, 0.045]",
             "--set=analyses.segmented_pad.velocity_pairs=[[0.001, 0.1], [0.003, 0.1]]"]


def _demo(prefix: list[str], tmp_path, n: int) -> dict:
    d = tmp_path / f"r{n}"
    p = subprocess.run(prefix + [sys.executable, str(ROOT / "demos" / "segmented_pad.py"), str(d), *PAD_QUICK],
                       capture_output=True, text=True, timeout=600,
                       env=clean_env() | {"FEM_SQUEAL_CACHE": str(tmp_path / f"cache{n}")})
    assert p.returncode == 0 and p.stdout.count("check passed") == 1, p.stdout[-2000:] + p.stderr[-2000:]
    return json.loads((d / "segmented_pad.json").read_text())


@pytest.mark.mpi
def test_segmented_pad_demo_on_two_ranks(tmp_path, mpirun):
    """The demo checks the seed's regimes itself, once (rank 0 prints)."""
    _demo(mpirun, tmp_path, 2)


@pytest.mark.mpi
@pytest.mark.slow
def test_segmented_pad_demo_serial_and_two_ranks(tmp_path, mpirun):
    """The runs are dealt over the ranks, each run is the same arithmetic whatever the rank count, so
    both give the same segmented_pad.json."""
    assert _demo([], tmp_path, 1) == _demo(mpirun, tmp_path, 2)
