#!/usr/bin/env python3
"""Do `cashash sequential_matcher` and `spatial_matcher` match the pairs that
COLMAP's (pycolmap's) sequential and spatial matching match?

  compare_pairing_with_pycolmap.py --cashash build-cpu/app/cashash [--work_dir DIR]
                                   [--num_images 40] [--num_features 256]
                                   [--revisit_images 0] [--keep_name_order]

Generates a street (`cashash generate_database --position_priors gps`, from
a source database of random SIFT-like descriptors made here), gives its
images names out of id order (and, for sequential matching, also recasts it
as a rig of two cameras), and for each configuration below matches a
copy with pycolmap (CPU) and copies with cashash (CPU), then compares the
sets of pairs in table matches (COLMAP writes a row for every pair it
attempts, empty or not, and so does cashash). cashash reads the priors from
where each schema keeps them, so it runs twice: on the COLMAP 3.8 database
the generator writes (priors in images.prior_t*), and on the copy pycolmap
upgraded to 4.x with the priors written by pycolmap into pose_priors.

Loop detection's own pairs are not compared: COLMAP's uses a vocabulary
tree, cashash's the cascade's codes; they find different images by design.
With loop detection on, cashash must match every pair pycolmap matches
without it (the sequential pairs), and each pair beyond those must have a
loop query (every loop_detection_period-th image in name order) in it.
--revisit_images makes the street return to its start
(`generate_database --revisit_images`), so that there are loops to find;
--keep_name_order keeps the names in path order, as a drive records them,
instead of shuffling them.

Prints one line per configuration and exits 1 when any pair set differs,
77 when pycolmap cannot be imported (callers skip).
"""
import argparse
import os
import random
import shutil
import sqlite3
import subprocess
import sys
import tempfile

import numpy as np

try:
    import pycolmap
except ImportError as error:  # pragma: no cover - depends on the machine
    print(f"pycolmap not available: {error}", file=sys.stderr)
    sys.exit(77)

MAX_IMAGE_ID = 2147483647
WITHOUT_PRIOR = "images without prior"  # not an option: ids whose prior a configuration removes

SEQUENTIAL = [
    ("defaults (overlap 10, quadratic)", {}),
    ("overlap 3, linear", {"overlap": 3, "quadratic_overlap": False}),
    ("overlap 4, quadratic", {"overlap": 4}),
    # cashash with loop detection against pycolmap without (see above).
    ("loop detection (overlap 10, quadratic)", {"loop_detection": True}),
]
# The options that belong to loop detection, left out of pycolmap's run.
LOOP_OPTIONS = ("loop_detection", "loop_detection_period", "loop_detection_num_images")
# On the street recast as a rig of two cameras (two images a frame).
SEQUENTIAL_RIG = [
    ("rig, defaults", {}),
    ("rig, overlap 2, linear", {"overlap": 2, "quadratic_overlap": False}),
    ("rig, overlap 3, expand_rig_images 0", {"overlap": 3, "expand_rig_images": False}),
]
SPATIAL = [
    ("defaults (50 neighbours within 100 m)", {}),
    ("max_distance 4", {"max_distance": 4.0}),
    ("max_num_neighbors 3", {"max_num_neighbors": 3}),
    ("max_distance 1.5, min_num_neighbors 3", {"max_distance": 1.5, "min_num_neighbors": 3}),
    ("max_distance 3, ignore_z 0", {"max_distance": 3.0, "ignore_z": False}),
    # Images 5, 11 and 17 lose their prior in every copy (COLMAP skips them).
    ("max_num_neighbors 3, 3 images without prior", {"max_num_neighbors": 3, WITHOUT_PRIOR: (5, 11, 17)}),
]


