#!/usr/bin/env bash
# Reliability checks beyond the normal suite (docs/RELIABILITY.md):
#  1. the CPU test suite built with AddressSanitizer + UndefinedBehaviorSanitizer
#     in its own build folder, run without the integration tests, then the
#     bad-input integration test on the sanitized binary;
#  2. the libFuzzer targets of tests/fuzz, each run for a bounded time, seeded
#     from small real-schema databases.
# Where clang has libFuzzer, one clang build serves both, and the suite also
# runs under a second compiler (scripts/test.sh builds with the default one,
# g++ on Debian). Without it: a sanitized build with the default compiler,
# and no fuzzing.
# No CUDA, no benchmarks. A finding fails the script; libFuzzer leaves the
# crashing input in the build folder (crash-*), to replay with
# `build-sanitize-clang/tests/NAME_fuzz crash-...`.
#
# Usage: scripts/sanitize_and_fuzz.sh
# Environment:
#   CASHASH_SANITIZE_BUILD_DIR  (default build-sanitize-clang/ in the repo, or
#                               build-sanitize/ without clang's libFuzzer)
#   CASHASH_FUZZ_SECONDS        seconds of wall time of the fuzz targets, which run
#                               side by side (default 60: about 40 s of a core each
#                               on two cores)
#   CASHASH_SKIP_SANITIZE=1, CASHASH_SKIP_FUZZ=1  leave a part out
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FUZZ_SECONDS="${CASHASH_FUZZ_SECONDS:-60}"
SHARED="${CASHASH_SHARED_DATA:-$REPO/../shared/data}"
JOBS="$(nproc)"

log() { echo "[sanitize_and_fuzz] $*"; }

LAUNCHER=()
if command -v ccache >/dev/null; then LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
# -O1: sanitized code at -O3 takes several times longer to compile for little
# gain in test speed. No Python module: it would need the sanitizer runtime
# preloaded into Python.
COMMON=(-DCASHASH_CUDA=OFF -DCASHASH_BUILD_PYTHON=OFF -DCMAKE_BUILD_TYPE=Release
        "-DCMAKE_CXX_FLAGS_RELEASE=-O1 -DNDEBUG" -DCASHASH_SHARED_DATA="$SHARED" "${LAUNCHER[@]}")
# Ninja for a new build folder (see scripts/test.sh).
generator_for() { if [[ ! -f "$1/CMakeCache.txt" ]] && command -v ninja >/dev/null; then echo "-GNinja"; fi; }

# libFuzzer ships with clang (Debian: clang and libclang-rt-NN-dev).
probe="$(mktemp -d)"
trap 'rm -rf "$probe"' EXIT
echo 'extern "C" int LLVMFuzzerTestOneInput(const char*, unsigned long) { return 0; }' >"$probe/p.cc"
FUZZ=1
if [[ "${CASHASH_SKIP_FUZZ:-0}" == 1 ]]; then
  FUZZ=0
elif ! command -v clang++ >/dev/null || ! clang++ -fsanitize=fuzzer "$probe/p.cc" -o "$probe/p" 2>/dev/null; then
  log "SKIP fuzzing: clang++ with libFuzzer not found (apt-get install clang libclang-rt-14-dev)"
  FUZZ=0
fi
if [[ "$FUZZ" == 1 ]]; then
  BUILD="${CASHASH_SANITIZE_BUILD_DIR:-$REPO/build-sanitize-clang}"
  COMPILER=(env CC=clang CXX=clang++)
  COMMON+=(-DCASHASH_FUZZ=ON)
else
  BUILD="${CASHASH_SANITIZE_BUILD_DIR:-$REPO/build-sanitize}"
  COMPILER=()
fi

if [[ "$FUZZ" != 1 && "${CASHASH_SKIP_SANITIZE:-0}" == 1 ]]; then exit 0; fi

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"

log "ASan+UBSan build${COMPILER:+ with clang} in $BUILD"
"${COMPILER[@]}" cmake -S "$REPO" -B "$BUILD" $(generator_for "$BUILD") -DCASHASH_SANITIZE=ON "${COMMON[@]}" >/dev/null
cmake --build "$BUILD" -j"$JOBS"

