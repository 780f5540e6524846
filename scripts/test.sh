#!/usr/bin/env bash
# Set up (idempotent) and run the test suite: serial tests plus the mpirun -n 2 tests.
# setup.sh --test: also chromium (the headless render of report.html) and pytest-xdist.
# The suite runs on every core (pytest-xdist, one worker per core, a test file per worker so that
# its module fixtures are built once), one OpenBLAS thread per worker (two workers of two threads on
# two cores would oversubscribe them: OpenBLAS's waiting threads spin).  FEM_SQUEAL_TEST_WORKERS=1,
# or -n/-p no:xdist among the arguments, runs it in one process.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
py=$("$here/setup.sh" --test | tail -n 1)
cd "$here/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 PYTHONDONTWRITEBYTECODE=1
workers=${FEM_SQUEAL_TEST_WORKERS:-$(nproc 2>/dev/null || echo 1)}
parallel=()
case " $* " in *" -n "*|*" -n="*|*"no:xdist"*) workers=1 ;; esac
if [ "$workers" -gt 1 ] && "$py" -c "import xdist" >/dev/null 2>&1; then
  parallel=(-n "$workers" --dist loadfile)
  export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}
fi
exec "$py" -m pytest "${parallel[@]}" "$@"
