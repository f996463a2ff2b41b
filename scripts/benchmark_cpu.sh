#!/usr/bin/env bash
# CPU benchmark of cashash against `colmap exhaustive_matcher` on one data set.
#
# Features are extracted once; three copies of that database are matched by
# COLMAP's CPU matcher, cashash's cascade matcher and cashash's brute-force
# matcher, each copy is reconstructed by `colmap mapper`, and one table
# compares time, matches and reconstruction. It also reports which fraction
# of the brute-force (and COLMAP) verified inlier matches the cascade matcher
# verified too, pair by pair.
#
# Usage: scripts/benchmark_cpu.sh DATASET_IMAGES_DIR [WORK_DIR]
# Environment:
#   CASHASH_BINARY       cashash executable (default: build/colmap_bridge/cashash)
#   CASHASH_FEATURE_DB   an existing COLMAP feature database of these images
#                        to start from instead of extracting (it is copied,
#                        never written)
#   CASHASH_NUM_THREADS  threads for every matcher (default: all cores)
#   CASHASH_SKIP_MAPPER=1  skip the reconstructions
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
IMAGES="$(cd "${1:?usage: benchmark_cpu.sh DATASET_IMAGES_DIR [WORK_DIR]}" && pwd)"
NAME="$(basename "$(dirname "$IMAGES")")"
WORK="${2:-${TMPDIR:-/tmp}/cashash_bench_$NAME}"
CASHASH="${CASHASH_BINARY:-$REPO/build/colmap_bridge/cashash}"
THREADS="${CASHASH_NUM_THREADS:--1}"
export QT_QPA_PLATFORM=offscreen

now() { date +%s.%N; }
elapsed() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.2f}')" "$1" "$(now)"; }
# SQLite's backup API copies a database consistently, WAL included.
copy_db() {
  python3 -c "import sqlite3,sys; d=sqlite3.connect(sys.argv[2]); sqlite3.connect(sys.argv[1]).backup(d); d.close()" "$1" "$2"
}

[[ -x "$CASHASH" ]] || { echo "cashash not found at $CASHASH (set CASHASH_BINARY)"; exit 1; }
# What the table needs to be read correctly later: when, where, how loaded.
echo "Date: $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "Machine: $(lscpu | sed -n 's/^Model name: *//p' | head -1), $(nproc) cores; $(uptime | sed 's/.*load/load/')"
echo "COLMAP: $(colmap -h 2>/dev/null | head -1 | sed 's/ --.*//'); cashash: $CASHASH"
rm -rf "$WORK"
mkdir -p "$WORK"
BASE="$WORK/features.db"

if [[ -n "${CASHASH_FEATURE_DB:-}" ]]; then
  echo "Features: copying $CASHASH_FEATURE_DB"
  copy_db "$CASHASH_FEATURE_DB" "$BASE"
else
  echo "Features: extracting with colmap feature_extractor (CPU)"
  start=$(now)
  colmap feature_extractor --database_path "$BASE" --image_path "$IMAGES" \
    --ImageReader.single_camera 1 --SiftExtraction.use_gpu 0 >"$WORK/extract.log" 2>&1
  echo "Feature extraction: $(elapsed "$start") s"
fi
# Start every matcher from the same empty match tables.
python3 - "$BASE" <<'PY'
import sqlite3, sys
con = sqlite3.connect(sys.argv[1])
con.execute("DELETE FROM matches")
con.execute("DELETE FROM two_view_geometries")
con.commit()
PY

declare -A SECONDS_OF
run_matcher() {
  local method=$1; shift
  copy_db "$BASE" "$WORK/$method.db"
  echo "Matching: $method"
  local start; start=$(now)
  "$@" >"$WORK/$method.match.log" 2>&1 || { tail -20 "$WORK/$method.match.log"; exit 1; }
  SECONDS_OF[$method]=$(elapsed "$start")
  echo "  ${SECONDS_OF[$method]} s"
}
run_matcher colmap colmap exhaustive_matcher --database_path "$WORK/colmap.db" \
  --SiftMatching.use_gpu 0 --SiftMatching.num_threads "$THREADS"
run_matcher cascade "$CASHASH" exhaustive_matcher --database_path "$WORK/cascade.db" \
  --SiftMatching.use_gpu 0 --SiftMatching.num_threads "$THREADS" --CasHash.matcher cascade
run_matcher bruteforce "$CASHASH" exhaustive_matcher --database_path "$WORK/bruteforce.db" \
  --SiftMatching.use_gpu 0 --SiftMatching.num_threads "$THREADS" --CasHash.matcher bruteforce

