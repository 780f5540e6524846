"""The 1-versus-2-rank comparisons of test modules: a module's ``signature()`` computed by an
``mpirun -n 2`` child, and two spectra compared as sets."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from support.paths import ROOT
from support.processes import clean_env

TESTS = ROOT / "tests"


def two_rank_signature(mpirun: list[str], module: str, out) -> dict:
    """``module.signature()`` (a test module's dict of numbers, the module found anywhere under
    tests/) computed by an ``mpirun -n 2`` child, as rank 0 wrote it to the JSON file ``out``."""
    (path,) = TESTS.rglob(f"{module}.py")
    code = (f"import json, sys; sys.path[:0] = [{str(path.parent)!r}, {str(TESTS)!r}]; from mpi4py import MPI; "
            f"import {module} as t; "
            f"s = t.signature(); MPI.COMM_WORLD.rank == 0 and open({str(out)!r}, 'w').write(json.dumps(s))")
    p = subprocess.run(mpirun + [sys.executable, "-c", code], capture_output=True, text=True, timeout=900,
                       env=clean_env(), cwd=ROOT)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    return json.loads(Path(out).read_text())


def assert_same_spectrum(sig_a: dict, sig_b: dict, prefix: str, rel: float) -> None:
    """The eigenvalues ``<prefix>re`` + i ``<prefix>im`` of two signatures agree as sets: as many, and
    every one has its twin in the other within ``rel``·|λ| (the order may differ between runs)."""
    a = np.array(sig_a[prefix + "re"]) + 1j * np.array(sig_a[prefix + "im"])
    b = np.array(sig_b[prefix + "re"]) + 1j * np.array(sig_b[prefix + "im"])
    assert len(a) == len(b)
    for u, w in ((a, b), (b, a)):
        assert all(np.min(np.abs(w - lam)) <= rel * abs(lam) for lam in u)
