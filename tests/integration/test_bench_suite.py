"""The benchmark entry point (CI smoke case): ``fem-squeal bench --quick --only stress_coalescence``
runs the quick benchmark in a subprocess and writes its table, plot and the summary."""
from __future__ import annotations

import subprocess
import sys

from support.paths import ROOT
from support.processes import clean_env


def test_bench_quick_smoke(tmp_path):
    env = dict(clean_env(), FEM_SQUEAL_BENCH_OUT=str(tmp_path))
    cmd = [sys.executable, "-m", "fem_squeal.cli", "bench", "--quick", "--only", "stress_coalescence"]
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    table = (tmp_path / "stress_coalescence_1ranks_quick.md").read_text()
    assert "| δ/μ_c |" in table and "Tracker" in table
    assert (tmp_path / "stress_coalescence_1ranks_quick.png").stat().st_size > 1000
    summary = (tmp_path / "SUMMARY_quick.md").read_text()
    assert "| stress_coalescence |" in summary and "| ok |" in summary
    assert "## stress_coalescence_1ranks_quick" in summary


def test_bench_rejects_unknown_names(tmp_path):
    env = dict(clean_env(), FEM_SQUEAL_BENCH_OUT=str(tmp_path))
    out = subprocess.run([sys.executable, "-m", "fem_squeal.cli", "bench", "--only", "nope"], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and "unknown benchmark" in out.stderr + out.stdout
