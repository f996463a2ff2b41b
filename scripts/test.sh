#!/usr/bin/env bash
# Builds everything and runs the whole test suite: unit tests, the CUDA tests
# when the CUDA backend is built (they skip themselves without a GPU), and the
# end-to-end tests on the rendered scene and on real photographs.
#
# Quick check while working, the unit tests alone (under 5 minutes on two
# cores, once built):
#   cmake --build build -j2 && ctest --test-dir build -L unit -j2
# Labels: unit, gpu, integration, slow (tests/CMakeLists.txt); this script
# runs them all.
#
# Usage: scripts/test.sh [extra ctest arguments, e.g. -L integration]
# Environment:
#   CASHASH_BUILD_DIR    build folder (default: build/ in the repo)
#   CASHASH_SHARED_DATA  real data sets (default: ../shared/data beside the repo)
#   CASHASH_SKIP_DEPS=1  do not call install_deps.sh
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${CASHASH_BUILD_DIR:-$REPO/build}"
SHARED="${CASHASH_SHARED_DATA:-$REPO/../shared/data}"
JOBS="$(nproc)"

if [[ "${CASHASH_SKIP_DEPS:-0}" != 1 ]]; then
  "$REPO/scripts/install_deps.sh"
fi

# The CUDA backend is compiled whenever nvcc exists (CMake's AUTO), so that
# CUDA code is checked to build even on machines without a GPU; without one
# that is the portable list (SASS 7.5, 8.0, 8.6, 8.9, 9.0 and PTX 9.0), so a
# change that breaks one architecture fails here.
# Ninja where it exists, for a new build folder: it compiles a target's
# sources while the libraries it links are still being built, which make
# does not, and so keeps both cores busy.
GENERATOR=()
if [[ ! -f "$BUILD/CMakeCache.txt" ]] && command -v ninja >/dev/null; then GENERATOR=(-G Ninja); fi
cmake -S "$REPO" -B "$BUILD" "${GENERATOR[@]}" -DCMAKE_BUILD_TYPE=Release -DCASHASH_SHARED_DATA="$SHARED"
cmake --build "$BUILD" -j"$JOBS"

cd "$BUILD"
ctest --output-on-failure -j"$JOBS" "$@"

# Sanitizer build of the CPU suite and bounded fuzzing (docs/RELIABILITY.md).
[[ "${CASHASH_SKIP_SANITIZE_AND_FUZZ:-0}" == 1 ]] || CASHASH_SHARED_DATA="$SHARED" "$REPO/scripts/sanitize_and_fuzz.sh"
