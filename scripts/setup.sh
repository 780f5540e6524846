#!/usr/bin/env bash
# Idempotent set-up of fem_squeal on Debian bookworm (root, or sudo available).
#   - Debian packages: the FEniCSx 0.5.2 stack, MPI, OpenBLAS (2.3-3x faster shift-invert solves).
#   - A venv at $FEM_SQUEAL_VENV (default: <repo>/.venv) that sees the Debian packages,
#     with fem_squeal installed editable. numpy/mpi4py/petsc4py/slepc4py are never pip-installed.
#   - The package's compiled kernels (fem_squeal/fe/kernels/*.c) are built by that install (setup.py,
#     against Debian's gcc and libsuitesparse-dev), and rebuilt when their sources change; nothing is
#     compiled at run time.
# Usage: scripts/setup.sh [--test] [--docs] [--bench] [--packages-only]
#   (prints the venv python path on its last line, except with --packages-only)
#   --test:  also what only the test suite needs: chromium (485 MB; the headless render of
#            report.html in tests/integration/test_pipeline.py), pytest-xdist (the suite on every core) and
#            Sphinx with the MyST parser (the user guide, built by tests/integration/test_docs.py through
#            scripts/docs.sh).  scripts/test.sh passes it.
#   --docs:  also Sphinx with the MyST parser (scripts/docs.sh passes it).
#   --bench: also the peers of the benchmark suite: CalculiX (Debian calculix-ccx), GetFEM (Debian
#            python3-getfem), scikit-fem (pure Python, pip-installed into the venv without dependencies:
#            numpy/scipy stay Debian's) and scikit-sparse (CHOLMOD for GetFEM's and scikit-fem's eigsh:
#            built by pip against Debian's libsuitesparse-dev, cython3 and numpy, without dependencies).
#   --packages-only: only the Debian packages and the OpenBLAS selection; no venv, and nothing of
#            the project is read but this script (docker/Dockerfile runs it before copying the
#            sources, so that the package layer survives source edits).  Prints nothing on stdout.
set -euo pipefail
bench=0
tests=0
docs=0
packages_only=0
for a in "$@"; do
  case "$a" in
    --bench) bench=1 ;;
    --test) tests=1 ;;
    --docs) docs=1 ;;
    --packages-only) packages_only=1 ;;
    *) echo "setup.sh: unknown option $a (known: --test, --docs, --bench, --packages-only)" >&2; exit 2 ;;
  esac
done
repo=$(cd "$(dirname "$0")/.." && pwd)
venv=${FEM_SQUEAL_VENV:-$repo/.venv}
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"

pkgs=(python3-dolfinx python3-petsc4py python3-slepc4py python3-gmsh python3-meshio
      python3-venv python3-setuptools python3-pip python3-pytest python3-matplotlib python3-scipy
      python3-hypothesis python3-cffi python3-threadpoolctl openmpi-bin libopenblas0-pthread gcc libc6-dev libsuitesparse-dev)
[ "$tests" -eq 1 ] && pkgs+=(chromium python3-pytest-xdist) && docs=1
[ "$docs" -eq 1 ] && pkgs+=(python3-sphinx python3-myst-parser)
[ "$bench" -eq 1 ] && pkgs+=(calculix-ccx python3-getfem cython3 python3-dev)

missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "[setup] installing Debian packages: ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q >&2
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}" >&2
fi

# OpenBLAS must be the libblas.so.3 provider; the reference BLAS is 2.3-3x slower here.
# The multiarch triplet (x86_64-linux-gnu, aarch64-linux-gnu, ...) from Debian's own Python, which
# the packages above always bring (dpkg-architecture is in dpkg-dev, absent from minimal images).
arch=$(/usr/bin/python3 -c 'import sysconfig; print(sysconfig.get_config_var("MULTIARCH") or "")' 2>/dev/null || true)
if [ -z "$arch" ]; then
  echo "[setup] warning: no multiarch triplet from /usr/bin/python3; OpenBLAS selection skipped" >&2
else
  ob=/usr/lib/$arch/openblas-pthread/libblas.so.3
  if [ -e "$ob" ] && [ "$(readlink -f "/etc/alternatives/libblas.so.3-$arch" 2>/dev/null)" != "$(readlink -f "$ob")" ]; then
    echo "[setup] selecting OpenBLAS ($arch) as libblas.so.3/liblapack.so.3" >&2
    $SUDO update-alternatives --set "libblas.so.3-$arch" "$ob" >&2 || true
    ol=/usr/lib/$arch/openblas-pthread/liblapack.so.3
    [ -e "$ol" ] && { $SUDO update-alternatives --set "liblapack.so.3-$arch" "$ol" >&2 || true; }
  fi
fi
[ "$packages_only" -eq 1 ] && exit 0

if [ ! -x "$venv/bin/python" ]; then
  echo "[setup] creating venv $venv" >&2
  /usr/bin/python3 -m venv --system-site-packages "$venv"
fi
# Editable install, no dependency resolution: every runtime dependency comes from Debian.  It builds
# the compiled kernels in place (setup.py); a change to their sources or the build files rebuilds them.
stamp="$venv/.fem_squeal_installed"
stale=0
for f in "$repo/pyproject.toml" "$repo/setup.py" "$repo"/fem_squeal/fe/kernels/*.[ch]; do
  [ "$f" -nt "$stamp" ] && stale=1
done
if [ ! -f "$stamp" ] || [ "$stale" -eq 1 ] || \
   ! "$venv/bin/python" -c "import fem_squeal" >/dev/null 2>&1; then
  echo "[setup] installing fem_squeal (editable, with its compiled kernels) into $venv" >&2
  "$venv/bin/python" -m pip install -q --no-deps --no-build-isolation -e "$repo" >&2
  touch "$stamp"
fi
if [ "$bench" -eq 1 ] && ! "$venv/bin/python" -c "import skfem" >/dev/null 2>&1; then
  echo "[setup] installing scikit-fem (benchmark peer) into $venv" >&2
  "$venv/bin/python" -m pip install -q --no-deps "scikit-fem==12.0.2" >&2
fi
if [ "$bench" -eq 1 ] && ! "$venv/bin/python" -c "import sksparse.cholmod" >/dev/null 2>&1; then
  echo "[setup] building scikit-sparse (CHOLMOD, benchmark peers) into $venv" >&2
  "$venv/bin/python" -m pip install -q --no-deps --no-build-isolation "scikit-sparse==0.4.16" >&2
fi
echo "$venv/bin/python"
