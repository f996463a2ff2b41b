#!/usr/bin/env python3
"""Guided matching against exhaustive matching on one feature database:
verified pairs, inlier matches, and COLMAP's mapper on each result (with
camera errors against ground truth where given).

  scripts/bench/guided_quality.py --database_path DB --output_dir DIR
      [--image_path IMAGES] [--gt_cameras DIR] [--use_gpu 0|1]
      [--configs exhaustive,guided,paper] [--cashash PATH] [--num_threads N]

Configurations, each on its own copy of DB (never modified):
  exhaustive  cashash exhaustive_matcher (defaults)
  guided      cashash guided_matcher (defaults)
  paper       cashash guided_matcher --GuidedMatching.restrict_search_to_band 1
              --GuidedMatching.unguided_fallback 0 (the paper's Ga-CasHash)
  fallback    the paper's method with --GuidedMatching.unguided_fallback 1

With --image_path, pycolmap's incremental mapper (COLMAP 4) reconstructs
each result as scripts/compare_with_colmap.py does (fixed seed, one model,
the largest); with --gt_cameras (Strecha *.camera files) the models are
aligned to the true centres by a similarity and camera errors are given.
Writes DIR/guided_quality.md and DIR/guided_quality.json; prints the table.
"""
import argparse
import json
import os
import re
import sys

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import compare_with_colmap as cwc  # noqa: E402

COMMANDS = {
    "exhaustive": ["exhaustive_matcher"],
    "guided": ["guided_matcher"],
    "paper": ["guided_matcher", "--GuidedMatching.restrict_search_to_band", "1",
              "--GuidedMatching.unguided_fallback", "0"],
    "fallback": ["guided_matcher", "--GuidedMatching.restrict_search_to_band", "1"],
}


def run_config(name, args, work_dir, logs, gt):
    database = os.path.join(work_dir, name + ".db")
    cwc.prepare_copy(args.database_path, database)
    command = [args.cashash] + COMMANDS[name] + ["--database_path", database,
                                                  "--FeatureMatching.use_gpu", str(args.use_gpu),
                                                  "--FeatureMatching.num_threads", str(args.num_threads)]
    code, wall, output = cwc.run_command(command, os.path.join(logs, name + "_match.log"))
    if code != 0:
        raise SystemExit("ERROR: %s failed (exit %s): %s" % (name, code, cwc.tail(output, 6)))
    summary = re.search(r"Summary: \d+ pairs in ([0-9.]+) s", output)
    result = {"command": " ".join(command), "wall_s": wall, "summary_s": float(summary.group(1)) if summary else None,
              "guided_line": cwc.first_line(output, "Guided matching:"), "database": database}
    result["results"] = cwc.read_results(database)
    result["counts"] = cwc.counts(result["results"])
    if args.image_path:
        result["mapper"] = cwc.reconstruct_side(name, database, args, work_dir, logs, gt)
    return result


def row(name, result, reference, gt_given):
    counts = result["counts"]
    agreement = cwc.agreement(reference["results"], result["results"])
    mapper = result.get("mapper") or {}
    errors = mapper.get("gt") or {}
    fmt = cwc.fmt
    cells = [name, fmt(result["summary_s"]), str(counts["verified_pairs"]),
             cwc.pct(agreement["cashash_verified_also_by_colmap"] if name == "exhaustive"
                     else agreement["colmap_verified_also_by_cashash"]),
             "{:,}".format(counts["inlier_matches"]),
             cwc.pct(agreement["colmap_inlier_matches_also_in_cashash"])]
    if mapper:
        cells += ["%s" % mapper.get("registered_images", "-"), "{:,}".format(mapper.get("points3D") or 0),
                  fmt(mapper.get("mean_reprojection_error"))]
    if errors or (mapper and gt_given):
        if "position_median" in errors:
            cells += ["%s / %s mm" % (fmt(1000 * errors["position_median"], 2), fmt(1000 * errors["position_max"], 2)),
                      "%s / %s deg" % (fmt(errors["rotation_median_deg"]), fmt(errors["rotation_max_deg"]))]
        else:
            cells += ["fewer than 3 images", ""]
    return cells


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--database_path", required=True)
    parser.add_argument("--output_dir", required=True)
    parser.add_argument("--image_path")
    parser.add_argument("--gt_cameras")
    parser.add_argument("--use_gpu", type=int, choices=(0, 1), default=0)
    parser.add_argument("--configs", default="exhaustive,guided,paper")
    parser.add_argument("--cashash", default=os.path.join(cwc.REPO, "build", "colmap_bridge", "cashash"))
    parser.add_argument("--num_threads", type=int, default=-1)
    args = parser.parse_args(argv)
    configs = [c for c in args.configs.split(",") if c]
    unknown = [c for c in configs if c not in COMMANDS]
    if unknown or "exhaustive" not in configs:
        parser.error("--configs: known are %s, and exhaustive is the reference" % ", ".join(COMMANDS))
    if not os.path.isfile(args.database_path):
        parser.error("--database_path: no file at %s" % args.database_path)
    work_dir = os.path.abspath(args.output_dir)
    logs = os.path.join(work_dir, "logs")
    os.makedirs(logs, exist_ok=True)
    gt = cwc.cameras.read_gt_camera_files(args.gt_cameras) if args.gt_cameras else None

    results = {name: run_config(name, args, work_dir, logs, gt) for name in configs}
    header = ["run", "summary s", "verified pairs", "exhaustive's verified pairs also verified",
              "inlier matches", "exhaustive's inlier matches kept"]
    if args.image_path:
        header += ["registered", "3D points", "mean reproj. px"]
    if gt:
        header += ["centre error median / max", "rotation error median / max"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for name in configs:
        lines.append("| " + " | ".join(row(name, results[name], results["exhaustive"], gt is not None)) + " |")
    table = "\n".join(lines)
    database = cwc.database_summary(args.database_path)
    text = "# Guided against exhaustive matching: %s (%d images, %.0f features per image)\n\n%s\n\n" % (
        os.path.basename(args.database_path), database["num_images"], database["mean_features_per_image"], table)
    text += "\n".join("- %s: `%s`; %s" % (n, results[n]["command"], results[n]["guided_line"] or "")
                      for n in configs) + "\n"
    with open(os.path.join(work_dir, "guided_quality.md"), "w") as f:
        f.write(text)
    for result in results.values():
        result.pop("results")
    with open(os.path.join(work_dir, "guided_quality.json"), "w") as f:
        json.dump({"database": database, "configs": results}, f, indent=1, default=str)
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
