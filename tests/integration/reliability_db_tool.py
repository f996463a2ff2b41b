#!/usr/bin/env python3
"""Writes a small COLMAP 3.8-style feature database with synthetic features,
for the reliability tests: no feature extraction, a second or two to build.

Random 3-D points are seen by cameras on a circle; every image gets the
projections of a random subset of the points as keypoints and, as
descriptors, perturbed copies of one SIFT-like vector per point. Images
sharing points therefore have real matches that verify geometrically.

Usage: reliability_make_database.py OUT.db [--images N] [--features K]
       [--points P] [--seed S] [--journal wal|delete]
"""
import argparse
import sqlite3

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


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("path")
    parser.add_argument("--images", type=int, default=60)
    parser.add_argument("--features", type=int, default=400)
    parser.add_argument("--points", type=int, default=600)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--journal", choices=["wal", "delete"], default="wal")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)

    points = rng.uniform(-1.0, 1.0, size=(args.points, 3))
    base_descriptors = sift_like(rng, args.points)

    con = sqlite3.connect(args.path)
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


if __name__ == "__main__":
    main()
