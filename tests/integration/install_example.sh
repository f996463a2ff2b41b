#!/usr/bin/env bash
# Installs the built libraries into a temporary prefix, builds examples/
# against the installed package (find_package(cashash)) and runs it: once on
# features in memory, once on a small COLMAP database when colmap exists.
# Usage: install_example.sh <cashash binary> <shared data dir>
# The build folder is the one that holds the binary. Exit 77 = skipped.
set -euo pipefail

BINARY="$(realpath "$1")"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
BUILD="$(dirname "$(dirname "$BINARY")")"
command -v cmake > /dev/null || { echo "cmake not found; skipping"; exit 77; }

WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT

cmake --install "$BUILD" --prefix "$WORK/prefix" --component devel > "$WORK/install.log"
test -f "$WORK/prefix/lib/cmake/cashash/cashashConfig.cmake"
test -f "$WORK/prefix/include/colmap_bridge/api/matching_api.h"
# Only the API headers and what they include: the pipeline's and the
# database's internals stay private.
for internal in cashash/pipeline/feature_cache.h cashash/pipeline/blocking_queue.h colmap_bridge/database.h; do
  if [[ -e "$WORK/prefix/include/$internal" ]]; then
    echo "FAIL: the internal header $internal is installed"
    exit 1
  fi
done

launcher=()
if command -v ccache > /dev/null; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
cmake -S "$REPO/examples" -B "$WORK/example" -DCMAKE_PREFIX_PATH="$WORK/prefix" -DCMAKE_BUILD_TYPE=Release \
  "${launcher[@]}" > "$WORK/configure.log" || { cat "$WORK/configure.log"; exit 1; }
cmake --build "$WORK/example" -j2 > "$WORK/build.log" || { cat "$WORK/build.log"; exit 1; }

# The installed cashash::cashash target links no MPI (only the cashash
# executable does), neither directly nor through its package config.
if readelf -d "$WORK/example/cashash_example" | grep -i 'NEEDED.*libmpi'; then
  echo "FAIL: a program linked with cashash::cashash needs an MPI library"
  exit 1
fi
if grep -qi 'find_dependency(MPI' "$WORK/prefix/lib/cmake/cashash/cashashConfig.cmake"; then
  echo "FAIL: the installed package config asks for MPI"
  exit 1
fi

echo "== in memory"
"$WORK/example/cashash_example"

if command -v colmap > /dev/null; then
  echo "== on an empty COLMAP database"
  QT_QPA_PLATFORM=offscreen colmap database_creator --database_path "$WORK/empty.db" > /dev/null
  "$WORK/example/cashash_example" "$WORK/empty.db"
fi
echo "install_example: OK"
