#!/usr/bin/env bash
# `mpirun -np 3 cashash ...` on one machine must write exactly the rows of
# one process: exhaustive_matcher with blocks given, with blocks and groups
# derived from a small --max_host_memory (several groups), on a
# rollback-journal database, resuming a partly matched database;
# matches_importer on a pair list; and a database another process is
# matching must be refused by the whole job. Synthetic features (60 images,
# 1770 pairs), CPU matching.
# Usage: mpi_exhaustive.sh CASHASH_BINARY [SHARED_DATA_DIR]   (exit 77: skipped)
set -euo pipefail

CASHASH="$1"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
TOOL="$HERE/reliability_db_tool.py"
PAIRS=1770

command -v mpirun >/dev/null || { echo "SKIP: mpirun not found (apt-get install openmpi-bin)"; exit 77; }
if ! ldd "$CASHASH" 2>/dev/null | grep libmpi >/dev/null; then
  echo "SKIP: $CASHASH was built without MPI (install libopenmpi-dev and reconfigure)"; exit 77
fi
python3 -c "import numpy" 2>/dev/null || { echo "SKIP: python3 numpy is not installed"; exit 77; }

# Open MPI refuses to run as root unless told that it is meant.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# One machine, few cores: no network probing, no binding.
export OMPI_MCA_btl=self,vader OMPI_MCA_rmaps_base_oversubscribe=1

WORK="$(mktemp -d "${TMPDIR:-/tmp}/cashash_mpi.XXXXXX")"
cleanup() {
  [[ -n "${HOLDER:-}" ]] && kill "$HOLDER" 2>/dev/null || true
  rm -rf "$WORK"
}
trap cleanup EXIT

single() {  # single DB [extra args]
  local db="$1"; shift
  "$CASHASH" exhaustive_matcher --database_path "$db" --SiftMatching.use_gpu 0 --CasHash.matcher cascade "$@"
}
ranks3() {  # ranks3 DB [extra args]: 3 processes, one thread each
  local db="$1"; shift
  mpirun -np 3 --oversubscribe --bind-to none "$CASHASH" exhaustive_matcher --database_path "$db" \
    --SiftMatching.use_gpu 0 --CasHash.matcher cascade --FeatureMatching.num_threads 1 "$@"
}
expect_mpi_run() {  # expect_mpi_run LOG: rank 0 reported all three ranks
  grep -q "^Matched by 3 MPI processes" "$1" || { echo "FAIL: not a 3-rank run"; cat "$1"; exit 1; }
}

python3 "$TOOL" make "$WORK/base.db"
python3 "$TOOL" make "$WORK/base_delete.db" --journal delete

cp "$WORK/base.db" "$WORK/reference.db"
single "$WORK/reference.db" --ExhaustiveMatching.block_size 10 >"$WORK/reference.log" 2>&1 ||
  { cat "$WORK/reference.log"; exit 1; }
python3 "$TOOL" check "$WORK/reference.db" --pairs "$PAIRS"

echo "== 3 ranks, blocks of 10 (21 block pairs)"
cp "$WORK/base.db" "$WORK/mpi.db"
ranks3 "$WORK/mpi.db" --ExhaustiveMatching.block_size 10 >"$WORK/mpi.log" 2>&1 || { cat "$WORK/mpi.log"; exit 1; }
expect_mpi_run "$WORK/mpi.log"
grep "^Summary" "$WORK/mpi.log"
python3 "$TOOL" compare "$WORK/mpi.db" "$WORK/reference.db"

echo "== 3 ranks, blocks and groups from --max_host_memory 20M"
cp "$WORK/base.db" "$WORK/groups.db"
ranks3 "$WORK/groups.db" --max_host_memory 20M >"$WORK/groups.log" 2>&1 || { cat "$WORK/groups.log"; exit 1; }
expect_mpi_run "$WORK/groups.log"
grep "^Schedule" "$WORK/groups.log"
grep -qE "blocks, [2-9][0-9]* groups\)" "$WORK/groups.log" || { echo "FAIL: expected several groups"; exit 1; }
python3 "$TOOL" compare "$WORK/groups.db" "$WORK/reference.db"

