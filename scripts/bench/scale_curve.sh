#!/usr/bin/env bash
# Speed against collection size: `cashash exhaustive_matcher` run to the end
# on generated streets of growing size, and COLMAP's own exhaustive matcher
# (pycolmap, on the GPU where pycolmap has CUDA) for a fixed time on a copy
# of each database, in one run on one machine. Two kinds of street: every
# image with the same feature count ("equal"), and feature counts drawn as a
# real extraction spreads them ("extraction": many images at the cap, the
# rest below it). Writes a CSV, a plot and a Markdown table.
#
# Usage: scale_curve.sh CASHASH SOURCE_DB OUT_DIR
#   SOURCE_DB: a COLMAP database with real SIFT features (docs/BENCHMARKS.md
#   makes one from 7 sceaux_castle images).
# Environment (defaults in brackets):
#   SIZES ["1000 2500 5000 10000"]: images per street
#   KINDS ["equal extraction"]
#   NUM_FEATURES [8192]: features per image, the cap for "extraction"
#   COLMAP_TIME_LIMIT [20]: seconds COLMAP matches each street (0: not run);
#       its rate counts the pairs it committed up to its last write
#   WORK [/tmp/cashash_scale_curve]: where the databases go (about 1.2 MiB
#       per image of 8,192 features, twice with COLMAP's copy)
#   EXTRA: more options for every cashash run
#   APPEND [0]: 1 adds the rows to OUT_DIR/scale_curve.csv of an earlier call
#       (sizes split over calls shorter than a time limit) and tabulates and
#       plots them all
# Writes OUT_DIR/scale_curve.csv, the table OUT_DIR/scale_curve.md and its
# plot OUT_DIR/scale_curve.png (scripts/bench/plot_scale_curve.py), and
# OUT_DIR/logs/; prints the table.
set -u -o pipefail

CASHASH="$1"; SOURCE_DB="$2"; OUT="$3"
SIZES="${SIZES:-1000 2500 5000 10000}"
KINDS="${KINDS:-equal extraction}"
NUM_FEATURES="${NUM_FEATURES:-8192}"
COLMAP_TIME_LIMIT="${COLMAP_TIME_LIMIT:-20}"
WORK="${WORK:-/tmp/cashash_scale_curve}"
EXTRA="${EXTRA:-}"
APPEND="${APPEND:-0}"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
mkdir -p "$OUT/logs" "$WORK"
CSV="$OUT/scale_curve.csv"

HAVE_SMI=0
command -v nvidia-smi > /dev/null 2>&1 && nvidia-smi > /dev/null 2>&1 && HAVE_SMI=1
[ "$APPEND" = 1 ] && [ -s "$CSV" ] || {
  echo "# scale_curve.sh $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(nproc) cores; $("$CASHASH" --version 2>&1 | head -1)"
  [ "$HAVE_SMI" = 1 ] && echo "# $(nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | head -1)"
  echo "kind,images,mean_features,pairs,wall_s,pipeline_s,pairs_per_s,matching_s,verification_s,writing_s,verified_pairs,peak_rss_mib,peak_gpu_mib,colmap_pairs,colmap_pairs_per_s,colmap_verified_pairs"
} > "$CSV"

# Peak memory of one process on the GPU, sampled every 200 ms until it exits.
gpu_peak_of() {
  local pid="$1" peak=0 used
  while kill -0 "$pid" 2> /dev/null; do
    used=$(nvidia-smi --query-compute-apps=pid,used_memory --format=csv,noheader,nounits 2> /dev/null |
      awk -F', *' -v p="$pid" '$1 == p { print $2 }')
    [ -n "$used" ] && [ "$used" -gt "$peak" ] && peak="$used"
    sleep 0.2
  done
  echo "$peak"
}

