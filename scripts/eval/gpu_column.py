"""The GPU cascade column, measured on another machine.

The machine with the GPU has neither COLMAP nor the image data, so the
evaluation splits in two:

  export_inputs: the SIFT feature databases of the homography sequences
  (features only, no matches) and a run.sh that matches each of them in
  place with `cashash exhaustive_matcher --FeatureMatching.use_gpu 1` and
  the CPU cascade's setting (its --CasHash flags, the rematch off);
  read_results: after run.sh, the matched databases are evaluated like any
  other matcher, and compared row by row with the CPU cascade.

run.sh also stores what the evaluation must check before it trusts the
numbers: the setting it passed (setting.txt; it must equal the CPU
cascade's), the binary's option defaults, the GPU it saw and, per sequence, the matcher that finished the
run (a GPU run that fell back to the CPU says so in its summary line).
"""
import os
import re
import sqlite3
import stat

from eval import homography, tools

RUN_SCRIPT = """#!/usr/bin/env bash
# Matches every <sequence>.db of this folder with the GPU cascade, in place.
#   ./run.sh <path to the cashash binary>
# Writes <sequence>.log, options.txt (the binary's defaults), setting.txt (the
# cascade setting passed) and device.txt.
# Then bring the whole folder back and run
#   scripts/evaluate_accuracy.py --gpu-results <this folder> ...
set -euo pipefail
binary=$(realpath "${1:?usage: run.sh <cashash binary>}")
cd "$(dirname "$0")"
nvidia-smi -L > device.txt 2>/dev/null || echo "no nvidia-smi on this machine" > device.txt
"$binary" exhaustive_matcher --help > options.txt 2>&1
echo "%(setting)s" > setting.txt
for database in %(databases)s; do
  name=${database%%.db}
  echo "== $name"
  # --overwrite 1: a second run matches again instead of skipping the pairs.
  # --CasHash.matcher cascade: this column is the GPU cascade against the CPU
  # cascade's (the default, auto, may pick brute force for some pairs).
  "$binary" exhaustive_matcher --database_path "$database" --FeatureMatching.use_gpu 1 \\
      --CasHash.matcher cascade %(flags)s --overwrite 1 > "$name.log" 2>&1 || { tail -20 "$name.log"; exit 1; }
  grep -E "^(Summary|Time|Warning|WARNING)" "$name.log" || true
done
echo "done: bring back $(pwd)"
"""

# The option help prints defaults as "(=8)"; the option names of the cascade setting.
SETTING_OPTIONS = ["CasHash.num_tables", "CasHash.bits_per_table", "CasHash.tau", "CasHash.top_k"]


def export_inputs(feature_dbs, out_dir, setting, flags):
    """feature_dbs: {sequence: features.db}; setting: 'tables,bits,tau,top_k'
    and flags: the cascade options that give it. Copies each (without match rows,
    compacted) to out_dir/<sequence>.db and writes out_dir/run.sh. Returns the
    folder's size in bytes."""
    os.makedirs(out_dir, exist_ok=True)
    for name, source in feature_dbs.items():
        target = os.path.join(out_dir, name + ".db")
        for suffix in ("", "-wal", "-shm"):
            if os.path.exists(target + suffix):
                os.remove(target + suffix)
        tools.copy_database(source, target)
        conn = sqlite3.connect(target)
        conn.execute("DELETE FROM matches")
        conn.execute("DELETE FROM two_view_geometries")
        conn.commit()
        # Back to a single file without the WAL, as small as it gets.
        conn.execute("PRAGMA journal_mode=DELETE")
        conn.execute("VACUUM")
        conn.close()
    script = os.path.join(out_dir, "run.sh")
    with open(script, "w") as f:
        f.write(RUN_SCRIPT % {"databases": " ".join(name + ".db" for name in feature_dbs), "setting": setting,
                              "flags": " ".join(flags)})
    os.chmod(script, os.stat(script).st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    return sum(os.path.getsize(os.path.join(out_dir, f)) for f in os.listdir(out_dir))


def binary_defaults(results_dir):
    """'tables,bits,tau,top_k' the GPU run used: the setting run.sh passed, or
    (a run.sh that passed none) the binary's defaults as it printed them; None
    if neither is there."""
    passed = os.path.join(results_dir, "setting.txt")
    if os.path.exists(passed):
        return open(passed).read().strip()
    path = os.path.join(results_dir, "options.txt")
    if not os.path.exists(path):
        return None
    text = open(path).read()
    values = []
    for option in SETTING_OPTIONS:
        # The default may be on the option's line or, wrapped, on a later one.
        m = re.search(re.escape("--" + option) + r"\b[^(]*?\(=([0-9]+)\)", text, re.S)
        if not m:
            return None
        values.append(m.group(1))
    return ",".join(values)


def run_summary(results_dir, name):
    """(matcher that finished the run, matching seconds) from <name>.log."""
    path = os.path.join(results_dir, name + ".log")
    if not os.path.exists(path):
        return None, None
    text = open(path).read()
    matcher = re.search(r"^Summary: .* with ([a-z0-9-]+)", text, re.M)
    matching = re.search(r"matching ([0-9.]+) s", text)
    return (matcher.group(1) if matcher else None), (float(matching.group(1)) if matching else None)


def device_text(results_dir):
    path = os.path.join(results_dir, "device.txt")
    return "; ".join(l.strip() for l in open(path) if l.strip()) if os.path.exists(path) else None


def read_results(results_dir, hs_by_sequence, eps_list):
    """{sequence: evaluate_database result} for the matched databases found."""
    found = {}
    for name, hs in hs_by_sequence.items():
        database = os.path.join(results_dir, name + ".db")
        if os.path.exists(database) and os.path.exists(os.path.join(results_dir, name + ".log")):
            found[name] = homography.evaluate_database(database, hs, eps_list)
    return found


def agreement(cpu_pairs, gpu_pairs):
    """Per pair: CPU and GPU match counts, identical (idx1, idx2) rows, and
    whether the two lists are the same."""
    rows = {}
    for key, cpu in cpu_pairs.items():
        gpu = gpu_pairs[key]
        a = {tuple(p) for p in cpu["pairs"].tolist()}
        b = {tuple(p) for p in gpu["pairs"].tolist()}
        rows[key] = {"cpu": len(a), "gpu": len(b), "identical": len(a & b), "same": a == b}
    return rows
