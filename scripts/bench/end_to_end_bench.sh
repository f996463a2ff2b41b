#!/usr/bin/env bash
# What a user waits for: `cashash exhaustive_matcher` from start to finish
# (matching, verification, writing) in several configurations, and COLMAP's
# own exhaustive matcher (pycolmap, GPU when it has CUDA) on the same
# database, each on its own copy, in one run on one machine. Writes one
# Markdown table, OUT_DIR/table.md (process wall time, pairs/s by the run's
# summary line, the stage busy and waiting times, raw matches, verified
# pairs, inlier matches), and its plot, OUT_DIR/end_to_end.png (pairs/s of
# the whole command, scripts/bench/plot_end_to_end.py), and prints the table.
#
# Usage: end_to_end_bench.sh CASHASH DB OUT_DIR
# Environment (defaults in brackets):
#   CONFIGS ["default bruteforce cascade guided"]: default = no option
#       (--CasHash.matcher auto), bruteforce / cascade = --CasHash.matcher X,
#       guided = `cashash guided_matcher`, full_budget = default with
#       --TwoViewGeometry.early_exit 0, no_rematch = default with
#       --CasHash.exact_rematch_min_matches 0 (the cascade's matches kept),
#       cascade_no_rematch = the same with --CasHash.matcher cascade,
#       default+NAME=VALUE[+NAME=VALUE...] = default with --NAME VALUE ...
#       (for example default+CasHash.top_k=5),
#       guided_paper = guided_matcher with the paper's stage 2 (search within
#       the band, no fallback), matching_only = default with
#       --FeatureMatching.skip_geometric_verification 1
#   TIME_LIMIT [0]: stop each cashash run with SIGINT after this many seconds
#       (0: run to the end); the run commits what is in flight and prints its
#       summary, so rates are over the pairs reached
#   COLMAP [1]: also run pycolmap's match_exhaustive (GPU when pycolmap has
#       CUDA); COLMAP_TIME_LIMIT [0]: kill it after this many seconds and
#       count the pairs it committed (rate up to its last database write)
#   EXTRA: more options for every cashash run
#   COPY [1]: each run on its own copy of DB; 0: cashash runs on DB itself
#       with --overwrite 1 (for databases too large to copy; COLMAP still
#       gets a copy, with the match tables emptied)
set -u -o pipefail

CASHASH="$1"; DB="$2"; OUT="$3"
CONFIGS="${CONFIGS:-default bruteforce cascade guided}"
TIME_LIMIT="${TIME_LIMIT:-0}"
COLMAP="${COLMAP:-1}"
COLMAP_TIME_LIMIT="${COLMAP_TIME_LIMIT:-0}"
EXTRA="${EXTRA:-}"
COPY="${COPY:-1}"
mkdir -p "$OUT"
TABLE="$OUT/table.md"
WORK="$OUT/work"
mkdir -p "$WORK"
now() { date +%s.%N; }

{
  echo "# end_to_end_bench.sh $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(nproc) cores; database $(basename "$DB")"
  command -v nvidia-smi > /dev/null 2>&1 && nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | head -1
  echo
  echo "| run | wall s | pairs | pairs/s (summary) | loading s | hashing s | matching s | verification s | writing s | waiting: matching for verification / verification for matching s | raw matches | verified pairs | inlier matches |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
} > "$TABLE"

