"""fem_squeal: finite-element brake-squeal analysis on FEniCSx (dolfinx 0.5.2, PETSc/SLEPc 3.18)."""
from __future__ import annotations

import os as _os

# Under mpirun each rank must use one BLAS thread: 2 ranks x 2 OpenBLAS threads oversubscribe 2 cores.
if int(_os.environ.get("OMPI_COMM_WORLD_SIZE", _os.environ.get("PMI_SIZE", "1"))) > 1:
    _os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    _os.environ.setdefault("OMP_NUM_THREADS", "1")

__version__ = "0.1.0"
