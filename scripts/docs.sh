#!/usr/bin/env bash
# Build the user guide (idempotent): scripts/docs.sh [extra sphinx options]
#   - scripts/setup.sh --docs: the Debian packages python3-sphinx and python3-myst-parser besides the
#     stack, and the venv (its last output line), which sees the Debian packages;
#   - docs/conf.py generates docs/reference/scene.md from the schema in code
#     (fem_squeal.app.schema_reference), then Sphinx builds docs/_build/html with warnings as errors.
# Open docs/_build/html/index.html.  Exits non-zero if the build fails or warns.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/.." && pwd)
py=$("$here/setup.sh" --docs | tail -n 1)
cd "$repo"
# conf.py imports the package (the API pages import its modules); under MPI as root, OpenMPI's
# singleton start needs these, as in scripts/demo.sh and scripts/test.sh.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 PYTHONDONTWRITEBYTECODE=1
"$py" -m sphinx -W --keep-going -b html "$@" docs docs/_build/html
echo "[docs] built $repo/docs/_build/html/index.html" >&2
