#!/usr/bin/env python3
"""Compares cashash's EstimateTwoViewGeometry with pycolmap's on synthetic pairs.

Writes each scene to a text file, times scripts/bench/two_view_geometry_bench
on it and pycolmap.estimate_two_view_geometry on the same points (one thread,
default options), and prints config, inlier count and mean time for both.

Usage: compare_two_view_geometry.py BENCH_BINARY [repeats]
"""
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import pycolmap

W, H, FOCAL = 1600, 1200, 1300.0


def make_scene(rng, num_inliers, outlier_ratio, planar, noise=0.5):
    K = np.array([[FOCAL, 0, W / 2], [0, FOCAL, H / 2], [0, 0, 1]])
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = 0.15
    Kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx
    t = np.array([1.0, 0.1, 0.05])
    p1, p2 = [], []
    while len(p1) < num_inliers:
        px = rng.uniform([0, 0], [W, H])
        ray = np.linalg.solve(K, np.array([px[0], px[1], 1.0]))
        depth = 6.0 / (1 - 0.3 * ray[0] - 0.2 * ray[1]) if planar else rng.uniform(4, 10)
        X2 = R @ (ray * depth) + t
        if X2[2] <= 0.1:
            continue
        q = K @ X2
        q = q[:2] / q[2]
        if not (0 <= q[0] < W and 0 <= q[1] < H):
            continue
        p1.append(px + rng.normal(0, noise, 2))
        p2.append(q + rng.normal(0, noise, 2))
    num_out = int(round(outlier_ratio / (1 - outlier_ratio) * num_inliers))
    p1 += list(rng.uniform([0, 0], [W, H], size=(num_out, 2)))
    p2 += list(rng.uniform([0, 0], [W, H], size=(num_out, 2)))
    order = rng.permutation(len(p1))
    return np.array(p1)[order], np.array(p2)[order]


def run_pycolmap(p1, p2, prior, repeats):
    cam = pycolmap.Camera(model="SIMPLE_PINHOLE", width=W, height=H,
                          params=[FOCAL, W / 2, H / 2])
    cam.has_prior_focal_length = prior
    matches = np.stack([np.arange(len(p1)), np.arange(len(p1))], 1).astype(np.uint32)
    opts = pycolmap.TwoViewGeometryOptions()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        g = pycolmap.estimate_two_view_geometry(cam, p1, cam, p2, matches, opts)
        times.append(time.perf_counter() - start)
    return 1000 * np.mean(times), int(g.config), len(g.inlier_matches)


def main():
    bench = sys.argv[1]
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    rng = np.random.default_rng(1)
    print(f"{'scene':38s} {'colmap cfg/inl/ms':>22s} {'cashash cfg/inl/ms':>22s}")
    for planar in (False, True):
        for prior in (False, True):
            for outlier_ratio in (0.3, 0.5):
                p1, p2 = make_scene(rng, 1000, outlier_ratio, planar)
                with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as f:
                    f.write(f"{W} {H} {FOCAL} {int(prior)}\n{len(p1)}\n")
                    for a, b in zip(p1, p2):
                        f.write(f"{a[0]:.6f} {a[1]:.6f} {b[0]:.6f} {b[1]:.6f}\n")
                    path = f.name
                out = subprocess.run([bench, path, str(repeats)], capture_output=True, text=True,
                                     check=True).stdout.split()
                os.unlink(path)
                ours = (int(out[3]), int(out[5]), float(out[1]))
                theirs = run_pycolmap(p1, p2, prior, repeats)
                name = (f"{'planar' if planar else 'general'} prior={int(prior)} "
                        f"n={len(p1)} out={outlier_ratio:.0%}")
                print(f"{name:38s} {theirs[1]:>5d} {theirs[2]:>6d} {theirs[0]:>8.1f}"
                      f" {ours[0]:>7d} {ours[1]:>6d} {ours[2]:>8.1f}")


if __name__ == "__main__":
    main()