for config in $CONFIGS; do
  command=(exhaustive_matcher)
  options=()
  case "$config" in
    default) ;;
    bruteforce | cascade) options=(--CasHash.matcher "$config") ;;
    guided) command=(guided_matcher) ;;
    matching_only) options=(--FeatureMatching.skip_geometric_verification 1) ;;
    guided_paper) command=(guided_matcher)
                  options=(--GuidedMatching.restrict_search_to_band 1 --GuidedMatching.unguided_fallback 0) ;;
    full_budget) options=(--TwoViewGeometry.early_exit 0) ;;
    no_rematch) options=(--CasHash.exact_rematch_min_matches 0) ;;
    cascade_no_rematch) options=(--CasHash.matcher cascade --CasHash.exact_rematch_min_matches 0) ;;
    default+*)
      IFS='+' read -r -a assignments <<< "${config#default+}"
      for assignment in "${assignments[@]}"; do options+=("--${assignment%%=*}" "${assignment#*=}"); done ;;
    *) echo "unknown config $config" >&2; continue ;;
  esac
  copy="$WORK/$config.db"
  if [ "$COPY" = 1 ]; then
    cp "$DB" "$copy"
  else
    copy="$DB"
    options+=(--overwrite 1)
  fi
  log="$OUT/$config.log"
  start=$(now)
  # shellcheck disable=SC2086
  "$CASHASH" "${command[@]}" --database_path "$copy" "${options[@]}" $EXTRA > "$log" 2>&1 &
  pid=$!
  if [ "$TIME_LIMIT" != 0 ]; then
    ( sleep "$TIME_LIMIT"; kill -INT "$pid" 2> /dev/null ) &
    timer=$!
  fi
  wait "$pid"
  rc=$?
  [ "$TIME_LIMIT" != 0 ] && kill "$timer" 2> /dev/null
  wall=$(awk -v a="$start" -v b="$(now)" 'BEGIN { printf "%.2f", b - a }')
  python3 - "$log" "$config" "$wall" "$rc" >> "$TABLE" << 'EOF'
import re, sys
log, config, wall, rc = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
text = open(log, errors="replace").read()
def num(pattern, default=float("nan")):
    m = re.search(pattern, text)
    return float(m.group(1)) if m else default
pairs = num(r"Summary: (\d+) pairs")
rate = num(r"pairs in [\d.]+ s \(([\d.]+) pairs/s\)")
stage = {k: num(k + r" ([\d.]+) s") for k in ("loading", "hashing", "matching", "verification", "writing")}
wait_m = num(r"Waiting: matching for verification ([\d.]+) s")
wait_v = num(r"verification for matching ([\d.]+) s")
raw = num(r"; (\d+) raw matches")
verified = num(r"(\d+) verified pairs")
inliers = num(r"(\d+) inlier matches")
matcher = re.search(r"pairs/s\) with ([^;]+);", text)
name = config + (" (" + matcher.group(1) + ")" if matcher else "") + ("" if rc in ("0", "130") else " exit " + rc)
f = lambda v, d=0: "n/a" if v != v else f"{v:,.{d}f}"
print(f"| {name} | {wall:.2f} | {f(pairs)} | {f(rate)} | {f(stage['loading'], 2)} | {f(stage['hashing'], 2)} | "
      f"{f(stage['matching'], 2)} | {f(stage['verification'], 2)} | {f(stage['writing'], 2)} | {f(wait_m, 2)} / {f(wait_v, 2)} | "
      f"{f(raw)} | {f(verified)} | {f(inliers)} |")
EOF
  { echo "$config:"; grep -E "GPU verification|Matcher|auto|Hash tables|Exact rematch|Process:|Outside the pipeline" "$log" | head -8 | sed 's/^/    /'; } >> "$OUT/notes.txt"
  [ "$COPY" = 1 ] && rm -f "$copy" "$copy-wal" "$copy-shm"
done

if [ "$COLMAP" = 1 ]; then
  copy="$WORK/colmap.db"
  cp "$DB" "$copy"
  python3 -c "
import sqlite3, sys
c = sqlite3.connect(sys.argv[1])
for t in ('matches', 'two_view_geometries', 'cashash_empty_pairs'):
    try:
        c.execute('DELETE FROM ' + t)
    except sqlite3.OperationalError:
        pass
c.commit()" "$copy"
  python3 "$(dirname "$0")/colmap_exhaustive_timed.py" "$copy" "$COLMAP_TIME_LIMIT" >> "$TABLE" 2> "$OUT/colmap.log"
  rm -f "$copy" "$copy-wal" "$copy-shm"
fi
python3 "$(dirname "$0")/plot_end_to_end.py" "$TABLE" --png "$OUT/end_to_end.png"
cat "$TABLE"
[ -f "$OUT/notes.txt" ] && cat "$OUT/notes.txt"
exit 0
