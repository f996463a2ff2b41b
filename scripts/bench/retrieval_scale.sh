#!/bin/bash
# Retrieval's time against the whole command's on a generated street, at
# every size of the scale table (docs/BENCHMARKS.md, "Retrieval").
#
#   scripts/bench/retrieval_scale.sh BUILD_DIR SOURCE_DB WORK_DIR [SIZES] [FEATURES] [NUM_IMAGES] [USE_GPU]
#
# USE_GPU (default 1): retrieval's queries on the GPU, as the command runs
# them on a machine with one (docs/retrieval.md, "Queries on the GPU"); 0
# runs the benchmark and the command on the CPU alone.
# SOURCE_DB: a COLMAP database of real SIFT (e.g. herzjesu-P25's). One street
# of the largest size (default 20000 images x 4096 features) is generated
# into WORK_DIR once; each size (default "2500 5000 10000 20000") then
#   1. times retrieval alone on its first N images (scripts/retrieval_bench
#      --max_images N: mean, reading and hashing, indexing, querying; wall
#      and CPU seconds), and
#   2. runs the whole command, `cashash retrieval_matcher`, on a copy that
#      holds only those N images, timed by /usr/bin/time; retrieval's part
#      is the sum of the command's own "Retrieval time:" line.
# Prints one line per size, and writes the table WORK_DIR/retrieval_scale.md
# and its plot WORK_DIR/retrieval_scale.png (scripts/bench/plot_retrieval_scale.py).
set -euo pipefail
BUILD="$1"; SOURCE="$2"; WORK="$3"
SIZES="${4:-2500 5000 10000 20000}"; FEATURES="${5:-4096}"; K="${6:-50}"; USE_GPU="${7:-1}"
CASHASH="$BUILD/colmap_bridge/cashash"; BENCH="$BUILD/scripts/retrieval_bench"
mkdir -p "$WORK"
largest=0; for n in $SIZES; do (( n > largest )) && largest=$n; done
STREET="$WORK/street_${largest}x${FEATURES}.db"
if [[ ! -f "$STREET" ]]; then
  /usr/bin/time -f "generate_database: %e s" "$CASHASH" generate_database --database_path "$STREET" \
    --source_database_path "$SOURCE" --num_images "$largest" --num_features "$FEATURES" > "$WORK/generate.log"
fi
TABLE="$WORK/retrieval_scale.md"
{
echo "| images | retrieval_bench wall s | retrieval_bench CPU s | pairs | queries | command: retrieval s | command: wall s | retrieval share |"
echo "|---:|---|---|---:|---|---:|---:|---:|"
for n in $SIZES; do
  log="$WORK/bench_$n.log"
  "$BENCH" --database "$STREET" --max_images "$n" --num_images "$K" --use_gpu "$USE_GPU" \
    --pairs_out "$WORK/pairs_$n.txt" > "$log"
  walls=$(sed -n 's/^seconds: //p' "$log"); cpus=$(sed -n 's/^cpu seconds: //p' "$log")
  pairs=$(sed -n 's/^pairs \([0-9]*\) .*/\1/p' "$log")
  db="$WORK/run_$n.db"; rm -f "$db" "$db"-*
  # The first n images only: a copy without the others' rows.
  cp "$STREET" "$db"
  python3 -c "import sqlite3, sys; c = sqlite3.connect(sys.argv[1]); [c.execute(f'DELETE FROM {t} WHERE image_id > ?', (int(sys.argv[2]),)) for t in ('keypoints', 'descriptors', 'images')]; c.commit()" "$db" "$n"
  /usr/bin/time -f "%e" -o "$WORK/time_$n.txt" "$CASHASH" retrieval_matcher --database_path "$db" \
    --VocabTreeMatching.num_images "$K" --FeatureMatching.use_gpu "$USE_GPU" > "$WORK/run_$n.log" 2>&1
  command_s=$(tail -1 "$WORK/time_$n.txt")
  # "Retrieval time: mean A s, reading and hashing B s, indexing C s,
  # querying D s on GPU 0": the sum of the phases, and where the queries ran.
  retrieval_s=$(sed -n 's/^Retrieval time: //p' "$WORK/run_$n.log" | grep -o '[0-9.]* s' | awk '{t += $1} END {print t}')
  queries=$(sed -n 's/^Retrieval time: .* s on \(.*\)$/\1/p' "$WORK/run_$n.log")
  share=$(python3 -c "print('%.1f %%' % (100 * $retrieval_s / $command_s))")
  echo "| $n | $walls | $cpus | $pairs | $queries | $retrieval_s | $command_s | $share |"
  rm -f "$db" "$db"-*
done
} | tee "$TABLE"
# A machine without matplotlib keeps the table; the same line draws the plot elsewhere.
python3 "$(dirname "$0")/plot_retrieval_scale.py" "$TABLE" --png "$WORK/retrieval_scale.png" \
  || echo "no plot drawn: run scripts/bench/plot_retrieval_scale.py $TABLE --png retrieval_scale.png where matplotlib is"