for kind in $KINDS; do
  for n in $SIZES; do
    db="$WORK/${kind}_${n}.db"
    log="$OUT/logs/${kind}_${n}"
    rm -f "$db"* "$WORK/colmap.db"*
    gen=(--num_features "$NUM_FEATURES")
    [ "$kind" = extraction ] && gen+=(--num_features_distribution extraction)
    if ! "$CASHASH" generate_database --database_path "$db" --source_database_path "$SOURCE_DB" \
      --num_images "$n" "${gen[@]}" > "$log.generate.log" 2>&1; then
      echo "generate_database failed for $kind $n:"; tail -3 "$log.generate.log"; continue
    fi
    mean=$(python3 -c "import sqlite3,sys; print(round(sqlite3.connect(sys.argv[1]).execute('SELECT AVG(rows) FROM descriptors').fetchone()[0]))" "$db")
    [ "$COLMAP_TIME_LIMIT" != 0 ] && cp "$db" "$WORK/colmap.db"
    # shellcheck disable=SC2086
    /usr/bin/time -f "%e %M" -o "$log.time" "$CASHASH" exhaustive_matcher --database_path "$db" $EXTRA \
      > "$log.cashash.log" 2>&1 &
    sleep 0.1
    pid=$(pgrep -n -f "exhaustive_matcher --database_path $db") || pid=""
    gpu_peak=""
    if [ "$HAVE_SMI" = 1 ] && [ -n "$pid" ]; then gpu_peak=$(gpu_peak_of "$pid"); fi
    wait
    read -r wall rss_kib < "$log.time" || { wall=""; rss_kib=0; }
    summary=$(grep '^Summary:' "$log.cashash.log" | tail -1)
    times=$(grep '^Time:' "$log.cashash.log" | tail -1)
    pairs=$(sed -E 's/^Summary: ([0-9]+) pairs in ([0-9.]+) s \(([0-9.]+) pairs\/s\).*/\1/' <<< "$summary")
    pipeline=$(sed -E 's/^Summary: ([0-9]+) pairs in ([0-9.]+) s.*/\2/' <<< "$summary")
    rate=$(sed -E 's/.*\(([0-9.]+) pairs\/s\).*/\1/' <<< "$summary")
    verified=$(sed -E 's/.* ([0-9]+) verified pairs.*/\1/' <<< "$summary")
    matching=$(sed -E 's/.*matching ([0-9.]+) s.*/\1/' <<< "$times")
    verification=$(sed -E 's/.*verification ([0-9.]+) s.*/\1/' <<< "$times")
    writing=$(sed -E 's/.*writing ([0-9.]+) s.*/\1/' <<< "$times")
    colmap_pairs=""; colmap_rate=""; colmap_verified=""
    if [ "$COLMAP_TIME_LIMIT" != 0 ]; then
      row=$(python3 "$HERE/colmap_exhaustive_timed.py" "$WORK/colmap.db" "$COLMAP_TIME_LIMIT" 2> "$log.colmap.log")
      echo "$row" >> "$log.colmap.log"
      # | label | wall | pairs | rate | ... | raw | verified | inliers |
      colmap_pairs=$(awk -F'|' '{ gsub(/[ ,]/, "", $4); print $4 }' <<< "$row")
      colmap_rate=$(awk -F'|' '{ gsub(/[ ,]/, "", $5); print $5 }' <<< "$row")
      colmap_verified=$(awk -F'|' '{ gsub(/[ ,]/, "", $13); print $13 }' <<< "$row")
    fi
    echo "$kind,$n,$mean,$pairs,$wall,$pipeline,$rate,$matching,$verification,$writing,$verified,$((rss_kib / 1024)),$gpu_peak,$colmap_pairs,$colmap_rate,$colmap_verified" >> "$CSV"
    tail -1 "$CSV"
    rm -f "$db"* "$WORK/colmap.db"*
  done
done

python3 "$HERE/plot_scale_curve.py" "$CSV" --png "$OUT/scale_curve.png" --table "$OUT/scale_curve.md"
