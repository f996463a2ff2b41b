#!/usr/bin/env bash
# A run stopped halfway -- kill -9, Ctrl-C (SIGINT), the disk filling up --
# must leave a valid database holding whole chunks only, and running again
# must finish with exactly the rows of an uninterrupted run. A reader polls
# the database during the killed run and must only ever see whole chunks.
# Synthetic features (60 images, 1770 pairs), CPU matching, block size 5.
# Usage: reliability_resume.sh CASHASH_BINARY [SHARED_DATA_DIR]   (exit 77: skipped)
set -euo pipefail

CASHASH="$1"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
TOOL="$HERE/reliability_db_tool.py"
PAIRS=1770  # 60 images

if ! python3 -c "import numpy" 2>/dev/null; then
  echo "SKIP: python3 numpy is not installed"; exit 77
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/cashash_reliability_resume.XXXXXX")"
cleanup() {
  [[ -n "${PID:-}" ]] && kill -9 "$PID" 2>/dev/null || true
  rm -rf "$WORK"
}
trap cleanup EXIT

match() {  # match DB [extra args]: the command every run uses
  local db="$1"; shift
  "$CASHASH" exhaustive_matcher --database_path "$db" --SiftMatching.use_gpu 0 --CasHash.matcher cascade \
    --ExhaustiveMatching.block_size 5 --database_commit_seconds 0 "$@"
}

# A commit per chunk (--database_commit_seconds 0), so that a kill lands
# between commits while most chunks are still to come; grouped commits are
# killed in writer_kill_resume.sh.
# Starts a run in the background and returns once it has committed at least
# MIN_PAIRS pairs (PID holds its process id).
start_and_wait_for_rows() {
  local db="$1" log="$2" min_pairs="$3"
  # exec: the signals must reach cashash itself, not a subshell.
  (exec "$CASHASH" exhaustive_matcher --database_path "$db" --SiftMatching.use_gpu 0 --CasHash.matcher cascade \
    --ExhaustiveMatching.block_size 5 --database_commit_seconds 0) >"$log" 2>&1 &
  PID=$!
  echo "$PID" >"$WORK/pid"
  for _ in $(seq 600); do
    if ! kill -0 "$PID" 2>/dev/null; then
      echo "FAIL: the run ended before it could be interrupted"; cat "$log"; exit 1
    fi
    local n
    n="$(python3 "$TOOL" count "$db" 2>/dev/null || echo 0)"
    if ((n >= min_pairs)); then return 0; fi
    sleep 0.05
  done
  echo "FAIL: no rows after 30 s"; cat "$log"; exit 1
}

python3 "$TOOL" make "$WORK/base.db"
cp "$WORK/base.db" "$WORK/reference.db"
match "$WORK/reference.db" >"$WORK/reference.log" 2>&1 || { cat "$WORK/reference.log"; exit 1; }
python3 "$TOOL" check "$WORK/reference.db" --pairs "$PAIRS"

echo "== kill -9 halfway, a reader polling meanwhile, then resume"
cp "$WORK/base.db" "$WORK/killed.db"
start_and_wait_for_rows "$WORK/killed.db" "$WORK/killed.log" 100 &
WAITER=$!
# The reader starts with the run and stops when the run's process is gone.
sleep 0.2
python3 "$TOOL" watch "$WORK/killed.db" "$WORK/pid" &
READER=$!
wait "$WAITER"
PID="$(cat "$WORK/pid")"
kill -9 "$PID"
while kill -0 "$PID" 2>/dev/null; do sleep 0.05; done
PID=""
wait "$READER"
python3 "$TOOL" check "$WORK/killed.db" --pairs $((PAIRS - 1))
match "$WORK/killed.db" >"$WORK/killed_resume.log" 2>&1 || { cat "$WORK/killed_resume.log"; exit 1; }
grep -E "^Skipping [0-9]+ of $PAIRS pairs already in the database" "$WORK/killed_resume.log"
python3 "$TOOL" check "$WORK/killed.db" --pairs "$PAIRS"
python3 "$TOOL" compare "$WORK/killed.db" "$WORK/reference.db"

echo "== SIGINT halfway: exit 130, 'run again to resume', then resume"
cp "$WORK/base.db" "$WORK/interrupted.db"
start_and_wait_for_rows "$WORK/interrupted.db" "$WORK/interrupted.log" 100
kill -INT "$PID"
rc=0
wait "$PID" || rc=$?
PID=""
if [[ $rc -ne 130 ]]; then echo "FAIL: exit status $rc after SIGINT, expected 130"; cat "$WORK/interrupted.log"; exit 1; fi
grep "run again to resume" "$WORK/interrupted.log"
python3 "$TOOL" check "$WORK/interrupted.db" --pairs $((PAIRS - 1))
match "$WORK/interrupted.db" >"$WORK/interrupted_resume.log" 2>&1 || { cat "$WORK/interrupted_resume.log"; exit 1; }
python3 "$TOOL" compare "$WORK/interrupted.db" "$WORK/reference.db"

echo "== disk full (file size limit) halfway, then resume"
cp "$WORK/base.db" "$WORK/full.db"
# The limit (KiB) lets the run commit a few chunks, then every write past it
# fails with EFBIG (SIGXFSZ ignored) as on a full disk.
LIMIT_KB=$(( $(stat -c %s "$WORK/base.db") / 1024 + 1500 ))
rc=0
( trap '' XFSZ; ulimit -f "$LIMIT_KB"; exec "$CASHASH" exhaustive_matcher --database_path "$WORK/full.db" \
    --SiftMatching.use_gpu 0 --CasHash.matcher cascade --ExhaustiveMatching.block_size 5 ) >"$WORK/full.log" 2>&1 || rc=$?
if [[ $rc -ne 1 ]]; then echo "FAIL: exit status $rc with a full disk, expected 1"; cat "$WORK/full.log"; exit 1; fi
grep "^ERROR: " "$WORK/full.log"
python3 "$TOOL" check "$WORK/full.db" --pairs $((PAIRS - 1))
match "$WORK/full.db" >"$WORK/full_resume.log" 2>&1 || { cat "$WORK/full_resume.log"; exit 1; }
python3 "$TOOL" compare "$WORK/full.db" "$WORK/reference.db"
echo "PASS"
