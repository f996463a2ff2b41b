#!/usr/bin/env bash
# End-to-end demo: render a synthetic scene, extract SIFT features with
# COLMAP, match them with cashash instead of `colmap exhaustive_matcher`,
# reconstruct with `colmap mapper`, and print what came out.
#
# Usage: scripts/demo.sh [WORK_DIR]        (default: demo_out/ in the repo)
# Environment:
#   CASHASH_BUILD_DIR   build folder (default: build/ in the repo)
#   CASHASH_MATCHER     auto (default: the cascade with the rule of the device
#                       the run matches on), cascade (the same) or bruteforce
#   CASHASH_SKIP_DEPS=1 do not call install_deps.sh
#   CASHASH_NUM_VIEWS   number of rendered views (default 10)
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WORK="${1:-$REPO/demo_out}"
BUILD="${CASHASH_BUILD_DIR:-$REPO/build}"
MATCHER="${CASHASH_MATCHER:-auto}"
NUM_VIEWS="${CASHASH_NUM_VIEWS:-10}"
JOBS="$(nproc)"
export QT_QPA_PLATFORM=offscreen

step() { printf '\n==> %s\n' "$*"; }
now() { date +%s.%N; }
seconds_since() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$1" "$(now)"; }

if [[ "${CASHASH_SKIP_DEPS:-0}" != 1 ]]; then
  step "Installing missing dependencies"
  "$REPO/scripts/install_deps.sh"
fi

# The CUDA backend only where a GPU can run it: without one nvcc would
# compile it for five architectures (minutes on a small machine) that the
# run cannot use. scripts/test.sh still builds and checks the CUDA code.
if command -v nvidia-smi >/dev/null && nvidia-smi -L 2>/dev/null | grep -q GPU; then
  CUDA=AUTO
else
  CUDA=OFF
fi
step "Building cashash (Release; CUDA backend: $CUDA, OFF where nvidia-smi lists no GPU) in $BUILD"
mkdir -p "$BUILD"
cmake -S "$REPO" -B "$BUILD" -DCMAKE_BUILD_TYPE=Release -DCASHASH_CUDA="$CUDA" >"$BUILD/configure.log" 2>&1 ||
  { cat "$BUILD/configure.log"; exit 1; }
cmake --build "$BUILD" -j"$JOBS" --target cashash
CASHASH="$BUILD/colmap_bridge/cashash"

step "Rendering $NUM_VIEWS views of a synthetic scene into $WORK/scene"
rm -rf "$WORK"
mkdir -p "$WORK"
python3 "$REPO/scripts/render_scene.py" "$WORK/scene" --num_views "$NUM_VIEWS"
read -r MODEL WIDTH HEIGHT FX FY CX CY <"$WORK/scene/intrinsics.txt"

DB="$WORK/database.db"
step "Extracting SIFT features with COLMAP (CPU, one $MODEL camera with the known intrinsics)"
start=$(now)
colmap feature_extractor --database_path "$DB" --image_path "$WORK/scene/images" \
  --ImageReader.single_camera 1 --ImageReader.camera_model "$MODEL" \
  --ImageReader.camera_params "$FX,$FY,$CX,$CY" \
  --SiftExtraction.use_gpu 0 >"$WORK/feature_extractor.log" 2>&1 ||
  { tail -20 "$WORK/feature_extractor.log"; exit 1; }
extract_seconds=$(seconds_since "$start")
echo "Feature extraction: $extract_seconds s (log: $WORK/feature_extractor.log)"

step "Matching every pair with cashash ($MATCHER)"
start=$(now)
"$CASHASH" exhaustive_matcher --database_path "$DB" --CasHash.matcher "$MATCHER" |
  tee "$WORK/cashash.log"
match_seconds=$(seconds_since "$start")

step "Reconstructing with colmap mapper"
mkdir -p "$WORK/sparse"
start=$(now)
colmap mapper --database_path "$DB" --image_path "$WORK/scene/images" --output_path "$WORK/sparse" \
  --Mapper.ba_refine_focal_length 0 --Mapper.ba_refine_principal_point 0 \
  --Mapper.ba_refine_extra_params 0 >"$WORK/mapper.log" 2>&1 ||
  { tail -20 "$WORK/mapper.log"; exit 1; }
mapper_seconds=$(seconds_since "$start")

step "Summary"
echo "Images:                    $WORK/scene/images ($WIDTH x $HEIGHT)"
python3 "$REPO/scripts/summarize_model.py" "$WORK/sparse" --num_images "$NUM_VIEWS" \
  --gt "$WORK/scene/gt"
echo "cashash:                   $(grep -m1 '^Summary:' "$WORK/cashash.log" | sed 's/^Summary: //')"
echo "Matching time (wall):      $match_seconds s"
echo "Extraction / mapper time:  $extract_seconds s / $mapper_seconds s"
