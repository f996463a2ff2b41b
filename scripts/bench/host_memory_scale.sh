#!/usr/bin/env bash
# Peak resident memory of `cashash exhaustive_matcher` against the number of
# images, as a new user meets it: a street of few features an image, each
# run stopped with SIGINT after RUN_S seconds (committed chunks stay), its
# peak resident memory read by `/usr/bin/time -v`. With MPI_RANKS > 1 the
# same run under `mpirun -np MPI_RANKS --oversubscribe`, each rank under its
# own /usr/bin/time and stopped by its own SIGINT (the peak of the largest
# rank is reported). Also the seconds from the start to the first
# committed chunk ("Matching block" line), which includes planning the
# pairs.
#
# Usage: host_memory_scale.sh SOURCE_DB CASHASH [CASHASH...]
#   SOURCE_DB: a COLMAP database with features to draw from, e.g.
#     colmap feature_extractor --database_path source.db --image_path IMAGES \
#       --SiftExtraction.use_gpu 0
#   CASHASH: one or more builds to compare (before and after), each run on
#     the same databases; the first one generates them.
# Environment (defaults in brackets):
#   SIZES ["5000 20000"]: images of each street, NUM_FEATURES [8],
#   RUN_S [25]: seconds before SIGINT, MPI_RANKS [2] (1: no MPI runs),
#   USE_GPU [0], OPTIONS []: more exhaustive_matcher options (for example
#   "--max_host_memory 256M"), WORK [/tmp/cashash_host_memory]: the
#   databases (kept, reused when present), OUT [WORK/logs]: one log and one
#   time file per run.
# Prints a table: build, images, processes, peak RSS (MiB, the largest
# process), seconds to the first committed chunk, pairs committed; writes
# the same rows to OUT/host_memory.csv, and from them
# (scripts/bench/plot_host_memory.py) the Markdown table OUT/host_memory.md
# and its plot OUT/host_memory.png (peak resident memory against images).
set -u -o pipefail

SOURCE_DB="$1"; shift
BUILDS=("$@")
SIZES="${SIZES:-5000 20000}"
NUM_FEATURES="${NUM_FEATURES:-8}"
RUN_S="${RUN_S:-25}"
MPI_RANKS="${MPI_RANKS:-2}"
USE_GPU="${USE_GPU:-0}"
read -r -a OPTIONS <<< "${OPTIONS:-}"
WORK="${WORK:-/tmp/cashash_host_memory}"
OUT="${OUT:-$WORK/logs}"
mkdir -p "$WORK" "$OUT"
[ -x /usr/bin/time ] || { echo "needs GNU time at /usr/bin/time (apt-get install time)"; exit 1; }
if [ "$MPI_RANKS" -gt 1 ]; then
  command -v mpirun > /dev/null || { echo "mpirun not found: MPI_RANKS=1 or apt-get install openmpi-bin"; exit 1; }
  # Open MPI refuses to run as root unless told that it is meant; one
  # machine: no network probing.
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl=self,vader
fi

# Prefixes each line of stdin with the seconds since $1 (an EPOCHREALTIME),
# without a process a line.
stamp() {
  local t0="${1/./}" line us
  while IFS= read -r line; do
    us=$((${EPOCHREALTIME/./} - t0))
    printf '%d.%03d %s\n' $((us / 1000000)) $((us % 1000000 / 1000)) "$line"
  done
}

