#!/usr/bin/env bash
# End to end on the rendered scene: render, extract (COLMAP, CPU), match with
# cashash, reconstruct with colmap mapper, then require every view registered,
# sub-pixel reprojection error and camera rotations within 1 degree of the
# ground truth the renderer wrote.
# Usage: demo_scene.sh CASHASH_BINARY [SHARED_DATA_DIR]   (exit 77: skipped)
set -euo pipefail

CASHASH="$1"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
NUM_VIEWS=10
export QT_QPA_PLATFORM=offscreen

if ! command -v colmap >/dev/null; then
  echo "SKIP: colmap is not installed"; exit 77
fi
if ! python3 -c "import numpy, PIL" 2>/dev/null; then
  echo "SKIP: python3 numpy/Pillow are not installed"; exit 77
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/cashash_demo_scene.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT
DB="$WORK/database.db"

python3 "$REPO/scripts/render_scene.py" "$WORK/scene" --num_views "$NUM_VIEWS"
read -r MODEL _ _ FX FY CX CY <"$WORK/scene/intrinsics.txt"

colmap feature_extractor --database_path "$DB" --image_path "$WORK/scene/images" \
  --ImageReader.single_camera 1 --ImageReader.camera_model "$MODEL" \
  --ImageReader.camera_params "$FX,$FY,$CX,$CY" \
  --SiftExtraction.use_gpu 0 >"$WORK/extract.log" 2>&1 || { tail -30 "$WORK/extract.log"; exit 1; }

"$CASHASH" exhaustive_matcher --database_path "$DB"

# Every pair must have been attempted and written, as COLMAP does.
python3 - "$DB" "$NUM_VIEWS" <<'PY'
import sqlite3, sys
db, n = sys.argv[1], int(sys.argv[2])
con = sqlite3.connect(db)
pairs = n * (n - 1) // 2
matches = con.execute("SELECT COUNT(*) FROM matches").fetchone()[0]
geometries = con.execute("SELECT COUNT(*) FROM two_view_geometries").fetchone()[0]
verified = con.execute("SELECT COUNT(*) FROM two_view_geometries WHERE config >= 2").fetchone()[0]
print(f"matches rows {matches}, two_view_geometries rows {geometries}, verified pairs {verified}")
assert matches == pairs and geometries == pairs, f"expected {pairs} rows in both tables"
assert verified >= n - 1, "too few verified pairs to chain every view"
PY

mkdir -p "$WORK/sparse"
colmap mapper --database_path "$DB" --image_path "$WORK/scene/images" --output_path "$WORK/sparse" \
  --Mapper.ba_refine_focal_length 0 --Mapper.ba_refine_principal_point 0 \
  --Mapper.ba_refine_extra_params 0 >"$WORK/mapper.log" 2>&1 || { tail -30 "$WORK/mapper.log"; exit 1; }

python3 "$REPO/scripts/summarize_model.py" "$WORK/sparse" --num_images "$NUM_VIEWS" \
  --gt "$WORK/scene/gt" --expect_registered "$NUM_VIEWS" --max_reprojection_error 1.0 \
  --max_rotation_error_deg 1.0
