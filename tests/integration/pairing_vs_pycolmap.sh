#!/usr/bin/env bash
# `cashash sequential_matcher` and `spatial_matcher` must match the same
# pairs as pycolmap's match_sequential and match_spatial (COLMAP 4.x, CPU)
# with the same options, on a generated street with GPS and Cartesian
# priors, from both the COLMAP 3.8 and the 4.x places of the priors
# (scripts/eval/compare_pairing_with_pycolmap.py; 24 images of 128 features
# keep pycolmap's CPU matching to seconds).
# Usage: pairing_vs_pycolmap.sh CASHASH_BINARY [SHARED_DATA_DIR]   (exit 77: skipped)
set -euo pipefail

CASHASH="$1"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
SCRIPT="$HERE/../../scripts/eval/compare_pairing_with_pycolmap.py"

if ! python3 -c "import numpy, pycolmap" 2>/dev/null; then
  echo "SKIP: python3 numpy or pycolmap is not installed"; exit 77
fi
python3 "$SCRIPT" --cashash "$CASHASH" --num_images 24 --num_features 128