if [[ "${CASHASH_SKIP_SANITIZE:-0}" != 1 ]]; then
  log "CPU suite with -fsanitize=address,undefined"
  # Left to the Release suite: the one unit test that runs COLMAP's full
  # RANSAC budget for E eight times (7 s in Release, 100 s sanitized); the
  # same estimators run sanitized in every other geometry test.
  (cd "$BUILD" && ctest --output-on-failure -j"$JOBS" \
     -E "integration|RansacEarlyExit.EssentialStopsOnceTheDecisionIsSettled")
  # The one integration test that is all error paths, on the sanitized binary.
  log "reliability_bad_input.sh on the sanitized cashash"
  bash "$REPO/tests/integration/reliability_bad_input.sh" "$BUILD/colmap_bridge/cashash" "$SHARED"
fi

if [[ "$FUZZ" != 1 ]]; then exit 0; fi
targets=()
for source in "$REPO"/tests/fuzz/*_fuzz.cc; do targets+=("$(basename "$source" .cc)"); done

# Seeds for the database target: small databases (512-byte pages, rollback
# journal) in COLMAP 3.8's layout with features and matches, and, where the
# tools exist, empty ones made by COLMAP itself and by pycolmap (4.x).
SEEDS="$BUILD/seeds/database_fuzz"
rm -rf "$SEEDS" && mkdir -p "$SEEDS"
TOOL="$REPO/tests/integration/reliability_db_tool.py"
if python3 -c "import numpy" 2>/dev/null; then
  python3 "$TOOL" make "$SEEDS/synthetic.db" --images 3 --features 4 --points 20 --journal delete --page_size 512
  cp "$SEEDS/synthetic.db" "$SEEDS/matched.db"
  "$BUILD/colmap_bridge/cashash" exhaustive_matcher --database_path "$SEEDS/matched.db" \
    --SiftMatching.use_gpu 0 --SiftMatching.min_num_inliers 3 >/dev/null 2>&1 || true
fi
if command -v colmap >/dev/null; then
  QT_QPA_PLATFORM=offscreen colmap database_creator --database_path "$SEEDS/colmap.db" >/dev/null 2>&1 || true
fi
python3 "$REPO/scripts/make_colmap4_database.py" "$SEEDS/pycolmap.db" >/dev/null 2>&1 || true
for db in "$SEEDS"/*.db; do
  python3 - "$db" <<'PY' || rm -f "$db"
import sqlite3, sys
con = sqlite3.connect(sys.argv[1], isolation_level=None)
con.execute("PRAGMA journal_mode=DELETE")
con.execute("PRAGMA page_size=512")
con.execute("VACUUM")
PY
done
rm -f "$SEEDS"/*-wal "$SEEDS"/*-shm "$SEEDS"/*-journal "$BUILD"/tests/cashash 2>/dev/null || true

# database_fuzz writes each input to a scratch file: in memory where possible.
if [[ -d /dev/shm && -w /dev/shm ]]; then export TMPDIR=/dev/shm; fi
# The targets run side by side (libFuzzer runs one thread each), for
# FUZZ_SECONDS of wall time each: on two cores three of them get about two
# thirds of a core each.
pids=()
for target in "${targets[@]}"; do
  name="${target%_fuzz}"
  corpus="$BUILD/corpus/$target"  # grows from run to run
  mkdir -p "$corpus"
  seed_dirs=()
  [[ -d "$REPO/tests/fuzz/corpus/$name" ]] && seed_dirs+=("$REPO/tests/fuzz/corpus/$name")
  [[ -d "$BUILD/seeds/$target" ]] && seed_dirs+=("$BUILD/seeds/$target")
  log "$target for ${FUZZ_SECONDS}s (seeds: ${seed_dirs[*]:-none})"
  (cd "$BUILD" && "$BUILD/tests/$target" -max_total_time="$FUZZ_SECONDS" -timeout=20 \
     -rss_limit_mb=2560 -max_len=65536 -print_final_stats=1 "$corpus" "${seed_dirs[@]}" \
     >"$BUILD/$target.log" 2>&1) &
  pids+=($!)
done
status=0
for index in "${!targets[@]}"; do
  target="${targets[$index]}"
  if ! wait "${pids[$index]}"; then
    tail -60 "$BUILD/$target.log"
    log "FAIL: $target found a problem (input saved as $BUILD/crash-* / timeout-* / oom-*)"
    status=1
  else
    log "$target:"
    grep -E "^stat::number_of_executed_units|^stat::peak_rss_mb|^#[0-9]+ *DONE" "$BUILD/$target.log" || true
  fi
done
exit $status
