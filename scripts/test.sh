#!/usr/bin/env bash
# Set up (idempotent) and run the test suite: serial tests plus the mpirun -n 2 tests.
# setup.sh --test: also chromium, for the headless render of report.html (tests/test_pipeline.py).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
py=$("$here/setup.sh" --test | tail -n 1)
cd "$here/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 PYTHONDONTWRITEBYTECODE=1
exec "$py" -m pytest "$@"
