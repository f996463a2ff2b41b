#!/usr/bin/env bash
# Bad databases and pair lists through the command line: each ends in exit
# status 1 and one "ERROR: " line naming what is wrong and where, or, where
# COLMAP would go on, exit status 0 with a "WARNING: " line. Never a crash
# (status >= 128), a hang (60 s limit) or silence.
# Usage: reliability_bad_input.sh CASHASH_BINARY [SHARED_DATA_DIR]   (exit 77: skipped)
set -euo pipefail

CASHASH="$1"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
TOOL="$HERE/reliability_db_tool.py"

if ! python3 -c "import numpy" 2>/dev/null; then
  echo "SKIP: python3 numpy is not installed"; exit 77
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/cashash_reliability_bad_input.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT
python3 "$TOOL" make "$WORK/base.db" --images 4 --features 150
FAILURES=0

sql() { python3 -c "import sqlite3, sys; c = sqlite3.connect(sys.argv[1]); c.executescript(sys.argv[2]); c.commit()" "$@"; }

# run_case NAME EXPECTED_STATUS KIND TEXT COMMAND...: KIND is ERROR or WARNING;
# the output must hold a line starting with "KIND: " that contains TEXT.
run_case() {
  local name="$1" expected="$2" kind="$3" text="$4"; shift 4
  local rc=0
  timeout 60 "$@" >"$WORK/$name.log" 2>&1 || rc=$?
  local line
  line="$(grep -m1 "^$kind: .*$text" "$WORK/$name.log" || true)"
  if [[ $rc -eq $expected && -n "$line" ]]; then
    printf 'ok   %-24s %s\n' "$name" "$line"
  else
    printf 'FAIL %-24s exit status %s (expected %s), no "%s: ...%s" line:\n' "$name" "$rc" "$expected" "$kind" "$text"
    tail -5 "$WORK/$name.log"
    FAILURES=$((FAILURES + 1))
  fi
}

