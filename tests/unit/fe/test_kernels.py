"""The compiled kernels are built with the package (setup.py), never at run time (issue 34).

- Where their prerequisites are on the machine (a C compiler, CHOLMOD's headers, which
  scripts/setup.sh installs), every kernel is built and loads: a build that silently failed would
  leave the slower library path running without a word.
- The CHOLMOD shim reports the version of the cholmod.h it was compiled against, the one of the
  library it runs with (CHOLMOD 3 in SuiteSparse 5 on Debian bookworm).
- The tally of paths (``fem_squeal.fe.kernels.note``/``tally``) counts and resets.
"""
from __future__ import annotations

import os
import shutil

import numpy as np
import pytest
import scipy.sparse as sp

from fem_squeal.fe import cholmod, kernels


def _cholmod_header() -> bool:
    return any(os.path.isfile(os.path.join(d, "cholmod.h")) for d in ("/usr/include/suitesparse",
                                                                       "/usr/local/include/suitesparse"))


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler here")
def test_every_kernel_is_built_where_it_can_be():
    built = kernels.status()
    want = [n for n in kernels.NAMES if n != "cholmod_shim" or _cholmod_header()]
    assert all(built[n] for n in want), f"kernels not built: {[n for n in want if not built[n]]} " \
                                        "(run scripts/setup.sh, or pip install -e . again)"
    for n in want:
        assert kernels.path(n).parent == kernels.FOLDER


def test_unknown_kernel_is_refused():
    with pytest.raises(ValueError, match="unknown kernel 'nope'"):
        kernels.library("nope")


@pytest.mark.skipif(not cholmod.available(), reason="CHOLMOD shim not built")
def test_cholmod_shim_matches_the_library_and_solves():
    assert cholmod.version().startswith("3.")
    n = 400
    A = sp.diags([-np.ones(n - 1), 2.5 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    B = np.random.default_rng(1).standard_normal((n, 3))
    with cholmod.Cholesky(A.indptr, A.indices, A.data) as F:
        X = F.solve(B)
        assert F.factor_entries >= n and F.flops > 0
    assert np.abs(A @ X - B).max() <= 1e-13 * np.abs(B).max()
    with pytest.raises(cholmod.NotPositiveDefinite):
        cholmod.Cholesky(A.indptr, A.indices, -A.data)


def test_tally_counts_and_resets():
    kernels.tally(reset=True)
    kernels.note("block_solve", "cholmod")
    kernels.note("block_solve", "cholmod")
    kernels.note("assembly", "dolfinx")
    assert kernels.tally(reset=True) == {"assembly": {"dolfinx": 1}, "block_solve": {"cholmod": 2}}
    assert kernels.tally() == {}
