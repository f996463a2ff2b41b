#!/usr/bin/env bash
# Large-scale benchmark of `cashash exhaustive_matcher` within a fixed wall
# time: generates a street database, then runs
#   phase A: matching + geometric verification (what a user runs),
#   phase B: matching only (--FeatureMatching.skip_geometric_verification 1),
#            resuming after the pairs phase A committed,
# each stopped cleanly with SIGINT (committed blocks stay; the run prints its
# closing summary) before its share of the time is up. Every second a sampler
# records the pairs committed so far, the process's resident memory
# (/proc/PID/status) and the GPU memory in use (nvidia-smi, when present).
#
# Usage: scale_run.sh CASHASH SOURCE_DB OUT_DIR [extra exhaustive_matcher options]
# Environment (defaults in brackets):
#   NUM_IMAGES [5000], NUM_FEATURES [8192], TOTAL_S [520]: wall time for all of it,
#   PHASE_A_SHARE [0.5]: phase A's share of the time left after generating,
#   WORK [/tmp/cashash_scale]: where the database goes (about 1.2 MiB per
#       image of 8192 features), MAX_HOST_MEMORY [16G], WRITE_EMPTY_PAIRS [0],
#   USE_GPU [1], PHASES [AB] (A, B or AB), KEEP_DB [0],
#   PHASE_A_OPTIONS [--ExhaustiveMatching.block_size 25]: smaller chunks in
#       phase A, so that the blocks in flight after SIGINT (up to three being
#       verified) finish in time; phase B uses the derived size (50).
# Writes to OUT_DIR: samples.csv (t_s, phase, pairs_done, pairs_total,
# rss_mib, gpu_used_mib), generate.log, phase_A.log, phase_B.log, summary.txt,
# and from them (scripts/bench/plot_scale_run.py) the table scale_run.md and
# its plot scale_run.png.
set -u -o pipefail

CASHASH="$1"; SOURCE_DB="$2"; OUT_DIR="$3"; shift 3
EXTRA=("$@")
NUM_IMAGES="${NUM_IMAGES:-5000}"
NUM_FEATURES="${NUM_FEATURES:-8192}"
TOTAL_S="${TOTAL_S:-520}"
PHASE_A_SHARE="${PHASE_A_SHARE:-0.5}"
WORK="${WORK:-/tmp/cashash_scale}"
MAX_HOST_MEMORY="${MAX_HOST_MEMORY:-16G}"
WRITE_EMPTY_PAIRS="${WRITE_EMPTY_PAIRS:-0}"
USE_GPU="${USE_GPU:-1}"
PHASES="${PHASES:-AB}"
PHASE_A_OPTIONS="${PHASE_A_OPTIONS---ExhaustiveMatching.block_size 25}"
KEEP_DB="${KEEP_DB:-0}"

mkdir -p "$OUT_DIR" "$WORK"
DB="$WORK/street_${NUM_IMAGES}x${NUM_FEATURES}.db"
CSV="$OUT_DIR/samples.csv"
SUMMARY="$OUT_DIR/summary.txt"
T0=$(date +%s.%N)
now() { awk -v t0="$T0" -v t="$(date +%s.%N)" 'BEGIN { printf "%.1f", t - t0 }'; }
# Seconds as an integer comparison helper: ge A B is true when A >= B.
ge() { awk -v a="$1" -v b="$2" 'BEGIN { exit !(a >= b) }'; }

HAVE_SMI=0
command -v nvidia-smi > /dev/null 2>&1 && nvidia-smi > /dev/null 2>&1 && HAVE_SMI=1
gpu_used_mib() {
  if [ "$HAVE_SMI" = 1 ]; then
    nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits 2> /dev/null | head -1 | tr -d ' '
  fi
}

{
  echo "# scale_run.sh $(date -u +%Y-%m-%dT%H:%M:%SZ)"
  echo "host: $(nproc) cores, $(awk '/MemTotal/ { printf "%.1f GiB", $2 / 1048576 }' /proc/meminfo) memory"
  [ "$HAVE_SMI" = 1 ] && echo "gpu: $(nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | head -1)"
  echo "images: $NUM_IMAGES x $NUM_FEATURES features; total time $TOTAL_S s; phases $PHASES"
  echo "phase A options: ${PHASE_A_OPTIONS:-none}"
  echo "options: --max_host_memory $MAX_HOST_MEMORY --write_empty_pairs $WRITE_EMPTY_PAIRS --FeatureMatching.use_gpu $USE_GPU ${EXTRA[*]:-}"
} > "$SUMMARY"
echo "t_s,phase,pairs_done,pairs_total,rss_mib,gpu_used_mib" > "$CSV"

# --- Generate -----------------------------------------------------------
rm -f "$DB" "$DB-wal" "$DB-shm"
GEN_START=$(now)
TIME=()
[ -x /usr/bin/time ] && TIME=(/usr/bin/time -f "generate: %e s wall, %M KiB peak resident")
"${TIME[@]}" "$CASHASH" generate_database --database_path "$DB" --source_database_path "$SOURCE_DB" \
  --num_images "$NUM_IMAGES" --num_features "$NUM_FEATURES" > "$OUT_DIR/generate.log" 2>&1 \
  || { echo "generate_database failed:"; tail -5 "$OUT_DIR/generate.log"; exit 1; }