# fresh NAME [SQL]: a copy of the base database, changed by SQL.
fresh() {
  cp "$WORK/base.db" "$WORK/$1.db"
  if [[ $# -gt 1 ]]; then sql "$WORK/$1.db" "$2"; fi
  echo "$WORK/$1.db"
}

match() { echo "$CASHASH" exhaustive_matcher --SiftMatching.use_gpu 0 --database_path "$1"; }

printf 'just some text\n%.0s' $(seq 300) >"$WORK/text.db"
run_case not_sqlite 1 ERROR "not a SQLite database: $WORK/text.db" $(match "$WORK/text.db")

db="$(fresh truncated)"
python3 -c "import os, sys; os.truncate(sys.argv[1], os.path.getsize(sys.argv[1]) // 2)" "$db"
run_case truncated 1 ERROR "$db" $(match "$db")

db="$(fresh no_table "DROP TABLE two_view_geometries;")"
run_case missing_table 1 ERROR "has no table 'two_view_geometries'" $(match "$db")

db="$(fresh nan_keypoint)"
python3 - "$db" <<'PY'
import sqlite3, sys, numpy as np
con = sqlite3.connect(sys.argv[1])
rows, data = con.execute("SELECT rows, data FROM keypoints WHERE image_id = 3").fetchone()
kp = np.frombuffer(data, dtype=np.float32).reshape(rows, 6).copy()
kp[5, 0] = np.nan
con.execute("UPDATE keypoints SET data = ? WHERE image_id = 3", (kp.tobytes(),))
con.commit()
PY
run_case nan_keypoint 1 ERROR "keypoints of image 3 (image_003.png): row 5 holds a non-finite value" $(match "$db")

db="$(fresh outside_keypoints)"
python3 - "$db" <<'PY'
import sqlite3, sys, numpy as np
con = sqlite3.connect(sys.argv[1])
rows, data = con.execute("SELECT rows, data FROM keypoints WHERE image_id = 2").fetchone()
kp = np.frombuffer(data, dtype=np.float32).reshape(rows, 6).copy()
kp[:3, 0] += 5000
con.execute("UPDATE keypoints SET data = ? WHERE image_id = 2", (kp.tobytes(),))
con.commit()
PY
run_case outside_keypoints 0 WARNING "image 2 (image_002.png): 3 of 150 keypoints lie outside" $(match "$db")

db="$(fresh size_mismatch "UPDATE descriptors SET rows = 151 WHERE image_id = 4;")"
run_case size_mismatch 1 ERROR "descriptors of image 4 (image_004.png): blob size 19200 does not match rows x cols = 151 x 128" $(match "$db")

db="$(fresh float_descriptors)"
python3 - "$db" <<'PY'
import sqlite3, sys, numpy as np
con = sqlite3.connect(sys.argv[1])
con.execute("UPDATE descriptors SET data = ? WHERE image_id = 1", (np.zeros((150, 128), np.float32).tobytes(),))
con.commit()
PY
run_case float_descriptors 1 ERROR "descriptors of image 1 (image_001.png): blob size 76800" $(match "$db")

# COLMAP 4 layout with ALIKED features for one image.
db="$(fresh aliked "ALTER TABLE descriptors ADD COLUMN type INTEGER NOT NULL DEFAULT 0;
  UPDATE descriptors SET type = 1, cols = 512, rows = 37, data = zeroblob(37 * 512) WHERE image_id = 2;")"
run_case aliked 1 ERROR "descriptors of image 2 (image_002.png): descriptor type ALIKED_N16ROT (1) is not supported" $(match "$db")

db="$(fresh duplicate_names "CREATE TABLE images2 AS SELECT * FROM images; DROP TABLE images;
  ALTER TABLE images2 RENAME TO images; UPDATE images SET name = 'image_001.png' WHERE image_id = 4;")"
run_case duplicate_names 1 ERROR "table images: images 1 and 4 have the same name 'image_001.png'" $(match "$db")

db="$(fresh no_features "DELETE FROM keypoints WHERE image_id = 2; DELETE FROM descriptors WHERE image_id = 2;")"
run_case image_without_features 0 WARNING "image 2 (image_002.png) has 0 features" $(match "$db")
python3 "$TOOL" check "$db" --pairs 6 >/dev/null && [[ "$(python3 "$TOOL" count "$db")" == 6 ]] ||
  { echo "FAIL image_without_features: not every pair written"; FAILURES=$((FAILURES + 1)); }

db="$(fresh keypoints_only "DELETE FROM descriptors WHERE image_id = 3;")"
run_case keypoints_only 1 ERROR "image 3 (image_003.png): table keypoints has 150 rows but table descriptors has 0" $(match "$db")

db="$(fresh zero_images "DELETE FROM keypoints; DELETE FROM descriptors; DELETE FROM images;")"
run_case zero_images 0 WARNING "holds 0 images; nothing to match" $(match "$db")
db="$(fresh one_image "DELETE FROM images WHERE image_id > 1;")"
run_case one_image 0 WARNING "holds 1 image; nothing to match" $(match "$db")

db="$(fresh camera_params "UPDATE cameras SET params = zeroblob(8);")"
run_case camera_params 1 ERROR "table cameras: camera 1 (SIMPLE_RADIAL) has 1 params, the model has 4" $(match "$db")
db="$(fresh camera_model "UPDATE cameras SET model = 99;")"
run_case camera_model 0 WARNING "table cameras: camera 1 has model id 99, unknown to cashash" $(match "$db")

db="$(fresh pair_list)"
printf '# pairs\nimage_001.png image_002.png\n\nimage_001.png image_009.png\n' >"$WORK/unknown.txt"
run_case pair_list_unknown 1 ERROR "$WORK/unknown.txt:4: image 'image_009.png' is not in table images" \
  "$CASHASH" matches_importer --database_path "$db" --match_list_path "$WORK/unknown.txt" \
  --match_type pairs --SiftMatching.use_gpu 0
printf 'image_001.png image_002.png extra\n' >"$WORK/malformed.txt"
run_case pair_list_malformed 1 ERROR "$WORK/malformed.txt:1: expected 'name1 name2'" \
  "$CASHASH" matches_importer --database_path "$db" --match_list_path "$WORK/malformed.txt" \
  --match_type pairs --SiftMatching.use_gpu 0
python3 "$TOOL" check "$db" --pairs 0 >/dev/null ||
  { echo "FAIL pair lists: rows were written"; FAILURES=$((FAILURES + 1)); }

if [[ $FAILURES -gt 0 ]]; then echo "$FAILURES case(s) failed"; exit 1; fi
echo "PASS"
