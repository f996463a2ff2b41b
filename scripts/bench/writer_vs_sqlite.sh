#!/usr/bin/env bash
# The writer of a real run against SQLite inserting the same rows itself.
#
# For each round, on fresh copies of DATABASE (a feature database, e.g. from
# `cashash generate_database`):
#   - every CASHASH binary given runs `exhaustive_matcher` on the CPU; its
#     own `Time: ... writing X s (Y s CPU)` is taken: the writer thread's
#     busy wall time, which includes its waits for a core while matching and
#     verification run beside it, and its CPU time (older builds print no
#     CPU time: "-");
#   - SQLite copies the rows that run wrote into another fresh copy with
#     `INSERT INTO matches SELECT * FROM run.matches ORDER BY pair_id` (and
#     the same for two_view_geometries) in one transaction: the time of that
#     transaction (BEGIN to the end of COMMIT), wall and CPU, is what SQLite
#     itself needs to insert the same rows in key order;
#   - the rows of every binary are compared with the first binary's.
# Binaries alternate within a round, so that a busy machine slows each alike.
# Prints each round and a table of medians, with the ratios writing / SQLite
# of wall and of CPU time. Run `uptime` beside it: on a loaded machine both
# wall times stretch, the writer's more (it shares the process's cores).
# Round columns: round, binary, writing wall s, SQLite wall s, rows, rows as
# binary 0, writing CPU s, SQLite CPU s, the run's pipeline s (Summary), so
# that a change that helps the writer by slowing the run shows.
#
# Usage: writer_vs_sqlite.sh DATABASE WORK_DIR ROUNDS CASHASH [CASHASH_BEFORE ...] [-- EXTRA_MATCHER_ARGS]
# e.g.   writer_vs_sqlite.sh s1k32.db /tmp/w 5 build/colmap_bridge/cashash /path/to/main/build/colmap_bridge/cashash
set -euo pipefail

if (($# < 4)); then
  sed -n '2,26p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
DATABASE="$1"; WORK="$2"; ROUNDS="$3"; shift 3
BINARIES=()
while (($#)) && [[ "$1" != "--" ]]; do BINARIES+=("$(readlink -f "$1")"); shift; done
[[ "${1:-}" == "--" ]] && shift
EXTRA=("$@")
mkdir -p "$WORK"
RESULTS="$WORK/writer_vs_sqlite.tsv"
: >"$RESULTS"

sqlite_insert_select() {  # sqlite_insert_select RUN_DB TARGET_DB: prints seconds
  python3 - "$1" "$2" <<'EOF'
import sqlite3, sys, time
run, target = sys.argv[1], sys.argv[2]
con = sqlite3.connect(target, isolation_level=None)
con.execute("ATTACH DATABASE ? AS run", (run,))
start = time.perf_counter()
cpu = time.thread_time()
con.execute("BEGIN IMMEDIATE")
con.execute("INSERT INTO main.matches SELECT * FROM run.matches ORDER BY pair_id")
con.execute("INSERT INTO main.two_view_geometries SELECT * FROM run.two_view_geometries ORDER BY pair_id")
con.execute("COMMIT")
print(f"{time.perf_counter() - start:.3f} {time.thread_time() - cpu:.3f}")
con.close()
EOF
}

same_rows() {  # same_rows A B: prints "same" or what differs
  python3 - "$1" "$2" <<'EOF'
import sqlite3, sys
con = sqlite3.connect(sys.argv[1])
con.execute("ATTACH DATABASE ? AS ref", (sys.argv[2],))
differ = []
for table in ("matches", "two_view_geometries"):
    n = con.execute(f"SELECT (SELECT count(*) FROM (SELECT * FROM main.{table} EXCEPT SELECT * FROM ref.{table}))"
                    f" + (SELECT count(*) FROM (SELECT * FROM ref.{table} EXCEPT SELECT * FROM main.{table}))").fetchone()[0]
    if n:
        differ.append(f"{table}: {n} rows differ")
print("same" if not differ else "; ".join(differ))
EOF
}

for round in $(seq "$ROUNDS"); do
  for b in "${!BINARIES[@]}"; do
    bin="${BINARIES[$b]}"
    run_db="$WORK/run_$b.db"
    rm -f "$run_db" "$run_db-wal" "$run_db-shm"
    cp "$DATABASE" "$run_db"
    "$bin" exhaustive_matcher --database_path "$run_db" --FeatureMatching.use_gpu 0 "${EXTRA[@]}" \
      >"$WORK/run_$b.log" 2>&1 || { cat "$WORK/run_$b.log"; exit 1; }
    writing="$(sed -n 's/^Time: .*writing \([0-9.]*\) s.*/\1/p' "$WORK/run_$b.log")"
    writing_cpu="$(sed -n 's/^Time: .*writing [0-9.]* s (\([0-9.]*\) s CPU).*/\1/p' "$WORK/run_$b.log")"
    run_s="$(sed -n 's/^Summary: [0-9]* pairs in \([0-9.]*\) s.*/\1/p' "$WORK/run_$b.log")"
    rows="$(sqlite3 "$run_db" "SELECT (SELECT count(*) FROM matches) + (SELECT count(*) FROM two_view_geometries)")"
    copy_db="$WORK/insert_select.db"
    rm -f "$copy_db" "$copy_db-wal" "$copy_db-shm"
    cp "$DATABASE" "$copy_db"
    read -r sqlite_s sqlite_cpu <<<"$(sqlite_insert_select "$run_db" "$copy_db")"
    rows_check="same"
    if ((b > 0)); then rows_check="$(same_rows "$run_db" "$WORK/run_0.db")"; fi
    printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$round" "$b" "$writing" "$sqlite_s" "$rows" "$rows_check" \
      "${writing_cpu:--}" "$sqlite_cpu" "$run_s" | tee -a "$RESULTS"
  done
done

python3 - "$RESULTS" "${BINARIES[@]}" <<'EOF'
import statistics, sys
rows = [line.split("\t") for line in open(sys.argv[1]).read().splitlines()]
binaries = sys.argv[2:]
print("\n| binary | rounds | rows | writing s (median, min-max) | INSERT ... SELECT s (median) | writing / SQLite, wall | writing CPU s | INSERT ... SELECT CPU s | writing / SQLite, CPU | run s (median) | rows as binary 0 |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for b, name in enumerate(binaries):
    mine = [r for r in rows if int(r[1]) == b]
    w = [float(r[2]) for r in mine]
    s = [float(r[3]) for r in mine]
    ratio = [float(r[2]) / float(r[3]) for r in mine]
    sc = [float(r[7]) for r in mine]
    if all(r[6] != "-" for r in mine):
        wc = [float(r[6]) for r in mine]
        cpu = (f"{statistics.median(wc):.2f} | {statistics.median(sc):.2f} | "
               f"{statistics.median(float(r[6]) / float(r[7]) for r in mine):.2f}")
    else:
        cpu = f"- | {statistics.median(sc):.2f} | -"
    same = all(r[5] == "same" for r in mine)
    print(f"| {b}: {name} | {len(mine)} | {mine[0][4]} | {statistics.median(w):.2f} ({min(w):.2f}-{max(w):.2f}) | "
          f"{statistics.median(s):.2f} | {statistics.median(ratio):.2f} | {cpu} | "
          f"{statistics.median(float(r[8]) for r in mine):.1f} | {'yes' if same else 'NO'} |")
EOF
