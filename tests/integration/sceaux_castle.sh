#!/usr/bin/env bash
# End to end on real photographs: sceaux_castle (11 images, 2832x2128).
# COLMAP extracts SIFT on the CPU, cashash matches every pair, colmap mapper
# reconstructs; all 11 images must register with a mean reprojection error
# under 1 px.
# Usage: sceaux_castle.sh CASHASH_BINARY SHARED_DATA_DIR   (exit 77: skipped)
# Environment:
#   CASHASH_SCEAUX_DB  an existing COLMAP feature database of these images to
#                      copy instead of extracting (saves minutes when iterating)
set -euo pipefail

CASHASH="$1"
IMAGES="${2:-}/sceaux_castle/images"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
NUM_IMAGES=11
export QT_QPA_PLATFORM=offscreen

if [[ -z "${2:-}" || ! -d "$IMAGES" ]]; then
  echo "SKIP: no sceaux_castle images at '$IMAGES'"; exit 77
fi
if ! command -v colmap >/dev/null; then
  echo "SKIP: colmap is not installed"; exit 77
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/cashash_sceaux.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT
DB="$WORK/database.db"

if [[ -n "${CASHASH_SCEAUX_DB:-}" && -f "$CASHASH_SCEAUX_DB" ]]; then
  echo "Copying features from $CASHASH_SCEAUX_DB"
  python3 -c "import sqlite3,sys; s=sqlite3.connect(sys.argv[1]); d=sqlite3.connect(sys.argv[2]); s.backup(d)" \
    "$CASHASH_SCEAUX_DB" "$DB"
  python3 -c "import sqlite3,sys; c=sqlite3.connect(sys.argv[1]); c.execute('DELETE FROM matches'); c.execute('DELETE FROM two_view_geometries'); c.commit()" "$DB"
else
  start=$SECONDS
  colmap feature_extractor --database_path "$DB" --image_path "$IMAGES" \
    --ImageReader.single_camera 1 --SiftExtraction.use_gpu 0 \
    >"$WORK/extract.log" 2>&1 || { tail -30 "$WORK/extract.log"; exit 1; }
  echo "Feature extraction: $((SECONDS - start)) s"
fi

"$CASHASH" exhaustive_matcher --database_path "$DB" --CasHash.matcher cascade

mkdir -p "$WORK/sparse"
start=$SECONDS
colmap mapper --database_path "$DB" --image_path "$IMAGES" --output_path "$WORK/sparse" \
  >"$WORK/mapper.log" 2>&1 || { tail -30 "$WORK/mapper.log"; exit 1; }
echo "Mapper: $((SECONDS - start)) s"

python3 "$REPO/scripts/summarize_model.py" "$WORK/sparse" --num_images "$NUM_IMAGES" \
  --expect_registered "$NUM_IMAGES" --max_reprojection_error 1.0