def write_source_database(path, num_images=3, num_features=1500, seed=7):
    """A COLMAP 3.8 database of random SIFT-like descriptors (norm about 512)."""
    rng = np.random.default_rng(seed)
    db = sqlite3.connect(path)
    db.executescript(
        "CREATE TABLE cameras (camera_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, model INTEGER NOT NULL, "
        "width INTEGER NOT NULL, height INTEGER NOT NULL, params BLOB, prior_focal_length INTEGER NOT NULL);"
        "CREATE TABLE images (image_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, name TEXT NOT NULL UNIQUE, "
        "camera_id INTEGER NOT NULL, prior_qw REAL, prior_qx REAL, prior_qy REAL, prior_qz REAL, prior_tx REAL, "
        "prior_ty REAL, prior_tz REAL);"
        "CREATE TABLE keypoints (image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, "
        "data BLOB);"
        "CREATE TABLE descriptors (image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, "
        "cols INTEGER NOT NULL, data BLOB);"
        "CREATE TABLE matches (pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, "
        "data BLOB);"
        "CREATE TABLE two_view_geometries (pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, "
        "cols INTEGER NOT NULL, data BLOB, config INTEGER NOT NULL, F BLOB, E BLOB, H BLOB, qvec BLOB, tvec BLOB);"
        "PRAGMA user_version = 3800;")
    for k in range(num_images):
        params = np.array([1200, 500, 500], dtype=np.float64)
        db.execute("INSERT INTO cameras VALUES (?, 0, 1000, 1000, ?, 1)", (k + 1, params.tobytes()))
        db.execute("INSERT INTO images (image_id, name, camera_id) VALUES (?, ?, ?)", (k + 1, f"src_{k}.jpg", k + 1))
        kp = np.zeros((num_features, 6), dtype=np.float32)
        kp[:, :2] = rng.uniform(0, 1000, (num_features, 2))
        kp[:, 2] = kp[:, 5] = rng.uniform(1, 8, num_features)
        raw = rng.integers(0, 60, (num_features, 128)).astype(np.float64)
        raw *= 512.0 / np.linalg.norm(raw, axis=1, keepdims=True)
        desc = np.clip(np.round(raw), 0, 255).astype(np.uint8)
        db.execute("INSERT INTO keypoints VALUES (?, ?, 6, ?)", (k + 1, num_features, kp.tobytes()))
        db.execute("INSERT INTO descriptors VALUES (?, ?, 128, ?)", (k + 1, num_features, desc.tobytes()))
    db.commit()
    db.close()


def shuffle_names(path, seed=3):
    """Gives the images their names in a random order, so that name order
    (what sequential matching follows) is not id order."""
    db = sqlite3.connect(path)
    rows = db.execute("SELECT image_id, name FROM images ORDER BY image_id").fetchall()
    names = [name for _, name in rows]
    random.Random(seed).shuffle(names)
    db.executemany("UPDATE images SET name = ? WHERE image_id = ?", [("tmp_" + n, i) for (i, _), n in zip(rows, names)])
    db.execute("UPDATE images SET name = substr(name, 5)")
    db.commit()
    db.close()


def to_colmap4_with_pose_priors(path, gps):
    """Upgrades a 3.8 database with pycolmap and copies its prior columns
    into pose_priors, as COLMAP 4.x keeps them (its upgrade leaves them)."""
    source = sqlite3.connect(path)  # closed before pycolmap opens the file, as in loop_queries
    rows = source.execute(
        "SELECT image_id, camera_id, prior_tx, prior_ty, prior_tz FROM images ORDER BY image_id").fetchall()
    source.close()
    db = pycolmap.Database.open(path)
    for image_id, camera_id, x, y, z in rows:
        if x is None:
            continue
        prior = pycolmap.PosePrior()
        prior.corr_data_id = pycolmap.data_t(
            sensor_id=pycolmap.sensor_t(type=pycolmap.SensorType.CAMERA, id=camera_id), id=image_id)
        prior.position = np.array([x, y, z], dtype=np.float64)
        prior.coordinate_system = (pycolmap.PosePriorCoordinateSystem.WGS84 if gps
                                   else pycolmap.PosePriorCoordinateSystem.CARTESIAN)
        db.write_pose_prior(prior)
    db.close()


