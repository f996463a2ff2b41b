#!/usr/bin/env python3
"""Recall of `cashash retrieval_matcher` against exhaustive matching.

For each set: features are extracted with COLMAP (CPU SIFT, 1,600 px) into
WORK/<set>.db, matched exhaustively by cashash into WORK/<set>.exh.db, and
by `cashash retrieval_matcher` with num_images = a third of the images (at
most 50) into WORK/<set>.retr.db; files that exist are reused. The street
(`cashash generate_database`, 1,000 x 1,024 features from herzjesu-P25's
descriptors) is matched "exhaustively" over every pair at most 40 images
apart plus 2,000 random farther pairs: its images share points with about
ten neighbours on either side and no farther one (synthetic_street_scene.h),
so no other pair can verify; the far sample checks that.

Prints a markdown table: pairs matched (and their share of all pairs), the
pairs exhaustive matching verified with >= 50 and >= 15 inliers, the share
of each that retrieval verified, and the best share any choice of
num_images neighbours per image could reach (each image's num_images pairs
with most exhaustive inliers, united).

With --mapper 1, `colmap mapper` (defaults, 2 threads) reconstructs both
databases of every set that has Strecha ground truth (DATA/<set>/
gt_dense_cameras: fountain-P11, herzjesu-P25), --mapper_runs times each
(the mapper is random), and a second table gives per run and matcher the
pairs matched, the verified pairs, the registered images, the points and
the median / max camera centre error in mm after similarity alignment of
the largest model to the ground truth (scripts/eval/cameras.py, as
docs/ACCURACY.md), with retrieval's errors over exhaustive's.

    scripts/eval/retrieval_recall.py --cashash build-cpu/colmap_bridge/cashash \\
        --data ../shared/data --work /tmp/retrieval_eval [--sets herzjesu-P25,street] [--mapper 1]
"""
import argparse
import os
import random
import shutil
import sqlite3
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # scripts/, for eval.cameras

PF = 2147483647
REAL_SETS = ["fountain-P11", "herzjesu-P25", "sceaux_castle", "sacre_coeur"]


def matched_copy(source, target, command, log):
    """Copies source to target and runs command on it, once: a marker file
    says it finished (a stopped run is redone from a fresh copy)."""
    if os.path.exists(target + ".done"):
        return
    for suffix in ("", "-wal", "-shm"):
        if os.path.exists(target + suffix):
            os.remove(target + suffix)
    shutil.copy(source, target)
    run(command, log)
    open(target + ".done", "w").close()


def run(command, log):
    with open(log, "w") as out:
        subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, check=True)


def images(db):
    con = sqlite3.connect("file:%s?mode=ro" % db, uri=True)
    rows = con.execute("SELECT image_id, name FROM images ORDER BY image_id").fetchall()
    con.close()
    return rows


def inliers(db):
    con = sqlite3.connect("file:%s?mode=ro" % db, uri=True)
    out = {pid: rows or 0 for pid, rows in con.execute("SELECT pair_id, rows FROM two_view_geometries")}
    tried = {pid for (pid,) in con.execute("SELECT pair_id FROM matches")}
    con.close()
    return out, tried


def prepare_real(args, name):
    db = os.path.join(args.work, name + ".db")
    if not os.path.exists(db):
        images_path = os.path.join(args.data, name, "images")
        command = [args.colmap, "feature_extractor", "--database_path", db, "--image_path", images_path,
                   "--SiftExtraction.use_gpu", "0", "--SiftExtraction.max_image_size", "1600"]
        # sacre_coeur's photographs differ in size: one camera each there.
        if name != "sacre_coeur":
            command += ["--ImageReader.single_camera", "1"]
        run(command, db + ".extract.log")
    exh = os.path.join(args.work, name + ".exh.db")
    matched_copy(db, exh, [args.cashash, "exhaustive_matcher", "--database_path", exh, "--FeatureMatching.use_gpu", "0"],
                 exh + ".log")
    return db, exh


def prepare_street(args):
    db = os.path.join(args.work, "street.db")
    if not os.path.exists(db):
        source, _ = prepare_real(args, "herzjesu-P25")
        run([args.cashash, "generate_database", "--database_path", db, "--source_database_path", source,
             "--num_images", "1000", "--num_features", "1024"], db + ".log")
    exh = os.path.join(args.work, "street.exh.db")
    if not os.path.exists(exh + ".done"):
        ids = [image_id for image_id, _ in images(db)]
        names = dict(images(db))
        pairs = set()
        for a in range(len(ids)):
            for b in range(a + 1, min(len(ids), a + 41)):
                pairs.add((ids[a], ids[b]))
        rng = random.Random(1)
        far = 0
        while far < 2000:
            a, b = sorted(rng.sample(range(len(ids)), 2))
            if b - a > 40 and (ids[a], ids[b]) not in pairs:
                pairs.add((ids[a], ids[b]))
                far += 1
        pair_list = os.path.join(args.work, "street.band.txt")
        with open(pair_list, "w") as out:
            for a, b in sorted(pairs):
                out.write("%s %s\n" % (names[a], names[b]))
        matched_copy(db, exh, [args.cashash, "matches_importer", "--database_path", exh, "--match_list_path",
                               pair_list, "--match_type", "pairs", "--FeatureMatching.use_gpu", "0"], exh + ".log")
    return db, exh