for method in colmap cascade bruteforce; do
  echo "{}" >"$WORK/$method.model.json"
  if [[ "${CASHASH_SKIP_MAPPER:-0}" != 1 ]]; then
    echo "Mapper: $method"
    mkdir -p "$WORK/$method.sparse"
    start=$(now)
    colmap mapper --database_path "$WORK/$method.db" --image_path "$IMAGES" \
      --output_path "$WORK/$method.sparse" >"$WORK/$method.mapper.log" 2>&1 || true
    echo "  $(elapsed "$start") s"
    python3 "$REPO/scripts/summarize_model.py" "$WORK/$method.sparse" --json \
      | head -1 >"$WORK/$method.model.json" || true
  fi
done

echo "Finished: $(uptime | sed 's/.*load/load/')"
python3 - "$WORK" "$NAME" "${SECONDS_OF[colmap]}" "${SECONDS_OF[cascade]}" "${SECONDS_OF[bruteforce]}" <<'PY'
import json, sqlite3, sys

work, name = sys.argv[1], sys.argv[2]
seconds = dict(zip(["colmap", "cascade", "bruteforce"], map(float, sys.argv[3:6])))

def blob_pairs(data, rows):
    """Set of (idx1, idx2) from a uint32 N x 2 blob."""
    if not rows or data is None:
        return set()
    values = memoryview(data).cast("I")
    return {(values[2 * i], values[2 * i + 1]) for i in range(rows)}

def database_stats(path):
    con = sqlite3.connect(path)
    images = con.execute("SELECT COUNT(*) FROM images").fetchone()[0]
    raw = con.execute("SELECT COALESCE(SUM(rows), 0) FROM matches").fetchone()[0]
    verified = con.execute("SELECT COUNT(*) FROM two_view_geometries WHERE config >= 2").fetchone()[0]
    inliers = con.execute("SELECT COALESCE(SUM(rows), 0) FROM two_view_geometries").fetchone()[0]
    inlier_sets = {pid: blob_pairs(data, rows) for pid, rows, data in
                   con.execute("SELECT pair_id, rows, data FROM two_view_geometries WHERE config >= 2")}
    raw_sets = {pid: blob_pairs(data, rows) for pid, rows, data in
                con.execute("SELECT pair_id, rows, data FROM matches")}
    return dict(images=images, raw=raw, verified=verified, inliers=inliers,
                inlier_sets=inlier_sets, raw_sets=raw_sets)

def shared_fraction(reference, other):
    """Fraction of the reference's matches that `other` has too, pair by pair."""
    total = sum(len(s) for s in reference.values())
    shared = sum(len(s & other.get(pid, set())) for pid, s in reference.items())
    return shared / total if total else float("nan")

stats = {m: database_stats(f"{work}/{m}.db") for m in seconds}
models = {}
for m in seconds:
    try:
        models[m] = json.load(open(f"{work}/{m}.model.json"))
    except (OSError, ValueError):
        models[m] = {}
num_images = stats["colmap"]["images"]
num_pairs = num_images * (num_images - 1) // 2

def fmt(value, spec):
    return "-" if value is None else format(value, spec)

labels = {"colmap": "colmap exhaustive_matcher (CPU)",
          "cascade": "cashash --CasHash.matcher cascade",
          "bruteforce": "cashash --CasHash.matcher bruteforce"}
print()
print(f"### {name}: {num_images} images, {num_pairs} pairs")
print()
print("| matcher | matching s | pairs/s | raw matches | verified pairs | inlier matches "
      "| registered | points | mean track length | mean reproj. error px |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for m in seconds:
    s, mo = stats[m], models[m]
    print(f"| {labels[m]} | {seconds[m]:.1f} | {num_pairs / seconds[m]:.2f} | {s['raw']} "
          f"| {s['verified']} | {s['inliers']} | {fmt(mo.get('registered'), 'd')}/{num_images} "
          f"| {fmt(mo.get('points'), 'd')} | {fmt(mo.get('mean_track_length'), '.2f')} "
          f"| {fmt(mo.get('mean_reprojection_error'), '.3f')} |")
print()
print(f"- colmap / cascade matching time: {seconds['colmap'] / seconds['cascade']:.2f}x; "
      f"bruteforce / cascade: {seconds['bruteforce'] / seconds['cascade']:.2f}x")
print(f"- brute-force verified inlier matches also verified by the cascade matcher: "
      f"{100 * shared_fraction(stats['bruteforce']['inlier_sets'], stats['cascade']['inlier_sets']):.1f} %")
print(f"- brute-force raw matches also found by the cascade matcher: "
      f"{100 * shared_fraction(stats['bruteforce']['raw_sets'], stats['cascade']['raw_sets']):.1f} %")
print(f"- COLMAP verified inlier matches also verified by cashash bruteforce / cascade: "
      f"{100 * shared_fraction(stats['colmap']['inlier_sets'], stats['bruteforce']['inlier_sets']):.1f} % / "
      f"{100 * shared_fraction(stats['colmap']['inlier_sets'], stats['cascade']['inlier_sets']):.1f} %")
PY
