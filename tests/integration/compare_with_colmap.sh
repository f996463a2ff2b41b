#!/usr/bin/env bash
# scripts/compare_with_colmap.py end to end on sceaux_castle (11 images) with
# pycolmap's CPU matcher and mapper: the database is left as it was, the JSON
# report has every field, agreements lie in [0, 1], both times are positive
# and both databases register the same number of images. A second run with
# --colmap_time_limit stops COLMAP's matcher early and must still report,
# over the pairs COLMAP committed.
# Features are extracted at 1024 px (about 3k per image) so that COLMAP's
# CPU matcher and two reconstructions fit in a few minutes on 2 cores.
# Usage: compare_with_colmap.sh CASHASH_BINARY SHARED_DATA_DIR   (exit 77: skipped)
set -euo pipefail

CASHASH="$1"
SHARED_DATA="${2:-}"
WORK_PREFIX=cashash_compare
SCEAUX_EXTRACTION_OPTIONS=(--SiftExtraction.max_image_size 1024 --SiftExtraction.max_num_features 2048)
if ! python3 -c "import pycolmap, numpy" 2>/dev/null; then
  echo "SKIP: python3 cannot import pycolmap and numpy (scripts/install_deps.sh installs them)"; exit 77
fi
# Skips or sets IMAGES, REPO, NUM_IMAGES, WORK and DB (the features).
source "$(dirname "${BASH_SOURCE[0]}")/lib/sceaux_features.sh"

before="$(sha256sum "$DB" | cut -d' ' -f1)"
start=$SECONDS
rc=0
python3 "$REPO/scripts/compare_with_colmap.py" --database_path "$DB" --output_dir "$WORK/compare" \
  --use_gpu 0 --colmap pycolmap --mapper 1 --image_path "$IMAGES" --cashash "$CASHASH" --num_threads 2 || rc=$?
echo "Comparison: $((SECONDS - start)) s, exit code $rc"
[[ -f "$WORK/compare/comparison.json" ]] || { echo "FAIL: no comparison.json"; exit 1; }
[[ "$(sha256sum "$DB" | cut -d' ' -f1)" == "$before" ]] || { echo "FAIL: the input database changed"; exit 1; }

python3 - "$WORK/compare" "$NUM_IMAGES" <<'EOF'
import json, os, sys

out, num_images = sys.argv[1], int(sys.argv[2])
report = json.load(open(os.path.join(out, "comparison.json")))
failures = []


def get(*path):
    value = report
    for key in path:
        if not isinstance(value, dict) or key not in value:
            failures.append("missing " + ".".join(path))
            return None
        value = value[key]
    return value


for side in ("colmap", "cashash"):
    for key in ("label", "version", "gpu_requested", "gpu_used", "command"):
        get("matchers", side, key)
    if get("matchers", side, "gpu_used") is not False:
        failures.append("%s: gpu_used should be false with --use_gpu 0" % side)
    for key in ("wall_s", "pairs_per_s"):
        value = get("time", side, key)
        if value is not None and not value > 0:
            failures.append("time.%s.%s = %r is not positive" % (side, key, value))
    for key in ("raw_matches", "pairs_with_raw_matches", "verified_pairs", "inlier_matches", "pairs_per_config"):
        get("counts", side, key)
    if (get("counts", side, "verified_pairs") or 0) <= 0:
        failures.append("%s verified no pair" % side)
    for key in ("registered_images", "points3D", "mean_track_length", "mean_reprojection_error"):
        get("reconstruction", side, key)
if "pycolmap" not in (get("matchers", "colmap", "label") or ""):
    failures.append("the COLMAP label does not say pycolmap")
if not (get("time", "speedup") or 0) > 0:
    failures.append("no positive speed-up")
for key in ("colmap_verified_also_by_cashash", "cashash_verified_also_by_colmap",
            "colmap_inlier_matches_also_in_cashash"):
    value = get("agreement", key)
    if value is None or not 0 <= value <= 1:
        failures.append("agreement.%s = %r is not in [0, 1]" % (key, value))
if not (get("agreement", "cashash_over_colmap_inliers") or 0) > 0:
    failures.append("no inlier ratio")
if get("dataset", "num_pairs") != num_images * (num_images - 1) // 2:
    failures.append("dataset.num_pairs is not N(N-1)/2")
registered = [get("reconstruction", side, "registered_images") for side in ("colmap", "cashash")]
if registered[0] != registered[1] or not registered[0]:
    failures.append("registered images differ or are zero: COLMAP %r, cashash %r" % tuple(registered))
if get("exit_code") != 0:
    failures.append("exit_code %r" % get("exit_code"))
try:
    import matplotlib  # noqa: F401
    expected = ("comparison.md", "comparison.png")
except ImportError:
    expected = ("comparison.md",)
for name in expected:
    if not os.path.isfile(os.path.join(out, name)):
        failures.append("no " + name)
print(open(os.path.join(out, "comparison.md")).read().split("\n\nCommands:")[0])
if failures:
    print("FAIL:\n  " + "\n  ".join(failures))
    sys.exit(1)
print("OK: registered %d = %d of %d images" % (registered[0], registered[1], num_images))
EOF

# COLMAP stopped after 1 s (its import alone takes about that): still a
# report, COLMAP marked stopped, its rate over the pairs it committed, no
# mapper, exit code 0.
rc=0
python3 "$REPO/scripts/compare_with_colmap.py" --database_path "$DB" --output_dir "$WORK/compare_stopped" \
  --use_gpu 0 --colmap pycolmap --cashash "$CASHASH" --num_threads 2 --colmap_time_limit 1 || rc=$?
[[ $rc == 0 ]] || { echo "FAIL: the time-limited comparison exited with $rc"; exit 1; }
python3 - "$WORK/compare_stopped" "$NUM_IMAGES" <<'EOF'
import json, os, sys

report = json.load(open(os.path.join(sys.argv[1], "comparison.json")))
num_pairs = int(sys.argv[2]) * (int(sys.argv[2]) - 1) // 2
t = report["time"]
failures = []
if not t["colmap"]["stopped"] or t["cashash"]["stopped"]:
    failures.append("COLMAP should be marked stopped and cashash not: %r" % t)
if not 0 <= t["colmap"]["pairs_done"] < num_pairs or t["cashash"]["pairs_done"] != num_pairs:
    failures.append("pairs done: COLMAP %r, cashash %r of %d" % (t["colmap"]["pairs_done"], t["cashash"]["pairs_done"],
                                                                num_pairs))
if report["dataset"].get("pairs_compared", -1) < t["colmap"]["pairs_done"]:
    failures.append("pairs_compared %r" % report["dataset"].get("pairs_compared"))
if report["counts"]["cashash"]["pairs_written"] > report["dataset"]["pairs_compared"]:
    failures.append("cashash's counts are not restricted to the pairs COLMAP reached")
if "skipped" not in report["reconstruction"]:
    failures.append("the mapper should be skipped")
if "stopped" not in open(os.path.join(sys.argv[1], "comparison.md")).read():
    failures.append("comparison.md does not say COLMAP was stopped")
if failures:
    print("FAIL:\n  " + "\n  ".join(failures))
    sys.exit(1)
print("OK: COLMAP stopped with %d of %d pairs committed" % (t["colmap"]["pairs_done"], num_pairs))
EOF
