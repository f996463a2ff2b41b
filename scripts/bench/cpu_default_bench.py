#!/usr/bin/env python3
"""CPU matchers on copies of one feature database: time, verified pairs, agreement.

  scripts/bench/cpu_default_bench.py --database DB --work DIR
      [--cashash PATH] [--configs colmap38,default,cascade,...]
      [--reference colmap38] [--mapper --image_path IMAGES [--gt_cameras DIR]]

DB is never written: each config matches a copy of it (DIR/<config>.db, its
matches cleared first), as one whole process, timed by wall clock from start
to exit, wall clock and CPU seconds (user + system of the process and its
threads: the cores are shared, and the CPU seconds are what another job's
load inflates least). Configs:

  colmap38      colmap exhaustive_matcher --SiftMatching.use_gpu 0 (COLMAP 3.8)
  pycolmap      pycolmap.match_exhaustive on the CPU (COLMAP 4.x), in a child
  default       cashash exhaustive_matcher with no option but the CPU
  cascade       ... --CasHash.exact_rematch_min_matches 0 (the cascade's matches)
  fullrematch   ... --CasHash.exact_rematch_min_matches 12 (every pair with
                12 cascade matches matched again exactly)
  bruteforce    ... --CasHash.matcher bruteforce
  NAME=ARGS     cashash with the extra options ARGS (space separated)

Prints one Markdown row per config: seconds, verified pairs (rows of
two_view_geometries with at least one inlier), of the reference's verified
pairs how many are verified here too, inlier matches, raw matches, and with
--mapper the images `colmap mapper` registered and, with --gt_cameras (a
folder of Strecha *.camera files), the median and largest camera position
error after a similarity alignment to the true centres, and the median
rotation error.
"""
import argparse
import os
import resource
import shutil
import sqlite3
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

PYCOLMAP_MATCH = ("import pycolmap, sys\n"
                  "m = pycolmap.FeatureMatchingOptions(); m.use_gpu = False\n"
                  "pycolmap.match_exhaustive(sys.argv[1], matching_options=m, device=pycolmap.Device.cpu)\n")


def copy_database(source, target):
    for suffix in ("", "-wal", "-shm"):
        if os.path.exists(target + suffix):
            os.remove(target + suffix)
    src = sqlite3.connect("file:%s?mode=ro" % source, uri=True)
    dst = sqlite3.connect(target)
    src.backup(dst)
    src.close()
    dst.execute("DELETE FROM matches")
    dst.execute("DELETE FROM two_view_geometries")
    dst.commit()
    dst.close()


def command_for(config, cashash, database):
    name, _, extra = config.partition("=")
    if name == "colmap38":
        return ["colmap", "exhaustive_matcher", "--database_path", database, "--SiftMatching.use_gpu", "0"]
    if name == "pycolmap":
        return [sys.executable, "-c", PYCOLMAP_MATCH, database]
    base = [cashash, "exhaustive_matcher", "--database_path", database, "--SiftMatching.use_gpu", "0"]
    fixed = {"default": [], "cascade": ["--CasHash.exact_rematch_min_matches", "0"],
             "fullrematch": ["--CasHash.exact_rematch_min_matches", "12"],
             "bruteforce": ["--CasHash.matcher", "bruteforce"]}
    if name in fixed:
        return base + fixed[name]
    return base + extra.split()


def read_counts(database):
    con = sqlite3.connect(database)
    raw = sum(r[0] for r in con.execute("SELECT rows FROM matches"))
    verified = {}
    for pair_id, rows in con.execute("SELECT pair_id, rows FROM two_view_geometries"):
        if rows > 0:
            verified[pair_id] = rows
    con.close()
    return raw, verified


