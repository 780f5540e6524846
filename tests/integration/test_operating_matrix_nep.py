"""The operating matrix's corner checks with a loss-factor table in frequency (issue 39, shims): the
Ryzhik ring (seed 003) with the disc's η(f, T) rising from 0.01 to 0.05 over 0–10 kHz at 0 °C; each watched
reduced mode (the unstable ones and the three least stable) solved in the full nonlinear eigenproblem
T(λ) = λ²M + λC + K + iη(|Im λ|/2π)K_disc from the reduced eigenvalue alone (fem_squeal.fe.projection.loss_nep).

Tolerances: the full answers are eigenpairs of T to a backward error of round-off (≤ 1e-14, measured 1.6e-17);
the reduced fixed point is within the reduced basis's error of them: with the loss-factor static corrections
in the basis the full NEP sits 9.1e-7 (0 °C) and 7.6e-7 (50 °C) from it (8.1e-6 and 4.6e-6 without them,
whatever the cut); 2e-6 is the issue's 1e-6 target with a margin of 2 for a second machine's round-off in
the basis (its eigenvalues' changes between rounds are 2.2e-6)."""
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
        assert r["max_rel_error"] <= 2e-6
    assert not verification_failures(om, 2e-6)
    # every band mode converges (rigid-body modes, f ≈ 0, are not followed) but one at 50 °C that starts
    # at 9999.99 Hz and steps over the table's 10 kHz end (reported as left_table, not hidden)
    for fp in om["loss_factor_fixed_point"]:
        assert all(m["left_table"] and m["frequency_hz"] > 9990.0 for m in fp["not_converged"])
        assert fp["converged"] >= fp["modes"] - 1
