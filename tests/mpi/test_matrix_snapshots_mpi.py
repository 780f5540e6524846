"""The snapshot basis of a model given as matrices built on 2 ranks (fem_squeal.fe.matrix_snapshots, each
rank on its rows) against the serial SciPy basis (fem_squeal.reduced.matrix_reduction.snapshot_basis): the
eigenvalues it resolves equal to 1e-10 (the same check on COMM_SELF: tests/integration/test_matrices.py)."""
from __future__ import annotations

import subprocess
import sys

import pytest
from support.paths import ROOT
from support.processes import clean_env

SCRIPT = """
import sys
import numpy as np
from mpi4py import MPI
sys.path[:0] = [r"{root}/scenes/matrices", r"{root}/tests/integration", r"{root}/tests"]
from make_matrices import matrices
from test_matrices import resolved_difference
from fem_squeal.fe.matrix_operators import scatter_rows
from fem_squeal.fe.matrix_snapshots import reduce_snapshot_rows
from fem_squeal.reduced.matrix_model import matrix_model
from fem_squeal.reduced.matrix_reduction import reduce_matrix_model

comm = MPI.COMM_WORLD
mats = matrices()
model = matrix_model({{"M": "M", "C": "D1 + W*DG + (1/W - 1)*DR + D4/(2*pi*1600)",
                      "K": "K1 + KR + (W**2 - 1)*KGEO"}}, list(mats), {{"W": 1.0}}, {{"W": (0.5, 3.0)}})
points = [{{"W": w}} for w in np.linspace(0.5, 3.0, 5)]
rows = {{n: scatter_rows(A if comm.rank == 0 else None, 48, comm) for n, A in mats.items()}}
b = reduce_snapshot_rows(model, rows, comm, points, 14, 600.0)
a = reduce_matrix_model(model, mats, basis="snapshots", snapshot_modes=14, target_hz=600.0, snapshot_points=points)
same = all(np.array_equal(x, y) for x, y in zip(comm.allgather(b.terms["K"])[0], b.terms["K"]))
print(comm.rank, a.size, b.size, b.info["built_on"], same, resolved_difference(a, b, (0.7, 1.0, 2.2)))
"""


@pytest.mark.slow           # a 2-rank run (6 s on a quiet machine, 24 s loaded); COMM_SELF in the default suite
@pytest.mark.mpi
def test_two_rank_snapshot_basis_equals_the_serial_one(mpirun, tmp_path):
    script = tmp_path / "snapshots.py"
    script.write_text(SCRIPT.format(root=ROOT))
    p = subprocess.run(mpirun + [sys.executable, str(script)], capture_output=True, text=True, env=clean_env(),
                       cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    lines = sorted(ln.split() for ln in p.stdout.splitlines() if ln[:2] in ("0 ", "1 "))
    assert [ln[0] for ln in lines] == ["0", "1"]
    for _, size_a, size_b, n, _, _, same, diff in lines:
        assert size_a == size_b and n == "2" and same == "True" and float(diff) <= 1e-10
