#!/usr/bin/env bash
# Set up (idempotent) and run the main demo under MPI: scripts/demo.sh [NRANKS] (default 2).
# The default brake scene end to end (scenes/brake_mu_E_map.toml): preload, CEA, reduced model
# checked against the full CEA (nominal point; lifted residuals at the design points), μ sweep and
# (μ, E) stability map; writes
# out/mu_E_stability_map/report.html and checks its own results.  Stages are cached in
# $XDG_CACHE_HOME/fem_squeal (or $FEM_SQUEAL_CACHE), so a second run only re-checks.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
py=$("$here/setup.sh" | tail -n 1)
cd "$here/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
exec mpirun -n "${1:-2}" --oversubscribe "$py" demos/mu_E_stability_map.py