def make_rig_database(colmap4_path, path):
    """The images as two cameras of one rig (cam1/frame_K.jpg, cam2/...),
    in frames of two, by pycolmap's apply_rig_config."""
    shutil.copy(colmap4_path, path)
    db = sqlite3.connect(path)
    ids = [r[0] for r in db.execute("SELECT image_id FROM images ORDER BY image_id")]
    for k, image_id in enumerate(ids):
        db.execute("UPDATE images SET name = ? WHERE image_id = ?", (f"tmp_{k}", image_id))
    for k, image_id in enumerate(ids):
        db.execute("UPDATE images SET name = ?, camera_id = ? WHERE image_id = ?",
                   (f"cam{1 + k % 2}/frame_{k // 2:04d}.jpg", 1 + k % 2, image_id))
    db.commit()
    db.close()
    config = pycolmap.RigConfig(cameras=[
        pycolmap.RigConfigCamera(ref_sensor=True, image_prefix="cam1/"),
        pycolmap.RigConfigCamera(image_prefix="cam2/", cam_from_rig=pycolmap.Rigid3d())])
    database = pycolmap.Database.open(path)
    pycolmap.apply_rig_config([config], database)
    database.close()


def remove_priors(path, image_ids):
    """Removes the priors of the images from both places a schema may keep them."""
    db = sqlite3.connect(path)
    marks = ",".join("?" * len(image_ids))
    db.execute(f"UPDATE images SET prior_tx = NULL, prior_ty = NULL, prior_tz = NULL WHERE image_id IN ({marks})",
               image_ids)
    if db.execute("SELECT 1 FROM sqlite_master WHERE name = 'pose_priors'").fetchone():
        db.execute(f"DELETE FROM pose_priors WHERE corr_data_id IN ({marks})", image_ids)
    db.commit()
    db.close()


def loop_queries(path, options):
    """The image ids loop detection queries: every period-th in name order
    (bytewise, as COLMAP sorts), the first included."""
    period = options.get("loop_detection_period", 10)
    # Closed at once: a connection to a WAL database that lingers until the
    # garbage collector checkpoints its stale view into the next copy made
    # at this path ("database disk image is malformed").
    db = sqlite3.connect(path)
    rows = db.execute("SELECT image_id, name FROM images").fetchall()
    db.close()
    ordered = [image_id for image_id, _ in sorted(rows, key=lambda row: row[1].encode())]
    return set(ordered[::period])


def pairs_of(path):
    db = sqlite3.connect(path)
    ids = {int(r[0]) for r in db.execute("SELECT pair_id FROM matches")}
    db.close()
    return ids


def describe(pair_ids, path):
    db = sqlite3.connect(path)  # closed at once, as in loop_queries
    names = dict(db.execute("SELECT image_id, name FROM images"))
    db.close()
    out = []
    for pair_id in sorted(pair_ids)[:5]:
        a, b = divmod(pair_id, MAX_IMAGE_ID)
        out.append(f"{names.get(a, a)}-{names.get(b, b)}")
    return ", ".join(out) + (" ..." if len(pair_ids) > 5 else "")


def run_cashash(binary, command, path, group, options, gps):
    args = [binary, command, "--database_path", path, "--FeatureMatching.use_gpu", "0",
            "--FeatureMatching.num_threads", "2"]
    for name, value in options.items():
        args += [f"--{group}.{name}", str(int(value)) if isinstance(value, bool) else str(value)]
    if command == "spatial_matcher":
        args += ["--SpatialMatching.is_gps", "1" if gps else "0"]
    result = subprocess.run(args, capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f"{' '.join(args)} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")


