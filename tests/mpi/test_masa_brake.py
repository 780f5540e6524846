"""MASA on the coarse brake: the demo checks itself serially and on 2 ranks, the two runs agree,
and the reduced static equilibrium is robust (Newton with line search from rest)."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from support.paths import ROOT
from support.processes import clean_env

# Slow (105 s, the longest case of the suite): the MASA arithmetic's rank independence is checked bit for
# bit in the default suite (tests/unit/reduced/test_masa.py); this runs the whole brake chain twice.
pytestmark = pytest.mark.slow

COARSE = ["--set=geometry.mesh_size=0.016", "--set=analyses.masa.n_amplitudes=30",
          "--set=analyses.reduced.band_hz=[0.0, 6000.0]", "--set=analyses.cea.band_hz=[0.0, 6000.0]"]


def _run(cmd, out):
    r = subprocess.run(cmd + [str(ROOT / "demos" / "masa_brake.py"), str(out), *COARSE], capture_output=True,
                       text=True, env=clean_env(), timeout=900)
    assert r.returncode == 0 and "check passed" in r.stdout, r.stdout[-3000:] + r.stderr[-3000:]
    with open(out / "masa.json") as fh:
        return json.load(fh)


@pytest.fixture(scope="module")
def runs(tmp_path_factory, mpirun):
    base = tmp_path_factory.mktemp("masa_brake")
    return base, _run([sys.executable], base / "serial"), _run(mpirun + [sys.executable], base / "mpi")


@pytest.mark.mpi
def test_masa_brake_demo_serial_equals_two_ranks(runs):
    """The MASA arithmetic is rank-independent bit for bit (tests/unit/reduced/test_masa.py); the brake's
    inputs are not: the preload Newton stops at ‖R‖ ≤ 1e-9‖f‖ and the SLEPc bases differ in
    round-off between partitionings.  Measured (two runs): frequencies ≤ 1.3e-7 relative, real
    parts ≤ 9e-8 of |λ| (a pair near its coalescence amplifies perturbations as a square root),
    tracked real parts ≤ 3.3e-3 of their start value (contact-loss kinks along the sweep), and
    stationary amplitudes 3e-4 (with 8 × 16 patches).  The bounds are about 10× those."""
    _, a, b = runs
    assert len(a["cases"]) == len(b["cases"]) == 1
    ia, ib = a["cases"][0]["instabilities"], b["cases"][0]["instabilities"]
    assert len(ia) == len(ib) >= 3
    for ra, rb in zip(ia, ib):
        lam = abs(complex(ra["real_part"], 2 * np.pi * ra["freq_hz"]))
        assert ra["freq_hz"] == pytest.approx(rb["freq_hz"], rel=1e-6)
        assert abs(ra["real_part"] - rb["real_part"]) < 1e-6 * lam
        n = min(len(ra["tracked_real"]), len(rb["tracked_real"]))
        ta, tb = np.array(ra["tracked_real"][:n]), np.array(rb["tracked_real"][:n])
        assert np.max(np.abs(ta - tb)) < 3e-2 * abs(ra["real_part"])
        assert ra["stationary_in_unit"] == pytest.approx(rb["stationary_in_unit"], rel=3e-3)
        assert ra["steps"] >= 10


@pytest.mark.mpi
def test_reduced_equilibrium_from_rest(runs):
    """Newton with line search from q = 0 (every pad point open: the pads hang on the piston and
    finger springs) reaches the full-order preload with the linear law, and converges with the
    cubic law too."""
    from fem_squeal.reduced.masa import from_reduced, static_equilibrium
    from fem_squeal.reduced.model import ReducedModel

    base, _, _ = runs
    rm = ReducedModel.load(base / "serial" / "reduced_model.npz")
    eq = static_equilibrium(from_reduced(rm, cubic_share=0.0))
    assert eq.iterations > 2
    assert eq.q == pytest.approx(rm.q_static, rel=1e-7, abs=1e-9 * np.max(np.abs(rm.q_static)))
    cubic = static_equilibrium(from_reduced(rm, cubic_share=0.5))
    assert cubic.residual <= 1e-10
    # a stiffer cubic law at the same preload: larger closures where the pressure is low
    assert sum(int((d > 0).sum()) for d in cubic.closure) >= sum(int((d > 0).sum()) for d in eq.closure)