GEN_END=$(now)
{
  echo "generate: $(awk -v a="$GEN_START" -v b="$GEN_END" 'BEGIN { printf "%.1f", b - a }') s wall, file $(du -m "$DB" | cut -f1) MiB"
  grep -E "^Wrote|^generate:" "$OUT_DIR/generate.log"
  echo "disk free after generating: $(df -m "$WORK" | awk 'NR == 2 { print $4 }') MiB"
} >> "$SUMMARY"

# --- One phase: run, sample every second, stop with SIGINT in time ---------
# run_phase NAME END_T [options...]: END_T is the time (s since start) by
# which the process must have exited. SIGINT goes out when the time left is
# under four block intervals + 15 s (blocks in flight are finished and
# committed after it; before a second commit the interval is taken as the
# time since the phase started); SIGKILL at END_T if it is still running.
run_phase() {
  local name="$1" end_t="$2"; shift 2
  local log="$OUT_DIR/phase_$name.log"
  local start_t; start_t=$(now)
  "$CASHASH" exhaustive_matcher --database_path "$DB" --max_host_memory "$MAX_HOST_MEMORY" \
    --write_empty_pairs "$WRITE_EMPTY_PAIRS" --FeatureMatching.use_gpu "$USE_GPU" "$@" "${EXTRA[@]}" \
    > "$log" 2>&1 &
  local pid=$! sent_int=0 first_commit_t="" commits=0 last_done=-1
  while kill -0 "$pid" 2> /dev/null; do
    local t progress ndone total rss gpu
    t=$(now)
    progress=$(grep -oE '\([0-9]+/[0-9]+ pairs' "$log" | tail -1 | tr -d '( ' | sed 's/pairs//')
    ndone="${progress%/*}"; total="${progress#*/}"
    [ -z "$progress" ] && { ndone=0; total=""; }
    if [ "$ndone" != "$last_done" ] && [ "$ndone" != 0 ]; then
      commits=$(grep -c '^Matching block' "$log")
      [ -z "$first_commit_t" ] && first_commit_t="$t"
      last_done="$ndone"
    fi
    rss=$(awk '/^VmRSS/ { printf "%.0f", $2 / 1024 }' "/proc/$pid/status" 2> /dev/null)
    gpu=$(gpu_used_mib)
    echo "$t,$name,$ndone,$total,${rss:-},${gpu:-}" >> "$CSV"
    if [ "$sent_int" = 0 ]; then
      # Mean time between commits since the first one (the first block
      # also waits for loading and hashing); before two commits, at least
      # the time since the phase started.
      local interval
      interval=$(awk -v a="$start_t" -v b="$t" 'BEGIN { printf "%.1f", b - a }')
      if [ "$commits" -gt 1 ]; then
        interval=$(awk -v a="$first_commit_t" -v b="$t" -v c="$commits" 'BEGIN { printf "%.1f", (b - a) / (c - 1) }')
      fi
      if ge "$(awk -v t="$t" -v i="$interval" 'BEGIN { print t + 4 * i + 15 }')" "$end_t"; then
        kill -INT "$pid" 2> /dev/null; sent_int=1
        echo "phase $name: SIGINT at $t s (block interval ${interval} s)" >> "$SUMMARY"
      fi
    elif ge "$t" "$end_t"; then
      kill -KILL "$pid" 2> /dev/null
      echo "phase $name: SIGKILL at $t s (the blocks in flight did not finish in time)" >> "$SUMMARY"
    fi
    sleep 1
  done
  wait "$pid"; local rc=$?
  local stop_t; stop_t=$(now)
  {
    echo "phase $name: exit $rc, $(awk -v a="$start_t" -v b="$stop_t" 'BEGIN { printf "%.1f", b - a }') s wall ($start_t to $stop_t s)"
    grep -E "^(Schedule|Skipping|Matcher|Hashing|Features|Elapsed time|Summary|Time|Memory|Stopped|WARNING|ERROR)" "$log" | sed "s/^/  /"
  } >> "$SUMMARY"
}

LEFT_AFTER_GEN=$(awk -v total="$TOTAL_S" -v t="$(now)" 'BEGIN { printf "%.0f", total - t }')
case "$PHASES" in
  AB) A_END=$(awk -v t="$(now)" -v l="$LEFT_AFTER_GEN" -v s="$PHASE_A_SHARE" 'BEGIN { printf "%.0f", t + l * s }') ;;
  *) A_END="$TOTAL_S" ;;
esac
# shellcheck disable=SC2086
case "$PHASES" in *A*) run_phase A "$A_END" $PHASE_A_OPTIONS ;; esac
case "$PHASES" in *B*) run_phase B "$TOTAL_S" --FeatureMatching.skip_geometric_verification 1 ;; esac

{
  echo "database after the run: $(du -m "$DB" | cut -f1) MiB; beside it: $(ls "$DB"-* 2> /dev/null | xargs -r -n1 basename | tr '\n' ' ')"
  echo "total: $(now) s"
} >> "$SUMMARY"
[ "$KEEP_DB" = 1 ] || rm -f "$DB" "$DB-wal" "$DB-shm"
cat "$SUMMARY"
python3 "$(dirname "$0")/plot_scale_run.py" "$OUT_DIR"
