"""Camera ground truth (Strecha's fountain-P11, herzjesu-P25): reconstruct
with COLMAP's mapper after a matcher, align the model to the ground-truth
centres with a similarity transform and measure position and rotation errors.
"""
import glob
import os
import shutil

import numpy as np

from eval import colmap_db, tools
from summarize_model import quaternion_to_rotation as quaternion_to_matrix  # scripts/ is on sys.path


def read_gt_cameras(scene_dir):
    """{image name: (R camera-to-world, centre)} from gt_dense_cameras/*.camera."""
    return read_gt_camera_files(os.path.join(scene_dir, "gt_dense_cameras"))


def read_gt_camera_files(directory):
    """{image name: (R camera-to-world, centre)} from directory/*.camera (Strecha's format).

    File layout: K (3 lines), distortion (1 line), R camera-to-world (3 lines),
    centre C (1 line), image size; P = K [R^T | -R^T C].
    """
    cameras = {}
    for path in sorted(glob.glob(os.path.join(directory, "*.camera"))):
        rows = [[float(v) for v in line.split()] for line in open(path) if line.strip()]
        rotation = np.array(rows[4:7])
        centre = np.array(rows[7])
        cameras[os.path.basename(path)[:-len(".camera")]] = (rotation, centre)
    return cameras


def read_model_images(images_txt):
    """{name: (R camera-to-world, centre)} from a COLMAP images.txt (world-to-camera qvec, tvec)."""
    cameras = {}
    lines = [l for l in open(images_txt) if not l.startswith("#")]
    for line in lines[0::2]:
        fields = line.split()
        if len(fields) < 10:
            continue
        r_wc = quaternion_to_matrix(np.array([float(v) for v in fields[1:5]]))
        t = np.array([float(v) for v in fields[5:8]])
        cameras[fields[9]] = (r_wc.T, -r_wc.T @ t)
    return cameras


def umeyama(source, target):
    """Similarity (s, R, t) minimising |target - (s R source + t)|^2 over the rows."""
    mu_s, mu_t = source.mean(axis=0), target.mean(axis=0)
    xs, xt = source - mu_s, target - mu_t
    covariance = xt.T @ xs / len(source)
    u, d, vt = np.linalg.svd(covariance)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1
    rotation = u @ sign @ vt
    variance = (xs ** 2).sum() / len(source)
    scale = np.trace(np.diag(d) @ sign) / variance
    return scale, rotation, mu_t - scale * rotation @ mu_s