def run_pycolmap(kind, path, options):
    matching = pycolmap.FeatureMatchingOptions()
    matching.use_gpu = False
    matching.num_threads = 2
    if kind == "sequential":
        pairing = pycolmap.SequentialPairingOptions(**{k: v for k, v in options.items() if k not in LOOP_OPTIONS})
        pycolmap.match_sequential(path, matching_options=matching, pairing_options=pairing,
                                  device=pycolmap.Device.cpu)
    else:
        pairing = pycolmap.SpatialPairingOptions(**options)
        pycolmap.match_spatial(path, matching_options=matching, pairing_options=pairing, device=pycolmap.Device.cpu)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cashash", required=True, help="the cashash executable")
    parser.add_argument("--work_dir", help="kept afterwards when given (default: a temporary folder)")
    parser.add_argument("--num_images", type=int, default=40)
    parser.add_argument("--num_features", type=int, default=256)
    parser.add_argument("--priors", choices=["gps", "cartesian", "both"], default="both")
    parser.add_argument("--revisit_images", type=int, default=0,
                        help="the last this many images drive the start of the street again")
    parser.add_argument("--keep_name_order", action="store_true",
                        help="names in path order instead of shuffled")
    args = parser.parse_args()
    pycolmap.logging.minloglevel = 2  # errors only: its per-image lines would bury the comparison
    work = args.work_dir or tempfile.mkdtemp(prefix="cashash_pairing_")
    os.makedirs(work, exist_ok=True)
    print(f"pycolmap {pycolmap.__version__}; {args.num_images} images x {args.num_features} features"
          f"{f', the last {args.revisit_images} back at the start' if args.revisit_images else ''} in {work}")
    source = os.path.join(work, "source.db")
    if not os.path.exists(source):
        write_source_database(source)
    failures = 0
    kinds = ["gps", "cartesian"] if args.priors == "both" else [args.priors]
    for prior_kind in kinds:
        gps = prior_kind == "gps"
        street = os.path.join(work, f"street_{prior_kind}.db")
        if not os.path.exists(street):
            subprocess.run([args.cashash, "generate_database", "--database_path", street, "--source_database_path",
                            source, "--num_images", str(args.num_images), "--num_features",
                            str(args.num_features), "--revisit_images", str(args.revisit_images),
                            "--position_priors", prior_kind, "--num_threads", "2"],
                           check=True, capture_output=True)
            if not args.keep_name_order:
                shuffle_names(street)
        upgraded = os.path.join(work, f"street_{prior_kind}_colmap4.db")
        if not os.path.exists(upgraded):
            shutil.copy(street, upgraded)
            to_colmap4_with_pose_priors(upgraded, gps)
        rig = os.path.join(work, "street_rig_colmap4.db")
        if gps and not os.path.exists(rig):
            make_rig_database(upgraded, rig)
        # (kind, label, options, databases cashash reads: schema -> path, the
        # one pycolmap reads)
        configs = []
        if gps:
            configs += [("sequential", c, {"3.8": street, "4.x": upgraded}, upgraded) for c in SEQUENTIAL]
            configs += [("sequential", c, {"4.x rig": rig}, rig) for c in SEQUENTIAL_RIG]
        configs += [("spatial", c, {"3.8": street, "4.x": upgraded}, upgraded) for c in SPATIAL]
        for kind, (label, all_options), ours_from, theirs_from in configs:
            options = {k: v for k, v in all_options.items() if k != WITHOUT_PRIOR}
            without_prior = all_options.get(WITHOUT_PRIOR, ())
            command = f"{kind}_matcher"
            group = "SequentialMatching" if kind == "sequential" else "SpatialMatching"
            colmap_db = os.path.join(work, "pycolmap.db")
            shutil.copy(theirs_from, colmap_db)
            if without_prior:
                remove_priors(colmap_db, without_prior)
            run_pycolmap(kind, colmap_db, options)
            expected = pairs_of(colmap_db)
            for schema, base in ours_from.items():
                ours = os.path.join(work, "cashash.db")
                shutil.copy(base, ours)
                if without_prior:
                    remove_priors(ours, without_prior)
                run_cashash(args.cashash, command, ours, group, options, gps)
                got = pairs_of(ours)
                unexplained = got - expected  # pairs only cashash matched that nothing accounts for
                if options.get("loop_detection"):
                    queries = loop_queries(ours, options)
                    unexplained = {p for p in unexplained
                                   if not any(i in queries for i in divmod(p, MAX_IMAGE_ID))}
                same = not unexplained and expected <= got
                failures += not same
                line = (f"{'same' if same else 'DIFFERENT'}: {kind} {label}, {prior_kind} priors, {schema} schema: "
                        f"{len(got)} pairs (pycolmap {len(expected)})")
                if options.get("loop_detection"):
                    line += f"; {len(got - expected)} loop pairs beyond pycolmap's pairs without loop detection"
                if not same:
                    line += (f"; only cashash: {describe(unexplained, ours)}; "
                             f"only pycolmap: {describe(expected - got, ours)}")
                print(line, flush=True)
    if not args.work_dir:
        shutil.rmtree(work, ignore_errors=True)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
