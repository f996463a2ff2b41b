#!/usr/bin/env python3
"""How ambiguous are the inliers that guided matching adds over exhaustive matching?

  scripts/bench/guided_match_ambiguity.py EXHAUSTIVE.db GUIDED.db

Both databases hold the same features, one matched by `cashash
exhaustive_matcher`, the other by `cashash guided_matcher`. For every pair
that both verify, the guided inlier matches that exhaustive matching does
not have are compared with the whole second image, by exact descriptor
angle (COLMAP's distance): is the matched feature the query's nearest
neighbour in the whole image, and would it pass the ratio test (0.8) there?
A match that only the epipolar band makes unambiguous fails both; the band
cannot tell it from the right one when it lies on the same epipolar line.
"""
import sqlite3
import sys

import numpy as np

PAIR_ID_FACTOR = 2147483647


def two_view_inliers(path):
    conn = sqlite3.connect("file:%s?mode=ro" % path, uri=True)
    out = {}
    for pid, rows, cols, data in conn.execute("SELECT pair_id, rows, cols, data FROM two_view_geometries"):
        if rows and data:
            out[pid] = np.frombuffer(data, np.uint32).reshape(rows, cols)
    conn.close()
    return out


def descriptors(path, image_id):
    conn = sqlite3.connect("file:%s?mode=ro" % path, uri=True)
    rows, cols, data = conn.execute("SELECT rows, cols, data FROM descriptors WHERE image_id = ?",
                                    (image_id,)).fetchone()
    conn.close()
    return np.frombuffer(data, np.uint8).reshape(rows, cols).astype(np.float32) / 512.0


def main(argv):
    if len(argv) != 3:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    exhaustive, guided = two_view_inliers(argv[1]), two_view_inliers(argv[2])
    print("| pair | exhaustive inliers | guided inliers | guided only | global nearest neighbour | "
          "global ratio < 0.8 | median global ratio |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    total = nearest = unambiguous = 0
    for pid in sorted(set(exhaustive) & set(guided)):
        a, b = exhaustive[pid], guided[pid]
        if len(a) < 15 or len(b) < 15:
            continue
        known = set(map(tuple, a.tolist()))
        only = np.array([m for m in map(tuple, b.tolist()) if m not in known], dtype=np.int64).reshape(-1, 2)
        if not len(only):
            continue
        image1, image2 = pid // PAIR_ID_FACTOR, pid % PAIR_ID_FACTOR
        d1, d2 = descriptors(argv[2], image1), descriptors(argv[2], image2)
        angles = np.arccos(np.clip(d1[only[:, 0]] @ d2.T, -1.0, 1.0))
        rows = np.arange(len(only))
        matched = angles[rows, only[:, 1]].copy()
        is_nearest = matched <= angles.min(axis=1) + 1e-6
        angles[rows, only[:, 1]] = np.inf
        ratio = matched / angles.min(axis=1)
        total += len(only)
        nearest += int(is_nearest.sum())
        unambiguous += int((ratio < 0.8).sum())
        print("| %d-%d | %d | %d | %d | %.2f | %.2f | %.2f |" % (image1, image2, len(a), len(b), len(only),
                                                                is_nearest.mean(), (ratio < 0.8).mean(),
                                                                np.median(ratio)))
    if total:
        print("\nAll pairs: %d guided-only inliers; %.1f %% are their query's nearest neighbour in the whole image, "
              "%.1f %% pass the ratio test there." % (total, 100.0 * nearest / total, 100.0 * unambiguous / total))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
