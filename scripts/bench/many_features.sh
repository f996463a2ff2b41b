#!/usr/bin/env bash
# Many features an image: cashash at and above COLMAP's cap of 32,768
# matches (FeatureMatching.max_num_matches, which also caps the features
# read), beside its exact brute force at the raised cap and COLMAP's own
# exhaustive matcher (pycolmap, GPU where it has CUDA) at its default and at
# the raised cap, each on its own copy of one generated street, in one run.
#
# Usage: many_features.sh CASHASH SOURCE_DB OUT_DIR
# Environment (defaults in brackets):
#   NUM_IMAGES [50], NUM_FEATURES [40000]: the street
#   RAISED_CAP [40960]: the cap above COLMAP's default
#   COLMAP_TIME_LIMIT [60]: seconds for each COLMAP run (0: not run)
#   WORK [/tmp/cashash_many_features]
# Prints a Markdown table: wall time, pairs, verified pairs and inlier
# matches of each run, and for cashash the share of brute force's verified
# pairs and inlier matches (at the raised cap) that it has.
set -u -o pipefail

CASHASH="$1"; SOURCE_DB="$2"; OUT="$3"
NUM_IMAGES="${NUM_IMAGES:-50}"
NUM_FEATURES="${NUM_FEATURES:-40000}"
RAISED_CAP="${RAISED_CAP:-40960}"
COLMAP_TIME_LIMIT="${COLMAP_TIME_LIMIT:-60}"
WORK="${WORK:-/tmp/cashash_many_features}"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
mkdir -p "$OUT" "$WORK"
DB="$WORK/street.db"
rm -f "$DB"*
"$CASHASH" generate_database --database_path "$DB" --source_database_path "$SOURCE_DB" \
  --num_images "$NUM_IMAGES" --num_features "$NUM_FEATURES" > "$OUT/generate.log" 2>&1 ||
  { echo "generate_database failed:"; tail -3 "$OUT/generate.log"; exit 1; }

# name|options; every run on a fresh copy.
RUNS=(
  "default_32768|--FeatureMatching.max_num_matches 32768"
  "default_$RAISED_CAP|--FeatureMatching.max_num_matches $RAISED_CAP"
  "bruteforce_$RAISED_CAP|--FeatureMatching.max_num_matches $RAISED_CAP --CasHash.matcher bruteforce"
  "default_1000000|--FeatureMatching.max_num_matches 1000000"
)
TABLE="$OUT/table.md"
{
  echo "# many_features.sh $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(nproc) cores; $NUM_IMAGES x $NUM_FEATURES features; $("$CASHASH" --version 2>&1 | head -1)"
  command -v nvidia-smi > /dev/null 2>&1 && echo "# $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | head -1)"
} > "$TABLE"
for run in "${RUNS[@]}"; do
  name="${run%%|*}"; options="${run#*|}"
  cp "$DB" "$WORK/$name.db"
  start=$(date +%s.%N)
  # shellcheck disable=SC2086
  "$CASHASH" exhaustive_matcher --database_path "$WORK/$name.db" $options > "$OUT/$name.log" 2>&1
  rc=$?
  end=$(date +%s.%N)
  echo "$name $rc $(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.2f", b - a }')" >> "$OUT/runs.txt"
  grep -E "^(ERROR|WARNING|Summary)" "$OUT/$name.log" | head -3
done
if [ "$COLMAP_TIME_LIMIT" != 0 ]; then
  for cap in 32768 "$RAISED_CAP"; do
    name="colmap_$cap"
    cp "$DB" "$WORK/$name.db"
    start=$(date +%s.%N)
    python3 "$HERE/colmap_exhaustive_timed.py" "$WORK/$name.db" "$COLMAP_TIME_LIMIT" "$cap" > "$OUT/$name.log" 2>&1
    rc=$?
    end=$(date +%s.%N)
    echo "$name $rc $(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.2f", b - a }')" >> "$OUT/runs.txt"
  done
fi

python3 - "$WORK" "$OUT/runs.txt" "bruteforce_$RAISED_CAP" >> "$TABLE" <<'PY'
import os, sqlite3, sys
work, runs_path, reference = sys.argv[1], sys.argv[2], sys.argv[3]
def rows(name):
    db = sqlite3.connect(os.path.join(work, name + ".db"))
    tvg = {p: n for p, n in db.execute("SELECT pair_id, rows FROM two_view_geometries WHERE config >= 2")}
    pairs = db.execute("SELECT COUNT(*) FROM two_view_geometries").fetchone()[0]
    return pairs, tvg
ref_pairs, ref = rows(reference)
print()
print("| run | exit | wall s | pairs | verified pairs | inlier matches | of brute force's verified pairs | of its inlier matches (same pairs) |")
print("|---|---:|---:|---:|---:|---:|---:|---:|")
for line in open(runs_path):
    name, rc, wall = line.split()
    try:
        pairs, tvg = rows(name)
    except sqlite3.Error as error:
        print("| %s | %s | %s | | | | (%s) | |" % (name, rc, wall, error)); continue
    inliers = sum(tvg.values())
    common = [p for p in ref if p in tvg]
    # Over the pairs the run reached: COLMAP's timed runs stop early.
    reached = {p for (p,) in sqlite3.connect(os.path.join(work, name + ".db")).execute("SELECT pair_id FROM two_view_geometries")}
    ref_reached = [p for p in ref if p in reached]
    share = "%.1f %%" % (100.0 * len(common) / len(ref_reached)) if ref_reached else ""
    ref_inliers = sum(ref[p] for p in common)
    inlier_share = "%.1f %%" % (100.0 * sum(tvg[p] for p in common) / ref_inliers) if ref_inliers else ""
    print("| %s | %s | %s | {:,} | {:,} | {:,} | %s | %s |".format(pairs, len(tvg), inliers) % (name, rc, wall, share, inlier_share))
PY
cat "$TABLE"
