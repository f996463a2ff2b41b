#!/usr/bin/env python3
"""Helpers of the reliability tests (tests/integration/reliability_*.sh).

  make OUT.db [--images N] [--features K] ...   synthetic feature database
  check DB [--pairs N] [--block_size B]
                           integrity_check ok, matches and two_view_geometries
                           hold the same pairs, no more than N of them; with
                           B, every pair of blocks of B images (an exhaustive
                           run's chunk) is there whole or not at all
  compare DB REF           same rows (pair_id and every column) in both tables
  count DB                 prints the number of matches rows
  watch DB PIDFILE         reads DB while the process in PIDFILE writes it;
                           fails if any read fails or sees half a chunk

`make` writes a small COLMAP 3.8-style database with synthetic features: no
feature extraction, a second or two to build.

Random 3-D points are seen by cameras on a circle; every image gets the
projections of a random subset of the points as keypoints and, as
descriptors, perturbed copies of one SIFT-like vector per point. Images
sharing points therefore have real matches that verify geometrically.

"""
import argparse
import os
import sqlite3
import sys
import time

import numpy as np

WIDTH, HEIGHT, FOCAL = 1000, 800, 800.0

SCHEMA = """
CREATE TABLE cameras(camera_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL,
  model INTEGER NOT NULL, width INTEGER NOT NULL, height INTEGER NOT NULL,
  params BLOB, prior_focal_length INTEGER NOT NULL);
CREATE TABLE images(image_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL,
  name TEXT NOT NULL UNIQUE, camera_id INTEGER NOT NULL,
  prior_qw REAL, prior_qx REAL, prior_qy REAL, prior_qz REAL,
  prior_tx REAL, prior_ty REAL, prior_tz REAL,
  CONSTRAINT image_id_check CHECK(image_id >= 0 and image_id < 2147483647),
  FOREIGN KEY(camera_id) REFERENCES cameras(camera_id));
CREATE TABLE keypoints(image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL,
  cols INTEGER NOT NULL, data BLOB,
  FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE);
CREATE TABLE descriptors(image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL,
  cols INTEGER NOT NULL, data BLOB,
  FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE);
CREATE TABLE matches(pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL,
  cols INTEGER NOT NULL, data BLOB);
CREATE TABLE two_view_geometries(pair_id INTEGER PRIMARY KEY NOT NULL,
  rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB, config INTEGER NOT NULL,
  F BLOB, E BLOB, H BLOB, qvec BLOB, tvec BLOB);
CREATE UNIQUE INDEX index_name ON images(name);
"""


def sift_like(rng, count):
    """uint8 x 128 vectors with COLMAP's scaling: norm about 512."""
    v = rng.gamma(0.6, 1.0, size=(count, 128))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return np.minimum(np.round(512 * v), 255)


def look_at(center, target):
    """World-to-camera rotation of a camera at `center` looking at `target`."""
    z = target - center
    z /= np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def make(args):
    rng = np.random.default_rng(args.seed)

    points = rng.uniform(-1.0, 1.0, size=(args.points, 3))
    base_descriptors = sift_like(rng, args.points)

    con = sqlite3.connect(args.path)
    con.execute(f"PRAGMA page_size={args.page_size}")
    con.executescript(SCHEMA)
    con.execute(f"PRAGMA journal_mode={args.journal}")
    con.execute("PRAGMA user_version=3800")
    params = np.array([FOCAL, WIDTH / 2, HEIGHT / 2, 0.0], dtype=np.float64)
    con.execute("INSERT INTO cameras VALUES (1, 2, ?, ?, ?, 0)", (WIDTH, HEIGHT, params.tobytes()))

    for i in range(args.images):
        # Cameras on a 90-degree arc at distance 4, all looking at the origin.
        angle = np.deg2rad(90.0 * i / max(args.images - 1, 1) - 45.0)
        center = np.array([4 * np.sin(angle), 0.3 * np.cos(3 * angle), -4 * np.cos(angle)])
        R = look_at(center, np.zeros(3))
        cam = (points - center) @ R.T
        uv = FOCAL * cam[:, :2] / cam[:, 2:3] + np.array([WIDTH / 2, HEIGHT / 2])
        visible = np.flatnonzero((uv[:, 0] > 1) & (uv[:, 0] < WIDTH - 1) &
                                 (uv[:, 1] > 1) & (uv[:, 1] < HEIGHT - 1))
        chosen = rng.choice(visible, size=min(args.features, len(visible)), replace=False)
        xy = uv[chosen] + rng.normal(0.0, 0.3, size=(len(chosen), 2))
        keypoints = np.zeros((len(chosen), 6), dtype=np.float32)
        keypoints[:, :2] = xy
        keypoints[:, 2] = keypoints[:, 5] = 2.0  # isotropic scale, no rotation
        noisy = base_descriptors[chosen] + rng.normal(0.0, 6.0, size=(len(chosen), 128))
        descriptors = np.clip(np.round(noisy), 0, 255).astype(np.uint8)
        image_id = i + 1
        con.execute("INSERT INTO images(image_id, name, camera_id) VALUES (?, ?, 1)",
                    (image_id, f"image_{image_id:03d}.png"))
        con.execute("INSERT INTO keypoints VALUES (?, ?, 6, ?)",
                    (image_id, len(chosen), keypoints.tobytes()))
        con.execute("INSERT INTO descriptors VALUES (?, ?, 128, ?)",
                    (image_id, len(chosen), descriptors.tobytes()))
    con.commit()
    con.close()


