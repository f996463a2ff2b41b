"""Homography ground truth: Oxford affine sequences and HPatches v_graffiti.

Each sequence has six images; H1toN maps pixel coordinates of image 1 to
image N. Images are converted to PNG with Pillow (the PPM/PGM headers carry
'#' comments and boat is greyscale), SIFT features are extracted once per
sequence with COLMAP, and every matcher then writes its raw matches for the
pairs 1-2 ... 1-6 into its own copy of that database.
"""
import os

import numpy as np
from PIL import Image

from eval import colmap_db, tools

OXFORD = ["graf", "boat", "bikes", "leuven"]
PAIRS = [(1, n) for n in range(2, 7)]


def sequences(data_dir):
    """[(name, folder, image paths 1..6, {n: H1toN})] for the sequences present."""
    found = []
    for name in OXFORD:
        folder = os.path.join(data_dir, "oxford_affine", name)
        if not os.path.isdir(folder):
            continue
        images = []
        for i in range(1, 7):
            for ext in ("ppm", "pgm", "png", "jpg"):
                path = os.path.join(folder, "img%d.%s" % (i, ext))
                if os.path.exists(path):
                    images.append(path)
                    break
        hs = {n: np.loadtxt(os.path.join(folder, "H1to%dp" % n)) for n in range(2, 7)}
        found.append((name, folder, images, hs))
    folder = os.path.join(data_dir, "hpatches_v_graffiti", "v_graffiti")
    if os.path.isdir(folder):
        images = [os.path.join(folder, "%d.ppm" % i) for i in range(1, 7)]
        hs = {n: np.loadtxt(os.path.join(folder, "H_1_%d" % n)) for n in range(2, 7)}
        found.append(("hpatches_v_graffiti", folder, images, hs))
    return found


def prepare_images(image_paths, png_dir):
    """Writes img1.png ... img6.png (RGB) into png_dir."""
    os.makedirs(png_dir, exist_ok=True)
    for i, path in enumerate(image_paths, start=1):
        target = os.path.join(png_dir, "img%d.png" % i)
        if not os.path.exists(target):
            Image.open(path).convert("RGB").save(target)


def extract_features(png_dir, database, log):
    """COLMAP CPU SIFT with default settings, one camera per image."""
    if os.path.exists(database):
        return
    tools.run_tool(["colmap", "feature_extractor", "--database_path", database, "--image_path", png_dir,
                    "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", "2"], log)


def write_pair_list(path):
    with open(path, "w") as out:
        for a, b in PAIRS:
            out.write("img%d.png img%d.png\n" % (a, b))


def reprojection_errors(h, points1, points2):
    """|H x1 - x2| in pixels. Inputs are COLMAP keypoints (pixel centre at
    0.5); the Oxford homographies use pixel centres at integer coordinates."""
    p1 = np.hstack([points1 - 0.5, np.ones((len(points1), 1))])
    mapped = p1 @ h.T
    mapped = mapped[:, :2] / mapped[:, 2:3]
    return np.linalg.norm(mapped - (points2 - 0.5), axis=1)


def evaluate_database(database, hs, eps_list):
    """Per pair: raw match count, correct count per eps, and the matches themselves."""
    db = colmap_db.Database(database)
    ids = db.image_ids_by_name()
    result = {}
    for a, b in PAIRS:
        id1, id2 = ids["img%d.png" % a], ids["img%d.png" % b]
        matches = db.raw_matches(id1, id2)
        k1, k2 = db.keypoints(id1), db.keypoints(id2)
        errors = reprojection_errors(hs[b], k1[matches[:, 0]], k2[matches[:, 1]]) if len(matches) else np.zeros(0)
        result["%d-%d" % (a, b)] = {
            "matches": int(len(matches)),
            "correct": {str(eps): int((errors <= eps).sum()) for eps in eps_list},
            "pairs": matches,
            "errors": errors,
        }
    db.close()
    return result


def ground_truth_reachable(database, hs, eps):
    """Per pair: how many keypoints of image 1 have a keypoint of image N within
    eps of their projection (an upper bound on correct one-to-one matches)."""
    db = colmap_db.Database(database)
    ids = db.image_ids_by_name()
    out = {}
    for a, b in PAIRS:
        k1, k2 = db.keypoints(ids["img%d.png" % a]), db.keypoints(ids["img%d.png" % b])
        p1 = np.hstack([k1 - 0.5, np.ones((len(k1), 1))]) @ hs[b].T
        p1 = p1[:, :2] / p1[:, 2:3]
        hits = 0
        for start in range(0, len(p1), 2048):
            d = np.linalg.norm(p1[start:start + 2048, None, :] - (k2[None, :, :] - 0.5), axis=2)
            hits += int((d.min(axis=1) <= eps).sum())
        out["%d-%d" % (a, b)] = hits
    db.close()
    return out