echo "== 3 ranks on a rollback-journal database (readers and the writer lock each other out briefly)"
cp "$WORK/base_delete.db" "$WORK/delete_reference.db"
single "$WORK/delete_reference.db" --ExhaustiveMatching.block_size 10 >"$WORK/delete_reference.log" 2>&1 ||
  { cat "$WORK/delete_reference.log"; exit 1; }
cp "$WORK/base_delete.db" "$WORK/delete.db"
ranks3 "$WORK/delete.db" --ExhaustiveMatching.block_size 10 >"$WORK/delete.log" 2>&1 ||
  { cat "$WORK/delete.log"; exit 1; }
expect_mpi_run "$WORK/delete.log"
python3 "$TOOL" compare "$WORK/delete.db" "$WORK/delete_reference.db"

echo "== 3 ranks resume a database holding a third of the pairs"
cp "$WORK/reference.db" "$WORK/resume.db"
python3 - "$WORK/resume.db" <<'PY'
import sqlite3, sys
con = sqlite3.connect(sys.argv[1])
for table in ("matches", "two_view_geometries"):
    con.execute(f"DELETE FROM {table} WHERE pair_id % 3 != 0")
con.commit()
PY
kept="$(python3 "$TOOL" count "$WORK/resume.db")"
ranks3 "$WORK/resume.db" --ExhaustiveMatching.block_size 10 >"$WORK/resume.log" 2>&1 ||
  { cat "$WORK/resume.log"; exit 1; }
expect_mpi_run "$WORK/resume.log"
grep -E "^Skipping $kept of $PAIRS pairs already in the database" "$WORK/resume.log"
grep -qE "^Summary: $((PAIRS - kept)) pairs" "$WORK/resume.log" || { echo "FAIL: resumed pair count"; cat "$WORK/resume.log"; exit 1; }
python3 "$TOOL" compare "$WORK/resume.db" "$WORK/reference.db"

echo "== matches_importer: 3 ranks match a pair list as one process does"
python3 -c "
for i in range(1, 41):
    for j in range(i + 1, 41, 3):
        print(f'image_{i:03d}.png image_{j:03d}.png')" >"$WORK/pairs.txt"
for n in 1 3; do
  cp "$WORK/base.db" "$WORK/list$n.db"
  launch=()
  [[ $n == 3 ]] && launch=(mpirun -np 3 --oversubscribe --bind-to none)
  "${launch[@]}" "$CASHASH" matches_importer --database_path "$WORK/list$n.db" --match_list_path "$WORK/pairs.txt" \
    --SiftMatching.use_gpu 0 --CasHash.matcher cascade --FeatureMatching.num_threads 1 --ExhaustiveMatching.block_size 5 \
    >"$WORK/list$n.log" 2>&1 || { cat "$WORK/list$n.log"; exit 1; }
done
expect_mpi_run "$WORK/list3.log"
python3 "$TOOL" compare "$WORK/list3.db" "$WORK/list1.db"

echo "== a database another process is matching: the whole job is refused, nothing written"
cp "$WORK/base.db" "$WORK/locked.db"
# flock on the database file, as cashash's writer lock takes it.
python3 -c '
import fcntl, sys, time
f = open(sys.argv[1], "rb"); fcntl.flock(f, fcntl.LOCK_EX); print("locked", flush=True); time.sleep(120)
' "$WORK/locked.db" >"$WORK/holder.log" &
HOLDER=$!
for _ in $(seq 100); do grep -q locked "$WORK/holder.log" && break; sleep 0.1; done
rc=0
ranks3 "$WORK/locked.db" --ExhaustiveMatching.block_size 10 >"$WORK/locked.log" 2>&1 || rc=$?
kill "$HOLDER"; HOLDER=""
[[ $rc -ne 0 ]] || { echo "FAIL: the locked database was matched"; cat "$WORK/locked.log"; exit 1; }
grep -q "is being matched by another cashash process" "$WORK/locked.log" ||
  { echo "FAIL: no lock message"; cat "$WORK/locked.log"; exit 1; }
[[ "$(python3 "$TOOL" count "$WORK/locked.db")" == 0 ]] || { echo "FAIL: rows written"; exit 1; }
echo "refused (exit $rc)"

echo "PASS: 3 MPI ranks write the rows of one process"