def rotation_angle_deg(r):
    """Angle of a rotation matrix. atan2 of sine and cosine stays accurate for
    small angles, where arccos of a trace rounded near 3 would report
    hundredths of a degree."""
    sine = np.linalg.norm([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2
    return float(np.degrees(np.arctan2(sine, (np.trace(r) - 1) / 2)))


def relative_rotation_errors(gt, model, names):
    """Alignment-free: for every pair of cameras, the angle between the
    ground-truth and the model's relative rotation."""
    errors = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            rel_gt = gt[names[a]][0].T @ gt[names[b]][0]
            rel_model = model[names[a]][0].T @ model[names[b]][0]
            errors.append(rotation_angle_deg(rel_gt.T @ rel_model))
    return np.array(errors)


def camera_errors(gt, model):
    """Aligns model to gt on the common images; returns the error summary."""
    names = sorted(set(gt) & set(model))
    gt_centres = np.array([c for _, c in gt.values()])
    scene_size = max(np.linalg.norm(a - b) for a in gt_centres for b in gt_centres)
    summary = {"gt_images": len(gt), "registered": len(names), "scene_size": float(scene_size)}
    if len(names) < 3:
        return summary
    source = np.array([model[n][1] for n in names])
    target = np.array([gt[n][1] for n in names])
    scale, rotation, translation = umeyama(source, target)
    aligned = (scale * (rotation @ source.T)).T + translation
    position = np.linalg.norm(aligned - target, axis=1)
    angles = []
    for n in names:
        angles.append(rotation_angle_deg(gt[n][0].T @ (rotation @ model[n][0])))
    angles = np.array(angles)
    relative = relative_rotation_errors(gt, model, names)
    summary.update({
        "position_median": float(np.median(position)), "position_max": float(position.max()),
        "position_median_rel": float(np.median(position) / scene_size),
        "position_max_rel": float(position.max() / scene_size),
        "rotation_median_deg": float(np.median(angles)), "rotation_max_deg": float(angles.max()),
        "relative_rotation_median_deg": float(np.median(relative)),
        "relative_rotation_max_deg": float(relative.max()),
    })
    return summary


def match_command(matcher, cashash_binary, database):
    """The command line of one matcher over all pairs of a database."""
    if matcher == "colmap":
        return ["colmap", "exhaustive_matcher", "--database_path", database,
                "--SiftMatching.use_gpu", "0", "--SiftMatching.num_threads", "2"]
    return [cashash_binary, "exhaustive_matcher", "--database_path", database,
            "--CasHash.matcher", matcher, "--SiftMatching.num_threads", "2"]


def largest_model(sparse_dir, work_dir, log):
    """Converts every model the mapper wrote to TXT; returns (cameras of the
    largest, its number of 3D points, registered images of every model)."""
    best, points, per_model = {}, 0, []
    for model_dir in sorted(glob.glob(os.path.join(sparse_dir, "*"))):
        if not os.path.isdir(model_dir):
            continue
        text_dir = os.path.join(work_dir, "txt_" + os.path.basename(model_dir))
        os.makedirs(text_dir, exist_ok=True)
        tools.run_tool(["colmap", "model_converter", "--input_path", model_dir, "--output_path", text_dir,
                        "--output_type", "TXT"], log, nice=0)
        cameras = read_model_images(os.path.join(text_dir, "images.txt"))
        per_model.append(len(cameras))
        if len(cameras) > len(best):
            best = cameras
            with open(os.path.join(text_dir, "points3D.txt")) as f:
                points = sum(1 for line in f if line.strip() and not line.startswith("#"))
    return best, points, per_model


def map_and_align(scene_dir, database, work_dir, log):
    """`colmap mapper` (defaults, 2 threads) on a matched database into
    work_dir/sparse; aligns the largest model to the ground truth.

    Returns camera_errors' summary with mapper_wall_s, points3D (of the
    largest model) and registered_per_model (every model the mapper wrote)."""
    os.makedirs(work_dir, exist_ok=True)
    # A model of an earlier run (another setting) must not be read as this one's.
    for stale in glob.glob(os.path.join(work_dir, "txt_*")) + [os.path.join(work_dir, "sparse")]:
        if os.path.isdir(stale):
            shutil.rmtree(stale)
    sparse = os.path.join(work_dir, "sparse")
    os.makedirs(sparse, exist_ok=True)
    map_wall, _, _ = tools.run_tool(["colmap", "mapper", "--database_path", database, "--image_path",
                                     os.path.join(scene_dir, "images"), "--output_path", sparse,
                                     "--Mapper.num_threads", "2"], log)
    model, points, per_model = largest_model(sparse, work_dir, log)
    summary = camera_errors(read_gt_cameras(scene_dir), model)
    summary.update({"mapper_wall_s": map_wall, "points3D": points, "registered_per_model": per_model})
    return summary


def reconstruct(scene_dir, source_db, matcher, cashash_binary, work_dir, log, extra_flags=()):
    """Copies the feature database, matches with matcher, maps, aligns. Returns the summary."""
    os.makedirs(work_dir, exist_ok=True)
    database = os.path.join(work_dir, "database.db")
    tools.copy_database(source_db, database)
    match_wall, match_cpu, _ = tools.run_tool(match_command(matcher, cashash_binary, database) + list(extra_flags),
                                              log)
    summary = map_and_align(scene_dir, database, work_dir, log)
    summary.update({"match_wall_s": match_wall, "match_cpu_s": match_cpu})
    return summary


def evaluate_existing(scene_dir, work_dir, summary):
    """Recomputes the error part of summary from the TXT models already in work_dir."""
    best = {}
    for text_dir in sorted(glob.glob(os.path.join(work_dir, "txt_*"))):
        cameras = read_model_images(os.path.join(text_dir, "images.txt"))
        if len(cameras) > len(best):
            best = cameras
    summary.update(camera_errors(read_gt_cameras(scene_dir), best))
    return summary


def verified_inliers_kept(reference_db, other_db):
    """Share of the reference's verified inlier matches (two_view_geometries
    rows, all pairs) that the other database also verifies."""
    reference, other = colmap_db.Database(reference_db), colmap_db.Database(other_db)
    try:
        ref_rows, other_rows = reference.all_inlier_rows(), other.all_inlier_rows()
    finally:
        reference.close()
        other.close()
    total = sum(len(rows) for rows in ref_rows.values())
    kept = sum(len(rows & other_rows.get(pair, set())) for pair, rows in ref_rows.items())
    return kept / total if total else float("nan")
