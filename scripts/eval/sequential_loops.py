#!/usr/bin/env python3
"""Does sequential loop detection close the loops of a street that returns
to its start?

  sequential_loops.py --cashash build-cpu/colmap_bridge/cashash --source_database sceaux7.db
                      [--work_dir DIR] [--num_images 200] [--revisit_images 20]
                      [--num_features 256] [--overlap 10]

Generates a street whose last K images drive its first K places again
(`generate_database --revisit_images K`), then runs `cashash
sequential_matcher --SequentialMatching.overlap O` on copies of it: without
loop detection, with COLMAP's loop defaults (every 10th image queries 50),
and with every 5th image querying 10. A loop-closing pair joins a revisiting
image (index >= N - K) and a first-drive image at most 10 places from where
it stands; a false closure is a verified pair across the loop farther apart
than that (the street shares no points past about ten places). Prints a
Markdown table.
"""
import argparse
import os
import shutil
import sqlite3
import subprocess
import tempfile

MAX_IMAGE_ID = 2147483647
NEAR_PLACES = 10

RUNS = [
    ("none", []),
    ("period 10, 50 images (COLMAP's defaults)", ["--SequentialMatching.loop_detection", "1"]),
    ("period 5, 10 images", ["--SequentialMatching.loop_detection", "1",
                             "--SequentialMatching.loop_detection_period", "5",
                             "--SequentialMatching.loop_detection_num_images", "10"]),
]


def pairs_of(database):
    """(matched pairs, verified pairs) as sets of (index1, index2) in name order."""
    with sqlite3.connect(database) as db:
        names = sorted(db.execute("SELECT image_id, name FROM images"), key=lambda row: row[1])
        index = {image_id: i for i, (image_id, _) in enumerate(names)}
        def split(pair_id):
            a, b = divmod(pair_id, MAX_IMAGE_ID)
            return tuple(sorted((index[a], index[b])))
        matched = {split(p) for (p,) in db.execute("SELECT pair_id FROM matches")}
        verified = {split(p) for (p,) in db.execute("SELECT pair_id FROM two_view_geometries WHERE config >= 2")}
    return matched, verified


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cashash", required=True)
    parser.add_argument("--source_database", required=True, help="a COLMAP database with SIFT features")
    parser.add_argument("--work_dir", default=None)
    parser.add_argument("--num_images", type=int, default=200)
    parser.add_argument("--revisit_images", type=int, default=20)
    parser.add_argument("--num_features", type=int, default=256)
    parser.add_argument("--overlap", type=int, default=10)
    args = parser.parse_args()
    work = args.work_dir or tempfile.mkdtemp(prefix="cashash_loops_")
    os.makedirs(work, exist_ok=True)
    n, k = args.num_images, args.revisit_images
    places = n - k
    street = os.path.join(work, "street.db")
    for suffix in ("", "-wal", "-shm"):
        if os.path.exists(street + suffix):
            os.remove(street + suffix)
    subprocess.run([args.cashash, "generate_database", "--database_path", street, "--source_database_path",
                    args.source_database, "--num_images", str(n), "--num_features", str(args.num_features),
                    "--revisit_images", str(k)], check=True, stdout=subprocess.DEVNULL)

    def place(i):
        return i if i < places else i - places

    def across(pair):  # one image of the first drive, one revisiting
        return (pair[0] < places) != (pair[1] < places)

    def closes(pair):
        return across(pair) and abs(place(pair[0]) - place(pair[1])) <= NEAR_PLACES

    print(f"Street: {n} images, the last {k} back at the start, {args.num_features} features; "
          f"sequential_matcher --SequentialMatching.overlap {args.overlap}")
    print()
    print("| loop detection | pairs matched | verified | loop-closing pairs matched / verified "
          "| revisiting images with a verified loop pair | false closures |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, options in RUNS:
        copy = os.path.join(work, "run.db")
        shutil.copy(street, copy)
        subprocess.run([args.cashash, "sequential_matcher", "--database_path", copy,
                        "--SequentialMatching.overlap", str(args.overlap)] + options,
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        matched, verified = pairs_of(copy)
        closing_matched = {p for p in matched if closes(p)}
        closing_verified = {p for p in verified if closes(p)}
        closed = {i for p in closing_verified for i in p if i >= places}
        false = {p for p in verified if across(p) and not closes(p)}
        print(f"| {name} | {len(matched):,} | {len(verified):,} | {len(closing_matched)} / {len(closing_verified)} "
              f"| {len(closed)} of {k} | {len(false)} |")
        os.remove(copy)


if __name__ == "__main__":
    main()
