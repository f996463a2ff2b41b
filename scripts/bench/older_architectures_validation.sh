#!/usr/bin/env bash
# Runs the code paths of older GPUs on a newer card and checks them against
# a build for the card itself (README, "GPU architectures"):
#   - the GPU tests of builds holding PTX only for compute_75 and compute_80
#     (the driver compiles it for the card at load time);
#   - a generated 300-image street matched by the reference build and by
#     those two: the matches and two_view_geometries tables must be equal,
#     and the pipeline seconds of each (summary line) are printed beside the
#     reference's, default matcher and brute force;
#   - a build holding SASS for sm_80 only (no PTX), which a 9.0 card cannot
#     load: its one-line message, exit code 0, and rows equal to a CPU run
#     (--FeatureMatching.use_gpu 0) of the same binary.
#
# Usage: older_architectures_validation.sh BINARIES SOURCE_DB WORK [ROUNDS]
#   BINARIES/{reference,ptx75,ptx80,sm80}/cashash; BINARIES/{ptx75,ptx80}/tests/gpu_*_test;
#   BINARIES/lib: shared libraries the binaries need beyond the system's (optional);
#   BINARIES/before/cashash (optional): an earlier build for the card, timed beside the reference.
#   SOURCE_DB: a COLMAP database with real SIFT features (e.g. 7 images);
#   WORK: a scratch folder; ROUNDS: timed runs per build (default 3).
set -uo pipefail
BIN="$1"
SOURCE_DB="$2"
WORK="$3"
ROUNDS="${4:-3}"
mkdir -p "$WORK"
[[ -d "$BIN/lib" ]] && export LD_LIBRARY_PATH="$BIN/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,compute_cap,driver_version --format=csv,noheader

STREET_BUILDS="reference ptx75 ptx80"
[[ -x "$BIN/before/cashash" ]] && STREET_BUILDS="before $STREET_BUILDS"
for build in reference ptx75 ptx80 sm80; do
  echo "== $build: $("$BIN/$build/cashash" --version)"
done

# Digest of each result table, in a fixed order.
table_digests() {
  python3 - "$1" <<'PY'
import hashlib, sqlite3, sys
db = sqlite3.connect(sys.argv[1])
out = []
for table in ("matches", "two_view_geometries"):
    h = hashlib.sha256()
    rows = db.execute(f"SELECT * FROM {table} ORDER BY pair_id").fetchall()
    for row in rows:
        h.update(repr(row).encode())
    out.append(f"{table} {len(rows)} rows {h.hexdigest()[:16]}")
print("; ".join(out))
PY
}

"$BIN/reference/cashash" generate_database --database_path "$WORK/street.db" --source_database_path "$SOURCE_DB" \
  --num_images 300 --num_features 8192 >"$WORK/generate.log" 2>&1 || { echo "generate_database failed"; tail "$WORK/generate.log"; exit 1; }

# One run on a fresh copy: prints "build mode rc seconds digests".
run_one() {
  local build="$1" mode="$2" round="$3"
  shift 3
  local db="$WORK/run.$build.$mode.$round.db"
  cp "$WORK/street.db" "$db"
  "$BIN/$build/cashash" exhaustive_matcher --database_path "$db" "$@" >"$db.out" 2>"$db.err"
  local rc=$?
  local seconds
  seconds=$(sed -n 's/^Summary: [0-9]* pairs in \([0-9.]*\) s.*/\1/p' "$db.out")
  echo "$build $mode round $round: rc $rc, ${seconds:-?} s; $(table_digests "$db")"
  rm -f "$db" "$db-wal" "$db-shm"
}

echo "== streets (the first round of each build includes compiling its PTX for the card)"
for round in $(seq 0 "$ROUNDS"); do
  for build in $STREET_BUILDS; do
    run_one "$build" default "$round"
    run_one "$build" bruteforce "$round" --CasHash.matcher bruteforce
  done
done

echo "== SASS for sm_80 only on this card"
cp "$WORK/street.db" "$WORK/sm80.db"
"$BIN/sm80/cashash" exhaustive_matcher --database_path "$WORK/sm80.db" >"$WORK/sm80.out" 2>"$WORK/sm80.err"
echo "sm80 exit code: $?"
echo "sm80 stderr:"
cat "$WORK/sm80.err"
grep -m2 "^cashash \|^Summary" "$WORK/sm80.out"
echo "sm80 GPU run rows: $(table_digests "$WORK/sm80.db")"
cp "$WORK/street.db" "$WORK/sm80cpu.db"
"$BIN/sm80/cashash" exhaustive_matcher --database_path "$WORK/sm80cpu.db" --FeatureMatching.use_gpu 0 \
  >"$WORK/sm80cpu.out" 2>"$WORK/sm80cpu.err"
echo "sm80 CPU run exit code: $?"
echo "sm80 CPU run rows: $(table_digests "$WORK/sm80cpu.db")"

echo "== GPU tests"
for build in ptx75 ptx80; do
  for test in "$BIN/$build"/tests/*_test; do
    name=$(basename "$test")
    (cd "$WORK" && timeout 150 "$test" >"$WORK/$build.$name.log" 2>&1)
    rc=$?
    passed=$(grep -c '^\[       OK \]' "$WORK/$build.$name.log")
    skipped=$(grep -c '^\[  SKIPPED \]' "$WORK/$build.$name.log")
    failed=$(grep -c '^\[  FAILED  \]' "$WORK/$build.$name.log")
    echo "$build $name: rc $rc, $passed passed; SKIPPED lines $skipped, FAILED lines $failed (each counted in the list and the summary)"
  done
done

