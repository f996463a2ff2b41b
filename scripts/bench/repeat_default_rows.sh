#!/usr/bin/env bash
# Runs `cashash exhaustive_matcher` with default options ten times, each on a
# fresh copy of one feature database (never written), and prints each run's
# wall time, the load average and a digest of every row of `matches` and
# `two_view_geometries` in pair order: a reproducible default prints the
# same digest ten times, whatever the load.
#
# Usage: scripts/bench/repeat_default_rows.sh CASHASH_BINARY DATABASE WORK_DIR [RUNS] [-- extra options]
set -euo pipefail
BIN=${1:?usage: repeat_default_rows.sh CASHASH_BINARY DATABASE WORK_DIR [RUNS]}
SRC=${2:?database}
WORK=${3:?work dir}
RUNS=${4:-10}
shift $(( $# < 4 ? $# : 4 ))
[[ "${1:-}" == "--" ]] && shift
mkdir -p "$WORK"
for i in $(seq 1 "$RUNS"); do
  DB="$WORK/run$i.db"
  rm -f "$DB" "$DB-wal" "$DB-shm"
  python3 -c "import sqlite3,sys; s=sqlite3.connect('file:'+sys.argv[1]+'?mode=ro',uri=True); d=sqlite3.connect(sys.argv[2]); s.backup(d); d.close()" "$SRC" "$DB"
  start=$(date +%s.%N)
  "$BIN" exhaustive_matcher --database_path "$DB" --SiftMatching.use_gpu 0 "$@" > "$WORK/run$i.log" 2>&1
  end=$(date +%s.%N)
  digest=$(python3 -c "
import sqlite3, sys, hashlib
c = sqlite3.connect(sys.argv[1]); h = hashlib.sha256()
for t in ('matches', 'two_view_geometries'):
    for row in c.execute('SELECT * FROM ' + t + ' ORDER BY pair_id'):
        h.update(repr(row).encode())
print(h.hexdigest()[:16])" "$DB")
  echo "run $i: $(python3 -c "print(f'{$end - $start:.1f}')") s, load $(cut -d' ' -f1 /proc/loadavg), rows sha256 $digest"
done
