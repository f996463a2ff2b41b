# Sourced by the sceaux_castle end-to-end tests: skips (exit 77) without the
# photographs or COLMAP, then leaves a COLMAP feature database of the 11
# images in $DB inside a fresh $WORK (removed on exit). Expects CASHASH and
# SHARED_DATA set and WORK_PREFIX naming the temporary folder.
# Optional, set before sourcing:
#   SCEAUX_EXTRACTION_OPTIONS  array of extra feature_extractor options (a
#                      quicker test with fewer, smaller features); a test that
#                      sets it always extracts, CASHASH_SCEAUX_DB is not used
# Environment:
#   CASHASH_SCEAUX_DB  an existing COLMAP feature database of these images to
#                      copy instead of extracting (saves minutes when iterating)
IMAGES="${SHARED_DATA:-}/sceaux_castle/images"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)"
NUM_IMAGES=11
export QT_QPA_PLATFORM=offscreen

if [[ -z "${SHARED_DATA:-}" || ! -d "$IMAGES" ]]; then
  echo "SKIP: no sceaux_castle images at '$IMAGES'"; exit 77
fi
if ! command -v colmap >/dev/null; then
  echo "SKIP: colmap is not installed"; exit 77
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/${WORK_PREFIX}.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT
DB="$WORK/database.db"

if [[ -z "${SCEAUX_EXTRACTION_OPTIONS+set}" && -n "${CASHASH_SCEAUX_DB:-}" && -f "$CASHASH_SCEAUX_DB" ]]; then
  echo "Copying features from $CASHASH_SCEAUX_DB"
  python3 -c "import sqlite3,sys; s=sqlite3.connect(sys.argv[1]); d=sqlite3.connect(sys.argv[2]); s.backup(d)" \
    "$CASHASH_SCEAUX_DB" "$DB"
  python3 -c "import sqlite3,sys; c=sqlite3.connect(sys.argv[1]); c.execute('DELETE FROM matches'); c.execute('DELETE FROM two_view_geometries'); c.commit()" "$DB"
else
  start=$SECONDS
  colmap feature_extractor --database_path "$DB" --image_path "$IMAGES" \
    --ImageReader.single_camera 1 --SiftExtraction.use_gpu 0 \
    ${SCEAUX_EXTRACTION_OPTIONS[@]+"${SCEAUX_EXTRACTION_OPTIONS[@]}"} \
    >"$WORK/extract.log" 2>&1 || { tail -30 "$WORK/extract.log"; exit 1; }
  echo "Feature extraction: $((SECONDS - start)) s"
fi
