#!/usr/bin/env bash
# Ga-CasHash end to end on real photographs: sceaux_castle (11 images,
# 2832x2128). COLMAP extracts SIFT on the CPU, `cashash guided_matcher`
# matches the top-scale features of every pair, estimates F, keeps the exact
# matches within the epipolar bands of the pairs that pass (and all exact
# matches of the weak pairs) and verifies them; every pair gets its rows (the
# skipped ones as pairs without matches); a rerun resumes with nothing to do;
# the paper's stage 2 verifies no more pairs; colmap mapper must register all
# 11 images.
# Usage: guided_sceaux_castle.sh CASHASH_BINARY SHARED_DATA_DIR   (exit 77: skipped)
# Environment: CASHASH_SCEAUX_DB (lib/sceaux_features.sh)
set -euo pipefail

CASHASH="$1"
SHARED_DATA="${2:-}"
WORK_PREFIX=cashash_guided_sceaux
# Skips or sets IMAGES, REPO, NUM_IMAGES, WORK and DB (the features).
source "$(dirname "${BASH_SOURCE[0]}")/lib/sceaux_features.sh"

# Options are refused by name.
if "$CASHASH" guided_matcher --database_path "$DB" --GuidedMatching.min_inlier_ratio 2 >"$WORK/bad.log" 2>&1; then
  echo "FAIL: a min_inlier_ratio of 2 was accepted"; exit 1
fi
grep -q "GuidedMatching.min_inlier_ratio" "$WORK/bad.log" || { cat "$WORK/bad.log"; exit 1; }

cp "$DB" "$WORK/paper.db"  # features only, for the paper's method below
"$CASHASH" guided_matcher --database_path "$DB" --FeatureMatching.use_gpu 0 | tee "$WORK/match.log"
grep -q "^Guided matching: 55 pairs, .* guided (.* exact matches within the epipolar band), .* without the band (" \
  "$WORK/match.log" || { echo "FAIL: no guided-matching report"; exit 1; }

# Every pair has its rows: guided pairs with matches, the others without.
python3 - "$DB" <<'PY'
import sqlite3, sys
c = sqlite3.connect(sys.argv[1])
geometries = c.execute("SELECT COUNT(*), SUM(rows > 0), SUM(config >= 2) FROM two_view_geometries").fetchone()
matches = c.execute("SELECT COUNT(*) FROM matches").fetchone()[0]
print(f"two_view_geometries: {geometries[0]} rows, {geometries[1]} with inliers, {geometries[2]} verified; matches: {matches} rows")
assert geometries[0] == 55 and matches == 55, "every pair needs a matches and a two_view_geometries row"
assert geometries[2] >= 40, "too few verified pairs"
PY

# A rerun finds every pair done.
"$CASHASH" guided_matcher --database_path "$DB" --FeatureMatching.use_gpu 0 | tee "$WORK/rerun.log"
grep -q "Nothing to match" "$WORK/rerun.log" || { echo "FAIL: the rerun matched again"; exit 1; }

# The paper's stage 2 (search within the band, no fallback) verifies no more
# pairs than the default.
"$CASHASH" guided_matcher --database_path "$WORK/paper.db" --FeatureMatching.use_gpu 0 \
  --GuidedMatching.restrict_search_to_band 1 --GuidedMatching.unguided_fallback 0 | tee "$WORK/paper.log"
grep -q "^Guided matching: 55 pairs, .* matched within the epipolar band (" "$WORK/paper.log" \
  || { echo "FAIL: no report of the paper's method"; exit 1; }
python3 - "$DB" "$WORK/paper.db" <<'PY'
import sqlite3, sys
default, paper = (sqlite3.connect(p).execute("SELECT SUM(config >= 2) FROM two_view_geometries").fetchone()[0]
                  for p in sys.argv[1:3])
print(f"verified pairs: {default} (default), {paper} (the paper's stage 2)")
assert default >= paper, "the default lost verified pairs against the paper's method"
PY

mkdir -p "$WORK/sparse"
start=$SECONDS
colmap mapper --database_path "$DB" --image_path "$IMAGES" --output_path "$WORK/sparse" \
  >"$WORK/mapper.log" 2>&1 || { tail -30 "$WORK/mapper.log"; exit 1; }
echo "Mapper: $((SECONDS - start)) s"

python3 "$REPO/scripts/summarize_model.py" "$WORK/sparse" --num_images "$NUM_IMAGES" \
  --expect_registered "$NUM_IMAGES" --max_reprojection_error 1.0
