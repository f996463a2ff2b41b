#!/usr/bin/env python3
"""COLMAP's exhaustive matcher (pycolmap's match_exhaustive, on the GPU when
pycolmap has CUDA) on DB, timed; prints one row of end_to_end_bench.sh's
table. With LIMIT > 0 the matcher is killed after LIMIT seconds and the
rate counts the pairs it committed up to its last database write.
MAX_NUM_MATCHES > 0 sets FeatureMatching.max_num_matches (COLMAP's default
otherwise).

  colmap_exhaustive_timed.py DB [LIMIT [MAX_NUM_MATCHES]]
"""
import multiprocessing as mp
import os
import sqlite3
import sys
import time


def match(db, max_num_matches):
    import pycolmap
    options = pycolmap.FeatureMatchingOptions()
    if max_num_matches > 0:
        options.max_num_matches = max_num_matches
    options.use_gpu = bool(pycolmap.has_cuda)
    if options.use_gpu:
        options.gpu_index = "0"
    device = pycolmap.Device.cuda if pycolmap.has_cuda else pycolmap.Device.cpu
    pycolmap.match_exhaustive(db, matching_options=options, device=device)


def main():
    db = sys.argv[1]
    limit = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
    max_num_matches = int(sys.argv[3]) if len(sys.argv) > 3 else 0
    import pycolmap
    label = f"COLMAP {pycolmap.__version__} match_exhaustive ({'GPU' if pycolmap.has_cuda else 'CPU'})"
    if max_num_matches > 0:
        label += f", max_num_matches {max_num_matches}"
    start = time.time()
    process = mp.get_context("spawn").Process(target=match, args=(db, max_num_matches))
    process.start()
    process.join(limit if limit > 0 else None)
    stopped = process.is_alive()
    if stopped:
        process.kill()
        process.join()
    end = time.time()
    busy = end - start
    if stopped:
        # The block being matched when it was killed is lost: rate up to the
        # last write of the database.
        busy = max(os.path.getmtime(f) for f in (db, db + "-wal") if os.path.exists(f)) - start
        label += f", stopped after {limit:.0f} s"
    elif process.exitcode != 0:
        label += f", exit {process.exitcode}"
    c = sqlite3.connect(db)
    pairs = c.execute("SELECT COUNT(*) FROM two_view_geometries").fetchone()[0]
    raw = c.execute("SELECT COALESCE(SUM(rows), 0) FROM matches").fetchone()[0]
    verified, inliers = c.execute(
        "SELECT COUNT(*), COALESCE(SUM(rows), 0) FROM two_view_geometries WHERE config >= 2").fetchone()
    rate = pairs / busy if busy > 0 else 0.0
    print(f"| {label} | {end - start:.2f} | {pairs:,} | {rate:,.0f} | | | | | | | {raw:,} | {verified:,} | {inliers:,} |")


if __name__ == "__main__":
    main()
