#!/usr/bin/env bash
# `cashash geometric_verifier` on stored raw matches must write exactly the
# two_view_geometries that matching with verification writes (same seeds,
# same decision code), skip verified pairs on a second run and redo them with
# --overwrite 1. Synthetic features (12 images, 66 pairs), CPU verification.
# Usage: geometric_verifier.sh CASHASH_BINARY [SHARED_DATA_DIR]   (exit 77: skipped)
set -euo pipefail

CASHASH="$1"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
TOOL="$HERE/reliability_db_tool.py"

if ! python3 -c "import numpy" 2>/dev/null; then
  echo "SKIP: python3 numpy is not installed"; exit 77
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/cashash_geometric_verifier.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT

python3 "$TOOL" make "$WORK/raw.db" --images 12 --features 400 --journal delete
cp "$WORK/raw.db" "$WORK/reference.db"

# Reference: matching and verification in one run.
"$CASHASH" exhaustive_matcher --database_path "$WORK/reference.db" --FeatureMatching.use_gpu 0 --CasHash.matcher cascade \
  --random_seed 3 >"$WORK/reference.log" 2>&1
# Raw matches only, then verification of the stored matches.
"$CASHASH" exhaustive_matcher --database_path "$WORK/raw.db" --FeatureMatching.use_gpu 0 --CasHash.matcher cascade \
  --FeatureMatching.skip_geometric_verification 1 --random_seed 3 >"$WORK/raw.log" 2>&1
geometry_rows() {
  python3 -c "import sqlite3,sys; print(sqlite3.connect(sys.argv[1]).execute('SELECT COUNT(*) FROM two_view_geometries').fetchone()[0])" "$1"
}
rows=$(geometry_rows "$WORK/raw.db")
[[ "$rows" == 0 ]] || { echo "FAIL: raw matching wrote $rows two_view_geometries rows"; exit 1; }

"$CASHASH" geometric_verifier --database_path "$WORK/raw.db" --FeatureMatching.use_gpu 0 \
  --random_seed 3 >"$WORK/verify.log" 2>&1 || { cat "$WORK/verify.log"; echo "FAIL: geometric_verifier"; exit 1; }
rows=$(geometry_rows "$WORK/raw.db")
[[ "$rows" == 66 ]] || { cat "$WORK/verify.log"; echo "FAIL: expected 66 pairs verified, got $rows rows"; exit 1; }
python3 "$TOOL" compare "$WORK/raw.db" "$WORK/reference.db"

# A second run has nothing left to do; --overwrite 1 verifies everything again.
"$CASHASH" geometric_verifier --database_path "$WORK/raw.db" --FeatureMatching.use_gpu 0 >"$WORK/again.log" 2>&1
grep -q "Nothing to verify" "$WORK/again.log" || { cat "$WORK/again.log"; echo "FAIL: second run verified again"; exit 1; }
"$CASHASH" geometric_verifier --database_path "$WORK/raw.db" --FeatureMatching.use_gpu 0 --overwrite 1 \
  --random_seed 3 >"$WORK/overwrite.log" 2>&1
python3 "$TOOL" compare "$WORK/raw.db" "$WORK/reference.db"

# A database without matches has nothing to verify.
python3 "$TOOL" make "$WORK/empty.db" --images 3 --features 50 --journal delete
"$CASHASH" geometric_verifier --database_path "$WORK/empty.db" >"$WORK/empty.log" 2>&1 ||
  { cat "$WORK/empty.log"; echo "FAIL: empty database"; exit 1; }
grep -q "Nothing to verify" "$WORK/empty.log" || { cat "$WORK/empty.log"; echo "FAIL: empty database"; exit 1; }
echo "PASS: geometric_verifier writes the same geometries as matching with verification, resumes, overwrites"
