#!/usr/bin/env bash
# Does a run's GPU memory stay within --max_gpu_memory on databases whose
# feature counts vary as a SIFT extraction's do? For each cashash binary
# given, each database and each cap, runs `cashash exhaustive_matcher` on a
# fresh copy of the database while nvidia-smi samples the process's device
# memory every 100 ms, and prints the peak beside the cap plus the CUDA
# context, and whether the log reports a fall back to the CPU.
#
# Usage: gpu_memory_cap.sh SOURCE_DB OUT_DIR CASHASH [CASHASH ...]
#   SOURCE_DB  a COLMAP database with SIFT features (generate_database's source)
#   CASHASH    one or more binaries, e.g. the old build and the new one, to
#              compare them in one call on the same databases
# Environment (defaults in brackets):
#   SETS ["1500"]: databases, any of
#       1500: 1,500 images of 1,000-12,288 features (40 % at the cap, the rest
#             spread evenly below it; mean about 8,900),
#       5000: 5,000 images of 500-8,192 features (20 % at the cap; mean about 5,100),
#       20:   20 images of 100-400 features (a dry run of the script),
#   CAPS ["1G 2G default"]: --max_gpu_memory values; "default" passes none,
#   WORK [/tmp/cashash_gpu_memory_cap]: databases and their run copies
#       (about 1.4 GB for 1500, 4 GB for 5000, twice during a run),
#   GENERATOR [the first CASHASH whose generate_database knows
#       --num_features_distribution]: the binary that generates the databases,
#   EXTRA [""]: more exhaustive_matcher options for every run,
#   TIME_LIMIT [0]: seconds after which a run is stopped (0: none); a run
#       that fell back to the CPU can take hours, and its peak and fallback
#       are known by then. Its wall time is then printed as ">LIMIT".
# The CUDA context of each binary is measured first: its peak on a database
# of 3 images of 2,000 features (enough matches for the exact rematch and
# the verification kernels to run, so that the device memory the driver
# takes for the kernels' code and local memory is in it). Writes OUT_DIR/results.csv, OUT_DIR/summary.txt
# and per run a log and the nvidia-smi samples.
set -u -o pipefail

if [ $# -lt 3 ]; then
  sed -n '2,/^set -u/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'
  exit 2
fi
SOURCE_DB="$1"; OUT_DIR="$2"; shift 2
BINARIES=("$@")
SETS="${SETS:-1500}"
CAPS="${CAPS:-1G 2G default}"
WORK="${WORK:-/tmp/cashash_gpu_memory_cap}"
EXTRA="${EXTRA:-}"
TIME_LIMIT="${TIME_LIMIT:-0}"
mkdir -p "$OUT_DIR" "$WORK"
SUMMARY="$OUT_DIR/summary.txt"
CSV="$OUT_DIR/results.csv"

command -v nvidia-smi > /dev/null 2>&1 || { echo "nvidia-smi not found: this script needs the GPU machine"; exit 1; }
[ -f "$SOURCE_DB" ] || { echo "no source database at $SOURCE_DB"; exit 1; }
for bin in "${BINARIES[@]}"; do
  [ -x "$bin" ] || { echo "not an executable: $bin"; exit 1; }
done

GENERATOR="${GENERATOR:-}"
if [ -z "$GENERATOR" ]; then
  for bin in "${BINARIES[@]}"; do
    if "$bin" generate_database --help 2>&1 | grep -q num_features_distribution; then GENERATOR="$bin"; break; fi
  done
fi
[ -n "$GENERATOR" ] || { echo "no binary generates varying feature counts; set GENERATOR to a new build"; exit 1; }

# generate NAME IMAGES CAP MIN AT_CAP_SHARE: WORK/NAME.db, once.
generate() {
  local db="$WORK/$1.db"
  if [ ! -f "$db" ]; then
    "$GENERATOR" generate_database --database_path "$db" --source_database_path "$SOURCE_DB" --num_images "$2" \
      --num_features "$3" --num_features_distribution extraction --min_num_features "$4" \
      --num_features_at_cap_share "$5" --random_seed 7 > "$OUT_DIR/generate_$1.log" 2>&1 \
      || { echo "generate_database failed:"; tail -5 "$OUT_DIR/generate_$1.log"; exit 1; }
  fi
  echo "$db"
}

# The process's peak device memory (MiB) in an nvidia-smi sample file for
# `pid`; every process's where the container hides the pid from nvidia-smi.
peak_of() {
  local samples="$1" pid="$2" peak
  peak=$(awk -F', *' -v pid="$pid" '$1 == pid && $2 + 0 > max { max = $2 + 0 } END { print max + 0 }' "$samples")
  if [ "$peak" = 0 ]; then
    peak=$(awk -F', *' '$2 + 0 > max { max = $2 + 0 } END { print max + 0 }' "$samples")
  fi
  echo "$peak"
}

# run BINARY DB TAG CAP: one exhaustive_matcher run on a fresh copy, sampled.
# Prints "wall_s peak_mib fallback owner_line".
run() {
  local bin="$1" db="$2" tag="$3" cap="$4"
  local copy="$WORK/run.db" log="$OUT_DIR/$tag.log" samples="$OUT_DIR/$tag.smi.csv"
  rm -f "$copy" "$copy-wal" "$copy-shm"
  cp "$db" "$copy"
  local cap_args=()
  [ "$cap" != default ] && cap_args=(--max_gpu_memory "$cap")
  nvidia-smi --query-compute-apps=pid,used_memory --format=csv,noheader,nounits -lms 100 > "$samples" 2> /dev/null &
  local sampler=$!
  local start end
  start=$(date +%s.%N)
  # shellcheck disable=SC2086
  "$bin" exhaustive_matcher --database_path "$copy" "${cap_args[@]}" $EXTRA > "$log" 2>&1 &
  local pid=$! stopped=0
  if [ "$TIME_LIMIT" != 0 ]; then
    rm -f "$OUT_DIR/$tag.stopped"
    ( sleep "$TIME_LIMIT"; touch "$OUT_DIR/$tag.stopped"; kill -INT "$pid" 2> /dev/null
      sleep 30; kill -KILL "$pid" 2> /dev/null ) &
    local watchdog=$!
  fi
  wait "$pid"
  local code=$?
  end=$(date +%s.%N)
  if [ "$TIME_LIMIT" != 0 ]; then
    kill "$watchdog" 2> /dev/null
    wait "$watchdog" 2> /dev/null
    [ -f "$OUT_DIR/$tag.stopped" ] && stopped=1
  fi
  sleep 0.3
  kill "$sampler" 2> /dev/null
  wait "$sampler" 2> /dev/null
  rm -f "$copy" "$copy-wal" "$copy-shm"
  local fallback=no
  grep -qE "CPU fallback|continuing on|(matching|verifying) on the CPU" "$log" && fallback=yes
  [ "$code" != 0 ] && [ "$stopped" = 0 ] && fallback="exit $code"
  local owner wall
  owner=$(grep -m1 "^GPU memory:" "$log" | sed 's/^GPU memory: //; s/,/;/g')
  wall=$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.1f", b - a }')
  [ "$stopped" = 1 ] && wall=">$TIME_LIMIT"
  echo "$wall $(peak_of "$samples" "$pid") $fallback|${owner:-}"
}

mib_of_cap() {  # "1G" -> 1024, "512M" -> 512, "default" -> the device's memory
  case "$1" in
    default) nvidia-smi --query-gpu=memory.total --format=csv,noheader,nounits | head -1 | tr -d ' ' ;;
    *[Gg]) awk -v v="${1%[Gg]}" 'BEGIN { printf "%d", v * 1024 }' ;;
    *[Mm]) echo "${1%[Mm]}" ;;
    *) echo "$1" ;;
  esac
}