def map_and_score(database, image_path, gt_cameras, work):
    from eval import cameras  # scripts/eval
    sparse = os.path.join(work, "sparse")
    shutil.rmtree(sparse, ignore_errors=True)
    os.makedirs(sparse)
    log = open(os.path.join(work, "mapper.log"), "w")
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    subprocess.run(["colmap", "mapper", "--database_path", database, "--image_path", image_path,
                    "--output_path", sparse], stdout=log, stderr=subprocess.STDOUT, env=env, check=False)
    best = {}
    for model in sorted(os.listdir(sparse)):
        text = os.path.join(work, "txt_" + model)
        os.makedirs(text, exist_ok=True)
        subprocess.run(["colmap", "model_converter", "--input_path", os.path.join(sparse, model),
                        "--output_path", text, "--output_type", "TXT"], stdout=log, stderr=subprocess.STDOUT,
                       env=env, check=False)
        found = cameras.read_model_images(os.path.join(text, "images.txt"))
        if len(found) > len(best):
            best = found
    log.close()
    if not gt_cameras:
        return {"registered": len(best)}
    return cameras.camera_errors(cameras.read_gt_camera_files(gt_cameras), best)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--database", required=True)
    parser.add_argument("--work", required=True)
    parser.add_argument("--cashash", default="build/colmap_bridge/cashash")
    parser.add_argument("--configs", default="colmap38,default,cascade,fullrematch,bruteforce")
    parser.add_argument("--reference", default="colmap38")
    parser.add_argument("--mapper", action="store_true")
    parser.add_argument("--image_path")
    parser.add_argument("--gt_cameras")
    parser.add_argument("--reuse", default="", help="configs (comma-separated) whose database in --work is "
                        "already matched: scored, not run again (their seconds are not shown)")
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)
    configs = args.configs.split(",")
    results = {}
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    for config in configs:
        name = config.partition("=")[0]
        database = os.path.join(args.work, name + ".db")
        seconds = cpu_seconds = float("nan")
        if name not in args.reuse.split(","):
            copy_database(args.database, database)
            with open(os.path.join(args.work, name + ".log"), "w") as log:
                before = resource.getrusage(resource.RUSAGE_CHILDREN)
                start = time.perf_counter()
                code = subprocess.run(command_for(config, args.cashash, database), stdout=log,
                                      stderr=subprocess.STDOUT, env=env).returncode
                seconds = time.perf_counter() - start
                after = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu_seconds = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            if code != 0:
                print("%s failed (exit %d), see %s.log" % (name, code, os.path.join(args.work, name)))
                continue
        raw, verified = read_counts(database)
        results[name] = {"seconds": seconds, "cpu_seconds": cpu_seconds, "raw": raw, "verified": verified}
        if args.mapper:
            results[name]["model"] = map_and_score(database, args.image_path, args.gt_cameras,
                                                   os.path.join(args.work, name + "_map"))
        print("done: %s %.1f s, %.1f CPU s (load %.1f)" % (name, seconds, cpu_seconds, os.getloadavg()[0]),
              flush=True)
    reference = results.get(args.reference, {}).get("verified", {})
    header = "| run | seconds | CPU seconds | verified pairs | of %s's %d verified, also verified | inlier matches | raw matches |" % (
        args.reference, len(reference))
    if args.mapper:
        header += " registered | position error median / max | rotation error median (deg) |"
    print(header)
    print("|---" * (header.count("|") - 1) + "|")
    for config in configs:
        name = config.partition("=")[0]
        if name not in results:
            continue
        r = results[name]
        both = sum(1 for p in reference if p in r["verified"])
        row = "| %s | %.1f | %.1f | %d | %d (%.1f %%) | %d | %d |" % (
            name, r["seconds"], r["cpu_seconds"], len(r["verified"]), both, 100.0 * both / max(1, len(reference)),
            sum(r["verified"].values()), r["raw"])
        if args.mapper:
            m = r["model"]
            if "position_median" in m:
                row += " %d | %.4f / %.4f | %.3f |" % (m["registered"], m["position_median"], m["position_max"],
                                                      m["rotation_median_deg"])
            else:
                row += " %d | | |" % m["registered"]
        print(row)


if __name__ == "__main__":
    main()
