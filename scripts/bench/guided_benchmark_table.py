#!/usr/bin/env python3
"""The table of scripts/bench/guided_benchmark.sh: per configuration, the
seconds of each repetition from the run summary (whole run / matching /
verification, and the process's wall time), verified pairs, inlier matches,
pairs Ga matched in stage 2, then colmap mapper's registered images, 3D
points and mean reprojection error, and each run's speed-up over the
exhaustive GPU run (ratio of the medians of the summary's seconds)."""

import argparse
import glob
import json
import os
import re
import statistics
import sys

NAMES = {"ex": "exhaustive, GPU verification", "ga": "Ga (guided_matcher)",
         "fb": "Ga with --GuidedMatching.unguided_fallback 1"}


def parse_log(path):
    text = open(path, errors="replace").read()

    def grab(pattern, cast=float):
        m = re.search(pattern, text, re.M)
        return cast(m.group(1)) if m else None
    return {
        "total": grab(r"^Summary: \d+ pairs in ([\d.]+) s"),
        "matching": grab(r"^Time: .*matching ([\d.]+) s"),
        "verification": grab(r"^Time: .*verification ([\d.]+) s"),
        "wall": grab(r"^Wall: (\d+) ms", int),
        "exit": grab(r"^Wall: .*exit (\d+)", int),
        "pairs": grab(r"^Summary: (\d+) pairs", int),
        "verified": grab(r"(\d+) verified pairs", int),
        "inliers": grab(r"(\d+) inlier matches", int),
        "stage2": grab(r"^Guided matching: .*?(\d+) matched within", int),
        "matcher": grab(r"^Matcher: (.*)$", str),
    }


def seconds(runs, key):
    values = [r[key] for r in runs if r[key] is not None]
    if key == "wall":
        values = [v / 1000 for v in values]
    return " / ".join(f"{v:.3f}" for v in values) if values else "-"


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("out_dir")
    args = parser.parse_args()
    rows, medians = [], {}
    for config in ("ex", "ga", "fb"):
        logs = sorted(glob.glob(os.path.join(args.out_dir, f"{config}_[0-9]*.log")))
        if not logs:
            continue
        runs = [parse_log(p) for p in logs]
        done = [r for r in runs if r["exit"] == 0 and r["total"] is not None]
        if done:
            medians[config] = (statistics.median(r["total"] for r in done),
                               statistics.median(r["wall"] / 1000 for r in done if r["wall"] is not None))
        last = runs[-1]
        model = {}
        model_path = os.path.join(args.out_dir, f"{config}.model.json")
        if os.path.exists(model_path):
            with open(model_path) as f:
                first = f.readline()
            model = json.loads(first) if first.startswith("{") else {}
        error = model.get("mean_reprojection_error")
        rows.append([NAMES[config], seconds(runs, "total"), seconds(runs, "wall"), seconds(runs, "matching"),
                     seconds(runs, "verification"), "-" if last["stage2"] is None else str(last["stage2"]),
                     str(last["verified"]), str(last["inliers"]),
                     str(model.get("registered", "-")), str(model.get("points", "-")),
                     "-" if error is None else f"{error:.3f}",
                     ", ".join([f"exit {r['exit']}" for r in runs if r["exit"] not in (0, None)]
                               + ([f"matcher {last['matcher']} (no GPU)"]
                                  if last["matcher"] and "gpu" not in last["matcher"] else []))])
    if not rows:
        print(f"no CONFIG_N.log files in {args.out_dir}", file=sys.stderr)
        return 1
    header = ["run", "summary s", "wall s", "matching s", "verification s", "Ga stage-2 pairs",
              "verified pairs", "inlier matches", "registered", "3D points", "reproj. error px", "notes"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")
    if "ex" in medians:
        for config, (total, wall) in medians.items():
            if config != "ex":
                print(f"\n{NAMES[config]} against the exhaustive GPU run: "
                      f"{medians['ex'][0] / total:.2f}x (summary), {medians['ex'][1] / wall:.2f}x (wall)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
