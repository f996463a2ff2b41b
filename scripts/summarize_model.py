#!/usr/bin/env python3
"""Summarises a COLMAP sparse reconstruction and optionally checks it.

Given the mapper's output folder (holding 0/, 1/, ...) or one model folder,
it picks the model with the most registered images, reads `colmap
model_analyzer`'s statistics and prints one summary. With --gt (a COLMAP text
model of the true cameras, as written by render_scene.py) it also aligns the
reconstructed camera centres to the true ones with a similarity transform and
reports rotation and position errors.

The --expect_* / --max_* options turn it into a check: it exits 1 when the
model misses any of them, which is how the end-to-end tests assert.
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

import numpy as np


def run_colmap(colmap, args):
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    proc = subprocess.run([colmap] + args, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"colmap {' '.join(args)} failed:\n{proc.stdout}")
    return proc.stdout


def analyze(colmap, model_dir):
    """model_analyzer's 'Name: value' lines as a dict of floats."""
    stats = {}
    for line in run_colmap(colmap, ["model_analyzer", "--path", model_dir]).splitlines():
        # glog may prefix lines with "I1122 02:53:00.000 file.cc:12] ".
        line = re.sub(r"^[IWE]\d{4} [^\]]*\] ", "", line.strip())
        m = re.match(r"^([A-Za-z ]+):\s*([-+0-9.eE]+)", line)
        if m:
            stats[m.group(1).strip().lower()] = float(m.group(2))
    return stats


def model_dirs(path):
    if os.path.exists(os.path.join(path, "images.bin")) or \
       os.path.exists(os.path.join(path, "images.txt")):
        return [path]
    subs = [os.path.join(path, d) for d in sorted(os.listdir(path)) if d.isdigit()]
    return [d for d in subs if os.path.exists(os.path.join(d, "images.bin"))]


def quaternion_to_rotation(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def read_images_txt(path):
    """name -> (R world-to-camera, camera centre)."""
    poses = {}
    with open(path) as f:
        lines = [l for l in f if not l.startswith("#")]
    # Every image takes two lines: the pose, then its 2-D points (maybe empty).
    for line in lines[0::2]:
        fields = line.split()
        if len(fields) < 10:
            continue
        q = np.array([float(v) for v in fields[1:5]])
        t = np.array([float(v) for v in fields[5:8]])
        R = quaternion_to_rotation(q)
        poses[fields[9]] = (R, -R.T @ t)
    return poses


def similarity_align(src, dst):
    """Scale s, rotation R, translation t minimising |s R src + t - dst|^2."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / (a ** 2).sum(1).mean()
    return s, R, mu_d - s * R @ mu_s


def compare_with_ground_truth(colmap, model_dir, gt_dir):
    with tempfile.TemporaryDirectory() as tmp:
        run_colmap(colmap, ["model_converter", "--input_path", model_dir,
                            "--output_path", tmp, "--output_type", "TXT"])
        est = read_images_txt(os.path.join(tmp, "images.txt"))
    gt = read_images_txt(os.path.join(gt_dir, "images.txt"))
    names = sorted(set(est) & set(gt))
    if len(names) < 3:
        return None
    src = np.array([est[n][1] for n in names])
    dst = np.array([gt[n][1] for n in names])
    s, R_align, t_align = similarity_align(src, dst)
    position_errors = np.linalg.norm((s * (R_align @ src.T)).T + t_align - dst, axis=1)
    rotation_errors = []
    for n in names:
        # World-to-camera rotations: R_est maps aligned world via R_align^T.
        R_rel = est[n][0] @ R_align.T @ gt[n][0].T
        cos = np.clip((np.trace(R_rel) - 1) / 2, -1, 1)
        rotation_errors.append(np.degrees(np.arccos(cos)))
    scene_size = np.linalg.norm(dst - dst.mean(0), axis=1).mean()
    return {"max rotation error deg": float(np.max(rotation_errors)),
            "max position error": float(position_errors.max()),
            "max position error relative": float(position_errors.max() / scene_size)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sparse_dir")
    parser.add_argument("--colmap", default=os.environ.get("COLMAP", "colmap"))
    parser.add_argument("--num_images", type=int, help="images in the data set")
    parser.add_argument("--gt", help="folder with the true cameras as a COLMAP text model")
    parser.add_argument("--expect_registered", type=int)
    parser.add_argument("--max_reprojection_error", type=float)
    parser.add_argument("--max_rotation_error_deg", type=float)
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object instead of the summary")
    args = parser.parse_args()

    models = model_dirs(args.sparse_dir)
    if not models:
        if args.json:
            print(json.dumps({"model": None, "num_models": 0, "registered": 0, "points": 0,
                              "mean_track_length": None, "mean_reprojection_error": None}))
        print(f"FAIL: no reconstruction in {args.sparse_dir}")
        return 1
    analysed = [(analyze(args.colmap, m), m) for m in models]
    stats, best = max(analysed, key=lambda sm: sm[0].get("registered images", 0))
    registered = int(stats.get("registered images", 0))
    if args.json:
        print(json.dumps({"model": best, "num_models": len(models), "registered": registered,
                          "points": int(stats.get("points", 0)),
                          "mean_track_length": stats.get("mean track length"),
                          "mean_reprojection_error": stats.get("mean reprojection error")}))
        return 0
    total = f"/{args.num_images}" if args.num_images else ""
    print(f"Model:                     {best} ({len(models)} model(s) in all)")
    print(f"Registered images:         {registered}{total}")
    print(f"3-D points:                {int(stats.get('points', 0))}")
    print(f"Mean track length:         {stats.get('mean track length', float('nan')):.3f}")
    print(f"Mean reprojection error:   {stats.get('mean reprojection error', float('nan')):.3f} px")

    failures = []
    if args.gt:
        errors = compare_with_ground_truth(args.colmap, best, args.gt)
        if errors is None:
            failures.append("too few images to compare with the ground truth")
        else:
            print(f"Max rotation error vs GT:  {errors['max rotation error deg']:.3f} deg")
            print(f"Max centre error vs GT:    {errors['max position error']:.4f} "
                  f"({100 * errors['max position error relative']:.2f} % of the scene radius)")
            if args.max_rotation_error_deg is not None and \
               errors["max rotation error deg"] > args.max_rotation_error_deg:
                failures.append(f"rotation error {errors['max rotation error deg']:.3f} deg "
                                f"> {args.max_rotation_error_deg}")
    if args.expect_registered is not None and registered < args.expect_registered:
        failures.append(f"{registered} images registered, expected {args.expect_registered}")
    error = stats.get("mean reprojection error", float("inf"))
    if args.max_reprojection_error is not None and not error < args.max_reprojection_error:
        failures.append(f"mean reprojection error {error} px >= {args.max_reprojection_error}")
    for failure in failures:
        print(f"FAIL: {failure}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
