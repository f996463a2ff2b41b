#!/usr/bin/env bash
# Ga-CasHash against exhaustive matching on one feature database: the
# configurations of the GPU verification issue's benchmark, each on a fresh
# copy of the database and REPEATS times (every run is a new process, so each
# includes starting the GPU), then `colmap mapper` on each configuration's
# result:
#   ex   cashash exhaustive_matcher --FeatureMatching.use_gpu 1
#        (GPU cascade, GPU verification)
#   ga   cashash guided_matcher --FeatureMatching.use_gpu 1
#   fb   cashash guided_matcher --GuidedMatching.unguided_fallback 1 (not run
#        unless CONFIGS names it)
#
# Usage: guided_benchmark.sh CASHASH FEATURE_DB OUT_DIR [IMAGE_DIR]
# Environment (defaults in brackets):
#   REPEATS [2], CONFIGS ["ex ga"], LIMIT_S [1800]: per run,
#   MAPPER [1]: run colmap mapper (needs colmap on PATH; IMAGE_DIR may be an
#       empty folder for a generated database), MAPPER_THREADS [all cores],
#   MATCH [1]: 0 skips matching and maps the databases already in OUT_DIR
#       (match on a GPU machine without COLMAP with MAPPER=0, copy OUT_DIR,
#       map where COLMAP is).
# Writes to OUT_DIR: CONFIG_N.log (N = 1..REPEATS), CONFIG.db (the last run's
# database), CONFIG.model.json (scripts/summarize_model.py --json); then
# scripts/bench/guided_benchmark_table.py OUT_DIR prints the table.
set -u -o pipefail

CASHASH="$1"; FEATURE_DB="$2"; OUT_DIR="$3"; IMAGE_DIR="${4:-}"
REPEATS="${REPEATS:-2}"
CONFIGS="${CONFIGS:-ex ga}"
LIMIT_S="${LIMIT_S:-1800}"
MAPPER="${MAPPER:-1}"
MAPPER_THREADS="${MAPPER_THREADS:--1}"
MATCH="${MATCH:-1}"
HERE="$(cd "$(dirname "$0")" && pwd)"
mkdir -p "$OUT_DIR" || exit 1

if [[ "$MATCH" == 1 ]]; then
  [[ -f "$FEATURE_DB" ]] || { echo "ERROR: feature database $FEATURE_DB not found" >&2; exit 1; }
  for config in $CONFIGS; do
    case $config in
      ex)  command=(env "$CASHASH" exhaustive_matcher) ;;
      ga)  command=(env "$CASHASH" guided_matcher) ;;
      fb)  command=(env "$CASHASH" guided_matcher --GuidedMatching.unguided_fallback 1) ;;
      *)   echo "ERROR: unknown configuration '$config' in CONFIGS (ex, ga, fb)" >&2; exit 1 ;;
    esac
    for ((n = 1; n <= REPEATS; n++)); do
      cp "$FEATURE_DB" "$OUT_DIR/$config.db" || exit 1
      start=$(date +%s%N)
      timeout "$LIMIT_S" "${command[@]}" --database_path "$OUT_DIR/$config.db" \
        --FeatureMatching.use_gpu 1 > "$OUT_DIR/${config}_$n.log" 2>&1
      rc=$?
      echo "Wall: $(( ($(date +%s%N) - start) / 1000000 )) ms, exit $rc" >> "$OUT_DIR/${config}_$n.log"
      echo "$config run $n: exit $rc, $(grep -E '^Summary:' "$OUT_DIR/${config}_$n.log" | cut -c10-)"
    done
  done
fi

if [[ "$MAPPER" == 1 ]]; then
  command -v colmap > /dev/null || { echo "ERROR: colmap not on PATH (MAPPER=0 skips the mapper)" >&2; exit 1; }
  [[ -n "$IMAGE_DIR" ]] || { echo "ERROR: IMAGE_DIR is needed for colmap mapper" >&2; exit 1; }
  for config in $CONFIGS; do
    [[ -f "$OUT_DIR/$config.db" ]] || { echo "no $OUT_DIR/$config.db: skipped"; continue; }
    sparse="$OUT_DIR/$config.sparse"; rm -rf "$sparse"; mkdir -p "$sparse"
    QT_QPA_PLATFORM=offscreen colmap mapper --database_path "$OUT_DIR/$config.db" --image_path "$IMAGE_DIR" \
      --output_path "$sparse" --Mapper.num_threads "$MAPPER_THREADS" > "$OUT_DIR/$config.mapper.log" 2>&1 \
      || { echo "colmap mapper failed on $config; see $OUT_DIR/$config.mapper.log" >&2; continue; }
    python3 "$HERE/../summarize_model.py" "$sparse" --json > "$OUT_DIR/$config.model.json"
    echo "$config mapped: $(cat "$OUT_DIR/$config.model.json")"
  done
fi
python3 "$HERE/guided_benchmark_table.py" "$OUT_DIR"
