"""The environment of a child process (a CLI run, a demo, ``mpirun``)."""
from __future__ import annotations

import atexit
import os
import shutil
import tempfile


def private_cache() -> str:
    """A new, empty stage-cache folder for one child process, removed when the test process exits."""
    path = tempfile.mkdtemp(prefix="fem_squeal_cache_")
    atexit.register(shutil.rmtree, path, ignore_errors=True)
    return path


def clean_env() -> dict[str, str]:
    """Environment for child processes.  ``os.environ`` is Python's snapshot from start-up; the
    C environ (used when ``env=None``) also holds the PMIX_/OMPI_ variables that this process's
    singleton MPI_Init added, and those make a child ``mpirun`` misbehave.

    Every call names a private, empty stage cache (``FEM_SQUEAL_CACHE``): a child never reads the
    user's cache nor another test's entries, so a run on 2 ranks compared with one on 1 rank computes
    every stage (with a shared cache the second run would read the first one's results and the
    comparison could not fail).  A test that means to reuse a cache passes ``--cache-dir`` or sets
    ``FEM_SQUEAL_CACHE`` itself."""
    # every OMPI_*/PMIX_* variable but the run-as-root ones: a pytest-xdist worker inherits in its
    # os.environ what the controlling process's singleton MPI_Init set (OMPI_MCA_ess, OMPI_MCA_pmix,
    # OMPI_APP_CTX_NUM_PROCS), and a child mpirun given them exits 1 without a word
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PMIX_", "OMPI_")) or k.startswith("OMPI_ALLOW_RUN_AS_ROOT")}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", FEM_SQUEAL_CACHE=private_cache())
    return env
