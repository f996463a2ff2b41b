#!/usr/bin/env bash
# Matching cost of the CPU default at two feature counts, interleaved.
#
#   scripts/bench/cpu_linear_cost.sh DB_SMALL DB_LARGE REPEATS CASHASH [CASHASH ...] [-- EXTRA OPTIONS]
#
# For each repeat and each binary, matches a copy of DB_SMALL, then of
# DB_LARGE, with --FeatureMatching.use_gpu 0 and
# --FeatureMatching.skip_geometric_verification 1 (matching only), and
# prints one line a run: the Summary line's seconds and raw matches, the
# process's CPU seconds (user + system) and the hash tables chosen.
# Interleaving the builds and the sizes keeps a shared machine's load from
# favouring one of them; compare CPU seconds, which load inflates least.
# Example, on generated streets:
#   cashash generate_database --database_path street16_4096.db \
#     --source_database_path fountain-P11.db --num_images 16 --num_features 4096
#   scripts/bench/cpu_linear_cost.sh street16_4096.db street16_16384.db 3 build/colmap_bridge/cashash
set -euo pipefail
small=$1 large=$2 repeats=$3
shift 3
binaries=()
while [ $# -gt 0 ] && [ "$1" != "--" ]; do binaries+=("$1"); shift; done
[ $# -gt 0 ] && shift
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
run() {
  local db=$1 binary=$2
  shift 2
  cp "$db" "$work/run.db"
  /usr/bin/time -f "%U %S" -o "$work/time.txt" "$binary" exhaustive_matcher --database_path "$work/run.db" \
    --FeatureMatching.use_gpu 0 --FeatureMatching.skip_geometric_verification 1 "$@" > "$work/log.txt" 2>&1
  local summary cpu tables
  summary=$(grep -E "^Summary" "$work/log.txt" | sed 's/.*pairs in \([0-9.]*\) s.*; \([0-9]*\) raw.*/\1 s, \2 raw matches/')
  cpu=$(awk '{ printf "%.2f", $1 + $2 }' "$work/time.txt")
  tables=$(grep -o 'Hash tables: [0-9]* x [0-9]*' "$work/log.txt" || true)
  echo "$(basename "$db") | $binary $* | $summary | CPU $cpu s | $tables | load $(cut -d' ' -f1 /proc/loadavg)"
}
for ((i = 0; i < repeats; ++i)); do
  for binary in "${binaries[@]}"; do
    run "$small" "$binary" "$@"
    run "$large" "$binary" "$@"
  done
done