# run_one LABEL BINARY DB RANKS: one stopped run on a fresh copy of DB.
run_one() {
  local label="$1" binary="$2" db="$3" ranks="$4"
  local tag="${label}_$(basename "$db" .db)_np${ranks}"
  local copy="$WORK/run.db"
  rm -f "$copy" "$copy-wal" "$copy-shm"
  cp "$db" "$copy"
  rm -f "$OUT/$tag".time*
  local args=(exhaustive_matcher --database_path "$copy" --FeatureMatching.use_gpu "$USE_GPU" "${OPTIONS[@]}")
  local t0="$EPOCHREALTIME"
  if [ "$ranks" -gt 1 ]; then
    # Each rank: its own timer, its own SIGINT (mpirun itself would end
    # the job on SIGINT instead of letting the ranks commit and report).
    mpirun -np "$ranks" --oversubscribe --bind-to none bash -c \
      'exec timeout -s INT "$1" /usr/bin/time -v -o "$2.rank$OMPI_COMM_WORLD_RANK" "${@:3}"' \
      rank "$RUN_S" "$OUT/$tag.time" "$binary" "${args[@]}" --FeatureMatching.num_threads 1 2>&1 |
      stamp "$t0" > "$OUT/$tag.log"
  else
    timeout -s INT "$RUN_S" /usr/bin/time -v -o "$OUT/$tag.time" "$binary" "${args[@]}" 2>&1 |
      stamp "$t0" > "$OUT/$tag.log"
  fi
  local peak_kib first pairs
  # The largest of /usr/bin/time's peaks and of the run's own "Memory: peak
  # resident" line (rank 0's under MPI): mpirun may end a rank's timer
  # before it writes its file once another rank has finished.
  peak_kib=$( (cat "$OUT/$tag".time* 2> /dev/null | awk '/Maximum resident set size/ { print $NF }'
    sed -n 's/.*Memory: peak resident \([0-9.]*\) \([MG]\)iB.*/\1 \2/p' "$OUT/$tag.log" |
      awk '{ print $1 * ($2 == "G" ? 1048576 : 1024) }') | awk '{ if ($1 > m) m = $1 } END { print m + 0 }')
  first=$(awk '/Matching block/ { print $1; exit }' "$OUT/$tag.log")
  pairs=$(grep -oE '\([0-9]+/[0-9]+ pairs' "$OUT/$tag.log" | tail -1 | tr -d '(' | sed 's/ pairs//')
  local images="${db##*/street_}"
  images="${images%%x*}"
  local peak_mib
  peak_mib=$(awk -v k="$peak_kib" 'BEGIN { printf "%.0f", k / 1024 }')
  printf '%-10s %7s %5s %10s %12s %22s\n' "$label" "$(basename "$db" .db | sed 's/street_//')" "$ranks" \
    "$peak_mib" "${first:--}" "${pairs:--}"
  echo "$label,$binary,$images,$ranks,$peak_mib,${first:-},${pairs%%/*}" >> "$CSV"
}

# --- Databases ---------------------------------------------------------------
for n in $SIZES; do
  db="$WORK/street_${n}x${NUM_FEATURES}.db"
  [ -f "$db" ] && continue
  "${BUILDS[0]}" generate_database --database_path "$db.tmp" --source_database_path "$SOURCE_DB" \
    --num_images "$n" --num_features "$NUM_FEATURES" > "$OUT/generate_$n.log" 2>&1 ||
    { echo "generate_database failed:"; tail -5 "$OUT/generate_$n.log"; exit 1; }
  mv "$db.tmp" "$db"
done

# --- Runs ----------------------------------------------------------------------
CSV="$OUT/host_memory.csv"
{
  echo "# host_memory_scale.sh $(date -u +%Y-%m-%dT%H:%M:%SZ), $(nproc) cores," \
    "$(awk '/MemTotal/ { printf "%.1f GiB", $2 / 1048576 }' /proc/meminfo); ${NUM_FEATURES} features an image," \
    "SIGINT after ${RUN_S} s, --FeatureMatching.use_gpu $USE_GPU ${OPTIONS[*]}"
  echo "build,binary,images,processes,peak_mib,first_chunk_s,pairs_committed"
} > "$CSV"
echo "# host_memory_scale.sh $(date -u +%Y-%m-%dT%H:%M:%SZ), $(nproc) cores," \
  "$(awk '/MemTotal/ { printf "%.1f GiB", $2 / 1048576 }' /proc/meminfo); ${NUM_FEATURES} features an image," \
  "SIGINT after ${RUN_S} s, --FeatureMatching.use_gpu $USE_GPU ${OPTIONS[*]}"
printf '%-10s %7s %5s %10s %12s %22s\n' build images procs "peak MiB" "1st chunk s" "pairs committed"
b=0
for binary in "${BUILDS[@]}"; do
  label="build$b"
  b=$((b + 1))
  for ranks in 1 $([ "$MPI_RANKS" -gt 1 ] && echo "$MPI_RANKS"); do
    for n in $SIZES; do
      run_one "$label" "$binary" "$WORK/street_${n}x${NUM_FEATURES}.db" "$ranks"
    done
  done
done
rm -f "$WORK/run.db" "$WORK/run.db-wal" "$WORK/run.db-shm"
echo "builds: $(b=0; for x in "${BUILDS[@]}"; do printf 'build%d=%s ' "$b" "$x"; b=$((b + 1)); done)"
python3 "$(dirname "$0")/plot_host_memory.py" "$CSV" --png "$OUT/host_memory.png" --table "$OUT/host_memory.md"