def oracle_recall(ids, truth, k, threshold):
    """Best share of the pairs with >= threshold inliers that k pairs per image can reach."""
    by_image = {i: [] for i in ids}
    for pid, rows in truth.items():
        a, b = pid // PF, pid % PF
        by_image[a].append((rows, b))
        by_image[b].append((rows, a))
    chosen = set()
    for i, partners in by_image.items():
        for rows, j in sorted(partners, key=lambda x: (-x[0], x[1]))[:k]:
            chosen.add(min(i, j) * PF + max(i, j))
    wanted = {pid for pid, rows in truth.items() if rows >= threshold}
    return len(wanted & chosen) / max(len(wanted), 1)


def evaluate(args, name, db, exh):
    ids = [image_id for image_id, _ in images(db)]
    n = len(ids)
    k = min(50, n // 3)
    retr = os.path.join(args.work, name + ".retr.db")
    matched_copy(db, retr, [args.cashash, "retrieval_matcher", "--database_path", retr, "--FeatureMatching.use_gpu", "0",
                            "--VocabTreeMatching.num_images", str(k)] + args.extra, retr + ".log")
    truth, _ = inliers(exh)
    got, tried = inliers(retr)
    all_pairs = n * (n - 1) // 2
    row = [name, str(n), str(k), "%d (%.1f %%)" % (len(tried), 100.0 * len(tried) / all_pairs)]
    for threshold in (50, 15):
        wanted = {pid for pid, rows in truth.items() if rows >= threshold}
        found = {pid for pid in wanted if got.get(pid, 0) >= args.min_inliers}
        row.append("%d of %d (%.1f %%)" % (len(found), len(wanted), 100.0 * len(found) / max(len(wanted), 1)))
        row.append("%.1f %%" % (100.0 * oracle_recall(ids, truth, k, threshold)))
    extra = {pid for pid, rows in got.items() if rows >= args.min_inliers and truth.get(pid, 0) < args.min_inliers}
    row.append(str(len(extra)))
    return row


def camera_rows(args, name, runs):
    """Maps the exhaustive and the retrieval database of a set with ground
    truth; returns the rows of the camera table (one per run and matcher)."""
    from eval import cameras
    scene_dir = os.path.join(args.data, name)
    databases = [("exhaustive", os.path.join(args.work, name + ".exh.db")),
                 ("retrieval", os.path.join(args.work, name + ".retr.db"))]
    counts = {}  # the databases do not change between mapper runs
    for matcher, db in databases:
        got, tried = inliers(db)
        counts[matcher] = (len(tried), sum(1 for rows_ in got.values() if rows_ >= args.min_inliers))
    rows = []
    for run_index in range(runs):
        errors = {}
        for matcher, db in databases:
            tried, verified = counts[matcher]
            work_dir = "%s.map%d" % (db[:-len(".db")], run_index + 1)
            s = cameras.map_and_align(scene_dir, db, work_dir, os.path.join(work_dir, "mapper.log"))
            errors[matcher] = (s.get("position_median"), s.get("position_max"))
            models = s["registered_per_model"]
            ratio = ""
            if matcher == "retrieval" and None not in errors["exhaustive"] + errors["retrieval"]:
                ratio = "%.3f / %.3f" % (errors["retrieval"][0] / errors["exhaustive"][0],
                                         errors["retrieval"][1] / errors["exhaustive"][1])
            rows.append([name, str(run_index + 1), matcher, str(tried), str(verified),
                         "%d / %d" % (s["registered"], s["gt_images"]),
                         str(len(models)) + ("" if len(models) == 1 else " (largest used: %s)" % models),
                         str(s["points3D"]),
                         "%.1f / %.1f" % (1000 * errors[matcher][0], 1000 * errors[matcher][1])
                         if errors[matcher][0] is not None else "n/a", ratio])
            print("mapped: %s run %d %s" % (name, run_index + 1, matcher), file=sys.stderr)
    return rows


def print_table(header, rows):
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cashash", required=True)
    parser.add_argument("--colmap", default="colmap")
    parser.add_argument("--data", required=True, help="folder of the real sets (../shared/data)")
    parser.add_argument("--work", required=True, help="folder for the databases (reused when present)")
    parser.add_argument("--sets", default=",".join(REAL_SETS + ["street"]))
    parser.add_argument("--min_inliers", type=int, default=15)
    parser.add_argument("--mapper", type=int, choices=(0, 1), default=0,
                        help="also map both databases of the sets with DATA/<set>/gt_dense_cameras and "
                        "report camera errors")
    parser.add_argument("--mapper_runs", type=int, default=1, help="mapper runs per database (it is random)")
    parser.add_argument("extra", nargs="*", help="more retrieval_matcher options (after --)")
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)
    rows = []
    for name in args.sets.split(","):
        db, exh = prepare_street(args) if name == "street" else prepare_real(args, name)
        rows.append(evaluate(args, name, db, exh))
        print("done: " + name, file=sys.stderr)
    header = ["set", "images", "num_images", "pairs matched", ">= 50 inliers: verified", "best possible",
              ">= 15 inliers: verified", "best possible", "verified, not by exhaustive"]
    print_table(header, rows)
    if args.mapper:
        camera_table = []
        for name in args.sets.split(","):
            if name != "street" and os.path.isdir(os.path.join(args.data, name, "gt_dense_cameras")):
                camera_table += camera_rows(args, name, args.mapper_runs)
        header = ["set", "run", "matcher", "pairs matched", "verified pairs (>= %d inliers)" % args.min_inliers,
                  "registered", "models", "points", "centre error median / max (mm)",
                  "retrieval / exhaustive: median / max"]
        print()
        print_table(header, camera_table)


if __name__ == "__main__":
    main()
