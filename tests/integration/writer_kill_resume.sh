#!/usr/bin/env bash
# The writer groups chunks into transactions (DatabaseResultSink's
# commit_seconds): a kill -9 must still leave whole chunks only, and resuming
# must end with exactly the rows of an uninterrupted run. A run on 120
# synthetic images (7,140 pairs, block size 6: 210 chunks of about 10 ms,
# a few seconds on the CPU) is killed twice, each time once its first commit
# is visible, with --database_commit_seconds 0.25 (each transaction some 25
# chunks; the kill lands while later chunks sit in an open one); after
# each kill every block pair must be in the database with all its pairs or
# with none. Then a third run finishes, and every row of matches and
# two_view_geometries must equal an uninterrupted run's.
# Usage: writer_kill_resume.sh CASHASH_BINARY [SHARED_DATA_DIR]   (exit 77: skipped)
set -euo pipefail

CASHASH="$1"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
TOOL="$HERE/reliability_db_tool.py"
IMAGES=120
BLOCK=6
PAIRS=$((IMAGES * (IMAGES - 1) / 2))

if ! python3 -c "import numpy" 2>/dev/null; then
  echo "SKIP: python3 numpy is not installed"; exit 77
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/cashash_writer_kill_resume.XXXXXX")"
cleanup() {
  [[ -n "${PID:-}" ]] && kill -9 "$PID" 2>/dev/null || true
  rm -rf "$WORK"
}
trap cleanup EXIT

ARGS=(--SiftMatching.use_gpu 0 --CasHash.matcher cascade --ExhaustiveMatching.block_size "$BLOCK")

python3 "$TOOL" make "$WORK/base.db" --images "$IMAGES" --features 80 --points 300
cp "$WORK/base.db" "$WORK/reference.db"
"$CASHASH" exhaustive_matcher --database_path "$WORK/reference.db" "${ARGS[@]}" >"$WORK/reference.log" 2>&1 ||
  { cat "$WORK/reference.log"; exit 1; }
python3 "$TOOL" check "$WORK/reference.db" --pairs "$PAIRS" --block_size "$BLOCK"

cp "$WORK/base.db" "$WORK/killed.db"
for attempt in 1 2; do
  before="$(python3 "$TOOL" count "$WORK/killed.db")"
  # exec: the signal must reach cashash itself, not a subshell.
  (exec "$CASHASH" exhaustive_matcher --database_path "$WORK/killed.db" "${ARGS[@]}" --database_commit_seconds 0.25) \
    >"$WORK/killed_$attempt.log" 2>&1 &
  PID=$!
  committed=""
  for _ in $(seq 1200); do
    if ! kill -0 "$PID" 2>/dev/null; then
      echo "FAIL: run $attempt ended before it could be killed"; cat "$WORK/killed_$attempt.log"; exit 1
    fi
    n="$(python3 "$TOOL" count "$WORK/killed.db" 2>/dev/null || echo 0)"
    if ((n > before)); then committed="$n"; break; fi
    sleep 0.05
  done
  [[ -n "$committed" ]] || { echo "FAIL: run $attempt committed nothing in 60 s"; cat "$WORK/killed_$attempt.log"; exit 1; }
  kill -9 "$PID"
  while kill -0 "$PID" 2>/dev/null; do sleep 0.05; done
  PID=""
  echo "run $attempt killed after its first commit (${committed} pairs visible then)"
  python3 "$TOOL" check "$WORK/killed.db" --pairs $((PAIRS - 1)) --block_size "$BLOCK"
done

"$CASHASH" exhaustive_matcher --database_path "$WORK/killed.db" "${ARGS[@]}" >"$WORK/resume.log" 2>&1 ||
  { cat "$WORK/resume.log"; exit 1; }
grep -E "^Skipping [0-9]+ of $PAIRS pairs already in the database" "$WORK/resume.log"
python3 "$TOOL" check "$WORK/killed.db" --pairs "$PAIRS" --block_size "$BLOCK"
python3 "$TOOL" compare "$WORK/killed.db" "$WORK/reference.db"
echo "PASS"
