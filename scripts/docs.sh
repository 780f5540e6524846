#!/usr/bin/env bash
# Build the user guide (idempotent): scripts/docs.sh [extra sphinx options]
#   - Debian packages python3-sphinx and python3-myst-parser, apt-installed when missing (as
#     scripts/setup.sh does for its packages);
#   - the venv of scripts/setup.sh (its last output line), which sees the Debian packages;
#   - docs/conf.py generates docs/reference/scene.md from the schema in code
#     (fem_squeal.app.schema_reference), then Sphinx builds docs/_build/html with warnings as errors.
# Open docs/_build/html/index.html.  Exits non-zero if the build fails or warns.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/.." && pwd)
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"

pkgs=(python3-sphinx python3-myst-parser)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "[docs] installing Debian packages: ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q >&2
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}" >&2
fi

py=$("$here/setup.sh" | tail -n 1)
cd "$repo"
# conf.py imports the package (the API pages import its modules); under MPI as root, OpenMPI's
# singleton start needs these, as in scripts/demo.sh and scripts/test.sh.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 PYTHONDONTWRITEBYTECODE=1
"$py" -m sphinx -W --keep-going -b html "$@" docs docs/_build/html
echo "[docs] built $repo/docs/_build/html/index.html" >&2
