#!/usr/bin/env bash
# End to end on real photographs: sceaux_castle (11 images, 2832x2128).
# COLMAP extracts SIFT on the CPU, cashash matches every pair, colmap mapper
# reconstructs; all 11 images must register with a mean reprojection error
# under 1 px.
# Usage: sceaux_castle.sh CASHASH_BINARY SHARED_DATA_DIR   (exit 77: skipped)
# Environment: CASHASH_SCEAUX_DB (lib/sceaux_features.sh)
set -euo pipefail

CASHASH="$1"
SHARED_DATA="${2:-}"
WORK_PREFIX=cashash_sceaux
# Skips or sets IMAGES, REPO, NUM_IMAGES, WORK and DB (the features).
source "$(dirname "${BASH_SOURCE[0]}")/lib/sceaux_features.sh"

"$CASHASH" exhaustive_matcher --database_path "$DB" --CasHash.matcher cascade

mkdir -p "$WORK/sparse"
start=$SECONDS
colmap mapper --database_path "$DB" --image_path "$IMAGES" --output_path "$WORK/sparse" \
  >"$WORK/mapper.log" 2>&1 || { tail -30 "$WORK/mapper.log"; exit 1; }
echo "Mapper: $((SECONDS - start)) s"

python3 "$REPO/scripts/summarize_model.py" "$WORK/sparse" --num_images "$NUM_IMAGES" \
  --expect_registered "$NUM_IMAGES" --max_reprojection_error 1.0