def fail(message):
    print(f"FAIL: {message}", file=sys.stderr)
    sys.exit(1)


def pair_ids(con, table):
    return {row[0] for row in con.execute(f"SELECT pair_id FROM {table}")}


def check(args):
    con = sqlite3.connect(args.path, timeout=60)
    integrity = con.execute("PRAGMA integrity_check").fetchone()[0]
    if integrity != "ok":
        fail(f"{args.path}: integrity_check says {integrity}")
    matches, geometries = pair_ids(con, "matches"), pair_ids(con, "two_view_geometries")
    if matches != geometries:
        fail(f"{args.path}: {len(matches ^ geometries)} pairs have a row in one table only")
    if args.pairs is not None and len(matches) > args.pairs:
        fail(f"{args.path}: {len(matches)} pairs, more than {args.pairs}")
    chunks = ""
    if args.block_size:
        # Blocks of images in image_id order; pair_id = id1 * 2147483647 + id2.
        ids = [row[0] for row in con.execute("SELECT image_id FROM images ORDER BY image_id")]
        block = {image_id: k // args.block_size for k, image_id in enumerate(ids)}
        present, total = {}, {}
        for a in range(len(ids)):
            for b in range(a + 1, len(ids)):
                key = (block[ids[a]], block[ids[b]])
                total[key] = total.get(key, 0) + 1
        for pair_id in matches:
            key = (block[pair_id // 2147483647], block[pair_id % 2147483647])
            present[key] = present.get(key, 0) + 1
        partial = [key for key, n in present.items() if n != total[key]]
        if partial:
            fail(f"{args.path}: {len(partial)} block pairs are partly written, e.g. {partial[0]} with "
                 f"{present[partial[0]]} of {total[partial[0]]} pairs")
        chunks = f", {len(present)} whole block pairs of {len(total)}"
    print(f"{args.path}: integrity ok, {len(matches)} pairs in both tables{chunks}")


def rows(con, table):
    return sorted(con.execute(f"SELECT * FROM {table}").fetchall())


def compare(args):
    con, ref = sqlite3.connect(args.path), sqlite3.connect(args.reference)
    for table in ("matches", "two_view_geometries"):
        a, b = rows(con, table), rows(ref, table)
        if a != b:
            keys_a, keys_b = {r[0] for r in a}, {r[0] for r in b}
            differ = sum(1 for x, y in zip(a, b) if x != y)
            fail(f"{table}: {len(a)} rows vs {len(b)} in the reference, "
                 f"{len(keys_a ^ keys_b)} pair_ids in one only, {differ} rows differ")
    print(f"{args.path}: same matches and two_view_geometries rows as {args.reference} "
          f"({len(rows(con, 'matches'))} pairs)")


def count(args):
    con = sqlite3.connect(args.path, timeout=60)
    print(con.execute("SELECT COUNT(*) FROM matches").fetchone()[0])


def watch(args):
    """A concurrent reader: every snapshot must be readable and hold whole
    chunks (a pair in matches is in two_view_geometries too) and counts never
    go down."""
    last, reads = 0, 0
    while True:
        alive = os.path.exists(args.pidfile)
        if alive:
            try:
                os.kill(int(open(args.pidfile).read()), 0)
            except (OSError, ValueError):
                alive = False
        con = sqlite3.connect(f"file:{args.path}?mode=ro", uri=True, timeout=60)
        try:
            con.execute("BEGIN")  # one snapshot for both reads
            matches = pair_ids(con, "matches")
            geometries = pair_ids(con, "two_view_geometries")
            con.execute("COMMIT")
        except sqlite3.Error as error:
            fail(f"reader: {error}")
        finally:
            con.close()
        reads += 1
        if matches != geometries:
            fail(f"reader saw a half-written chunk: {len(matches)} vs {len(geometries)} rows")
        if len(matches) < last:
            fail(f"reader saw the row count go down from {last} to {len(matches)}")
        last = len(matches)
        if not alive:
            break
        time.sleep(0.05)
    print(f"reader: {reads} consistent snapshots, last one {last} pairs")


def main():
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("make")
    p.add_argument("path")
    p.add_argument("--images", type=int, default=60)
    p.add_argument("--features", type=int, default=400)
    p.add_argument("--points", type=int, default=600)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--journal", choices=["wal", "delete"], default="wal")
    p.add_argument("--page_size", type=int, default=4096)
    p = sub.add_parser("check")
    p.add_argument("path")
    p.add_argument("--pairs", type=int)
    p.add_argument("--block_size", type=int)
    p = sub.add_parser("compare")
    p.add_argument("path")
    p.add_argument("reference")
    p = sub.add_parser("count")
    p.add_argument("path")
    p = sub.add_parser("watch")
    p.add_argument("path")
    p.add_argument("pidfile")
    args = parser.parse_args()
    {"make": make, "check": check, "compare": compare, "count": count, "watch": watch}[args.command](args)


if __name__ == "__main__":
    main()
