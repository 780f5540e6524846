"""The operating matrix's corner checks with a loss-factor table in frequency (issue 39, shims): the
Ryzhik ring (seed 003) with the disc's η(f, T) rising from 0.01 to 0.05 over 0–10 kHz at 0 °C; each watched
reduced mode (the unstable ones and the three least stable) solved in the full nonlinear eigenproblem
T(λ) = λ²M + λC + K + iη(|Im λ|/2π)K_disc from the reduced eigenvalue alone (fem_squeal.fe.projection.loss_nep).

Tolerances: the full answers are eigenpairs of T to a backward error of round-off (≤ 1e-14, measured 1.6e-17);
the reduced fixed point is within the reduced basis's error of them: the basis is grown until the unstable
eigenvalues change by less than 4.2e-6 between rounds, and the full NEP sits 8.1e-6 (0 °C) and 4.6e-6 (50 °C)
from it; 1e-4 leaves a margin of 12 for the other mesh of a second machine's BLAS."""
from __future__ import annotations

import json

import pytest
from support.paths import ROOT

RISING = ("{frequency=[0.0, 10000.0], temperature=[0.0, 100.0], eta=[[0.01, 0.05], [0.002, 0.01]], "
          "reference_frequency=1000.0, reference_temperature=20.0}")


@pytest.mark.slow
def test_corner_checks_solve_the_full_nonlinear_eigenproblem(tmp_path):
    from mpi4py import MPI

    from fem_squeal.app.analyses.operating_matrix import verification_failures
    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    scene = load_scene(ROOT / "scenes" / "ryzhik_ring.toml", [
        f"materials.disc.eta_table={RISING}",
        "analyses.operating_matrix={temperature=[0.0, 50.0], direction=['forward'], verify=true}"])
    run_scene(scene, tmp_path, MPI.COMM_SELF, cache=tmp_path / "cache", log=lambda *a: None)
    om = json.loads((tmp_path / "results.json").read_text())["operating_matrix"]
    rows = om["verification"]
    assert len(rows) == 2 and all(r["method"] == "full NEP" for r in rows)
    for r in rows:
        assert r["n_full"] >= 4 and r["n_unstable_full"] == r["n_unstable_reduced"] >= 1
        assert r["backward_error"] <= 1e-14
        assert r["max_rel_error"] <= 1e-4
    assert not verification_failures(om, 1e-4)
    # the rigid-body modes (f ≈ 0) are not followed by the fixed point: every band mode converges or is
    # reported at a frequency of its own
    for fp in om["loss_factor_fixed_point"]:
        assert all(m["frequency_hz"] > 10.0 for m in fp["not_converged"])
