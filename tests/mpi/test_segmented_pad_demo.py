"""The segmented-pad demo (seed 004) on 1 and 2 ranks: its own check passes on both and the results
are the same (its own file, so that the test runner can give this long test a worker of its own)."""
from __future__ import annotations

import pytest

PAD_QUICK = ["--set=analyses.segmented_pad.t_end=0.15", "--set=analyses.segmented_pad.speeds=[0.005, 0.045]"]


@pytest.mark.mpi
def test_segmented_pad_demo_serial_and_two_ranks(tmp_path, mpirun):
    """The demo checks the seed's regimes itself; the runs are dealt over the ranks, each run is
    the same arithmetic whatever the rank count, so both give the same segmented_pad.json."""
    import json
    import subprocess
    import sys

    from support.paths import ROOT
    from support.processes import clean_env

    out = {}
    for n, prefix in ((1, []), (2, mpirun)):
        d = tmp_path / f"r{n}"
        p = subprocess.run(prefix + [sys.executable, str(ROOT / "demos" / "segmented_pad.py"), str(d), *PAD_QUICK],
                           capture_output=True, text=True, timeout=600,
                           env=clean_env() | {"FEM_SQUEAL_CACHE": str(tmp_path / f"cache{n}")})
        assert p.returncode == 0 and p.stdout.count("check passed") == 1, p.stdout[-2000:] + p.stderr[-2000:]
        out[n] = json.loads((d / "segmented_pad.json").read_text())
    assert out[1] == out[2]
