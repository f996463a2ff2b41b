#!/usr/bin/env bash
# Runs the Python package's pytest suite (python/tests), which includes the
# pycolmap pipeline on sceaux_castle when the data is there, on the module
# that the CMake build made (MODULE, cashash._core) beside the package's
# Python files; without MODULE it builds the package with `pip install .`
# (CPU backend, module only) into a temporary folder first. Either way the
# package's metadata (pyproject.toml) must be readable by pip.
# Usage: python_module.sh <cashash binary> <shared data dir> [MODULE]   (exit 77: skipped)
# The CMake build folder build-python/ of `pip install .` is kept between
# runs, so only changed files are compiled again.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
SHARED="${2:-}"
MODULE="${3:-}"

for module in pybind11 scikit_build_core pytest numpy; do
  if ! python3 -c "import $module" 2>/dev/null; then
    echo "SKIP: Python module '$module' is missing (scripts/install_deps.sh installs it)"; exit 77
  fi
done

WORK="$(mktemp -d "${TMPDIR:-/tmp}/cashash_python.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT

# A module built for another Python than this python3 cannot be imported.
suffix="$(python3 -c "import sysconfig; print(sysconfig.get_config_var('EXT_SUFFIX'))")"
if [[ -n "$MODULE" && "$MODULE" != *"$suffix" ]]; then
  echo "The CMake build's module $MODULE is not for this python3 ($suffix): building one with pip"
  MODULE=""
fi

if [[ -n "$MODULE" ]]; then
  # pip reads the package's metadata (scikit-build-core, without compiling).
  (cd "$REPO" && python3 -m pip install --no-build-isolation --no-deps --disable-pip-version-check --quiet \
    --dry-run .) > "$WORK/pip.log" 2>&1 || { tail -40 "$WORK/pip.log"; exit 1; }
  mkdir -p "$WORK/site"
  cp -r "$REPO/python/cashash" "$WORK/site/cashash"
  cp "$MODULE" "$WORK/site/cashash/"
  echo "Module of the CMake build: $MODULE"
else
  if command -v ccache > /dev/null; then export CMAKE_CXX_COMPILER_LAUNCHER=ccache; fi
  export CMAKE_BUILD_PARALLEL_LEVEL="${CMAKE_BUILD_PARALLEL_LEVEL:-$(nproc)}"
  start=$SECONDS
  # No build isolation: build with the installed pybind11 and scikit-build-core
  # instead of downloading them for every run.
  (cd "$REPO" && python3 -m pip install --no-build-isolation --no-deps --disable-pip-version-check --quiet \
    --target "$WORK/site" .) > "$WORK/pip.log" 2>&1 || { tail -40 "$WORK/pip.log"; exit 1; }
  echo "pip install .: $((SECONDS - start)) s"
fi

# The module must load where no MPI library is installed (most pip users):
# only the cashash executable links MPI.
module="$(find "$WORK/site/cashash" -name '_core*.so' | head -n 1)"
if readelf -d "$module" | grep -i 'NEEDED.*libmpi'; then
  echo "FAIL: $module needs an MPI library"
  exit 1
fi

export PYTHONPATH="$WORK/site"
if [[ -n "$SHARED" ]]; then export CASHASH_SHARED_DATA="$SHARED"; fi
set +e
(cd "$WORK" && python3 -m pytest -q -p no:cacheprovider "$REPO/python/tests")
code=$?
set -e
# pytest exits 5 when it collected no test at all: the suite is broken (a
# skipped test still counts as collected and exits 0).
if [[ $code -eq 5 ]]; then
  echo "FAIL: pytest collected no tests from $REPO/python/tests"
  exit 1
fi
exit $code