{
  echo "# gpu_memory_cap.sh $(date -u +%Y-%m-%dT%H:%M:%SZ)"
  echo "gpu: $(nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | head -1)"
  echo "sets: $SETS; caps: $CAPS; extra options: ${EXTRA:-none}; generator: $GENERATOR"
} | tee "$SUMMARY"
echo "binary,set,cap,wall_s,peak_mib,cap_mib,context_mib,peak_minus_context_mib,within_cap,cpu_fallback,owner" > "$CSV"

TINY="$WORK/tiny.db"
rm -f "$TINY" "$TINY-wal" "$TINY-shm"
"$GENERATOR" generate_database --database_path "$TINY" --source_database_path "$SOURCE_DB" --num_images 3 \
  --num_features 2000 > "$OUT_DIR/generate_tiny.log" 2>&1 \
  || { echo "generating the 3-image database failed:"; tail -5 "$OUT_DIR/generate_tiny.log"; exit 1; }

for set in $SETS; do
  case "$set" in
    1500) DB=$(generate varying_1500 1500 12288 1000 0.4) ;;
    5000) DB=$(generate varying_5000 5000 8192 500 0.2) ;;
    20) DB=$(generate varying_20 20 400 100 0.4) ;;
    *) echo "unknown set $set (1500, 5000 or 20)"; exit 1 ;;
  esac
  [ -f "$DB" ] || { echo "$DB"; exit 1; }
  grep -h "^Wrote" "$OUT_DIR"/generate_varying_"$set".log 2> /dev/null | tee -a "$SUMMARY"
done

printf "%-40s %5s %8s %8s %9s %8s %9s %9s %8s  %s\n" binary set cap wall_s peak_MiB cap_MiB context peak-ctx within fallback \
  | tee -a "$SUMMARY"
n=0
for bin in "${BINARIES[@]}"; do
  n=$((n + 1))
  result=$(run "$bin" "$TINY" "b${n}_context" default)
  context=$(echo "${result%%|*}" | awk '{ print $2 }')
  echo "binary $n: $bin (CUDA context and a 3-image run: $context MiB)" | tee -a "$SUMMARY"
  for set in $SETS; do
    for cap in $CAPS; do
      result=$(run "$bin" "$WORK/varying_$set.db" "b${n}_${set}_${cap}" "$cap")
      read -r wall peak fallback <<< "${result%%|*}"
      owner="${result#*|}"
      cap_mib=$(mib_of_cap "$cap")
      within=$(awk -v p="$peak" -v c="$cap_mib" -v x="$context" 'BEGIN { print (p <= c + x) ? "yes" : "NO" }')
      printf "%-40s %5s %8s %8s %9s %8s %9s %9s %8s  %s\n" "b$n" "$set" "$cap" "$wall" "$peak" "$cap_mib" "$context" \
        "$((peak - context))" "$within" "$fallback" | tee -a "$SUMMARY"
      [ -n "$owner" ] && echo "    owner: $owner" | tee -a "$SUMMARY"
      echo "b$n,$set,$cap,$wall,$peak,$cap_mib,$context,$((peak - context)),$within,$fallback,$owner" >> "$CSV"
    done
  done
done
echo "within: peak process memory by nvidia-smi <= cap + the binary's context run; fallback: the log reports" \
     "a GPU part going on on the CPU (or the run failed)" | tee -a "$SUMMARY"
