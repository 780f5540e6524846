"""The environment of a child process (a CLI run, a demo, ``mpirun``)."""
from __future__ import annotations

import os


def clean_env() -> dict[str, str]:
    """Environment for child processes.  ``os.environ`` is Python's snapshot from start-up; the
    C environ (used when ``env=None``) also holds the PMIX_/OMPI_ variables that this process's
    singleton MPI_Init added, and those make a child ``mpirun`` misbehave."""
    # every OMPI_*/PMIX_* variable but the run-as-root ones: a pytest-xdist worker inherits in its
    # os.environ what the controlling process's singleton MPI_Init set (OMPI_MCA_ess, OMPI_MCA_pmix,
    # OMPI_APP_CTX_NUM_PROCS), and a child mpirun given them exits 1 without a word
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PMIX_", "OMPI_")) or k.startswith("OMPI_ALLOW_RUN_AS_ROOT")}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env
