#!/usr/bin/env bash
# Set up (idempotent) and run the main demo under MPI: scripts/demo.sh [NRANKS] (default 2).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
py=$("$here/setup.sh" | tail -n 1)
cd "$here/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
exec mpirun -n "${1:-2}" --oversubscribe "$py" demos/ryzhik_ring.py
