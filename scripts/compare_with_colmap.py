#!/usr/bin/env python3
"""cashash against COLMAP's exhaustive matcher on one feature database.

  scripts/compare_with_colmap.py --database_path DB --output_dir DIR
      [--use_gpu 0|1] [--colmap pycolmap|PATH] [--mapper 0|1]
      [--image_path IMAGES] [--gt_cameras DIR] [--cashash PATH]
      [--num_threads N] [--colmap_time_limit S] [-- extra cashash options]

DB (a COLMAP database with features) is never modified: it is copied twice
into DIR, matches and verified pairs already in it are cleared in the
copies, and each copy is matched and verified over all pairs:

- DIR/colmap.db by COLMAP's exhaustive matcher: pycolmap's match_exhaustive
  (default, run in a child process so that a crash is reported, not
  inherited), or the `colmap` executable given as --colmap, with its own
  option spelling (3.x SiftMatching.*, 4.x FeatureMatching.* and
  TwoViewGeometry.*). With --use_gpu 1 and no usable GPU matcher (pycolmap
  built without CUDA, COLMAP built without CUDA, or the GPU run fails) it
  runs COLMAP's CPU matcher and says so.
- DIR/cashash.db by `cashash exhaustive_matcher --FeatureMatching.use_gpu X`.

Both get the same matching and verification options (cashash's defaults,
which are COLMAP's, pinned on both command lines); an option after `--`
that COLMAP also has (either spelling) is applied to both, any other goes
to cashash only. With --mapper 1 pycolmap's incremental mapper reconstructs
each copy (needs --image_path); with --gt_cameras (a folder of Strecha
*.camera files) the models are aligned to the true camera centres by a
similarity transform and camera position and rotation errors are reported.

Writes DIR/comparison.md, DIR/comparison.json, DIR/comparison.png (skipped
with a note when matplotlib is missing) and DIR/logs/*.log, and prints a
short table. Exit code: 0 every requested step ran; 1 bad input or cashash
failed; 2 usage error; 3 COLMAP's matcher failed (cashash's results are
still reported); 4 the reconstruction failed on a side.

With --colmap_time_limit S, COLMAP's matcher is stopped after S seconds
(for collections it would take too long to match in full, as COLMAP's GPU
matcher on a thousand images): its rate is over the pairs it committed in
those seconds, process start included, and the counts and the agreement are
over those pairs on both sides; cashash still matches every pair. The
table says so.

Times are wall seconds of the matching step only: for pycolmap around
match_exhaustive (its interpreter start and import are excluded), for an
executable its whole run. Pairs/s counts all N(N-1)/2 image pairs.

Over 600 lines because it is one end-to-end command that re-runs itself as its
pycolmap worker child (_worker): both runs, comparison and report live here.
"""
import argparse
import datetime
import json
import os
import platform
import re
import shlex
import shutil
import sqlite3
import subprocess
import sys
import time

# No __pycache__ folders in the source tree.
sys.dont_write_bytecode = True
SCRIPTS = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, SCRIPTS)
REPO = os.path.dirname(SCRIPTS)

import numpy as np  # noqa: E402

from eval import cameras, tools  # noqa: E402

PAIR_ID_FACTOR = 2147483647
CONFIG_NAMES = {0: "UNDEFINED", 1: "DEGENERATE", 2: "CALIBRATED", 3: "UNCALIBRATED", 4: "PLANAR",
                5: "PANORAMIC", 6: "PLANAR_OR_PANORAMIC", 7: "WATERMARK", 8: "MULTIPLE", 9: "CALIBRATED_RIG"}
# Configurations that make a pair "verified" (an accepted two-view model).
VERIFIED_CONFIGS = (2, 3, 4, 5, 6, 8, 9)

# Options both matchers have: key -> (default, type, pycolmap attribute path
# (m = FeatureMatchingOptions, v = TwoViewGeometryOptions), COLMAP 3.x name,
# COLMAP 4.x name (also what cashash is given)). Defaults are cashash's,
# which are COLMAP's.
SHARED_OPTIONS = {
    "num_threads": (-1, int, "m.num_threads", "SiftMatching.num_threads", "FeatureMatching.num_threads"),
    "max_num_matches": (32768, int, "m.max_num_matches", "SiftMatching.max_num_matches",
                        "FeatureMatching.max_num_matches"),
    "max_ratio": (0.8, float, "m.sift.max_ratio", "SiftMatching.max_ratio", "SiftMatching.max_ratio"),
    "max_distance": (0.7, float, "m.sift.max_distance", "SiftMatching.max_distance", "SiftMatching.max_distance"),
    "cross_check": (1, int, "m.sift.cross_check", "SiftMatching.cross_check", "SiftMatching.cross_check"),
    "min_num_inliers": (15, int, "v.min_num_inliers", "SiftMatching.min_num_inliers",
                        "TwoViewGeometry.min_num_inliers"),
    "max_error": (4.0, float, "v.ransac.max_error", "SiftMatching.max_error", "TwoViewGeometry.max_error"),
    "confidence": (0.999, float, "v.ransac.confidence", "SiftMatching.confidence", "TwoViewGeometry.confidence"),
    "max_num_trials": (10000, int, "v.ransac.max_num_trials", "SiftMatching.max_num_trials",
                       "TwoViewGeometry.max_num_trials"),
    "min_inlier_ratio": (0.25, float, "v.ransac.min_inlier_ratio", "SiftMatching.min_inlier_ratio",
                         "TwoViewGeometry.min_inlier_ratio"),
}
GPU_OPTION_NAMES = ("FeatureMatching.use_gpu", "SiftMatching.use_gpu")

EXIT_OK, EXIT_CASHASH, EXIT_USAGE, EXIT_COLMAP, EXIT_MAPPER = 0, 1, 2, 3, 4


# ---------------------------------------------------------------------------
# Child processes running pycolmap (a crash there must not end the comparison)

def _set_path(roots, path, value):
    obj = roots[path[0]]
    parts = path.split(".")[1:]
    for part in parts[:-1]:
        obj = getattr(obj, part)
    current = getattr(obj, parts[-1])
    setattr(obj, parts[-1], type(current)(value))


def worker_match(args):
    import pycolmap
    out = {"pycolmap_version": pycolmap.__version__, "colmap_version": getattr(pycolmap, "COLMAP_version", ""),
           "has_cuda": bool(getattr(pycolmap, "has_cuda", False))}
    matching = pycolmap.FeatureMatchingOptions()
    verification = pycolmap.TwoViewGeometryOptions()
    roots = {"m": matching, "v": verification}
    matching.use_gpu = bool(args["use_gpu"])
    for key, value in args["options"].items():
        _set_path(roots, SHARED_OPTIONS[key][2], value)
    device = pycolmap.Device.cuda if args["use_gpu"] else pycolmap.Device.cpu
    out["matching_options"] = str(matching.summary() if hasattr(matching, "summary") else matching)
    out["verification_options"] = str(verification.summary() if hasattr(verification, "summary") else verification)
    start = time.perf_counter()
    pycolmap.match_exhaustive(args["database_path"], matching_options=matching,
                              verification_options=verification, device=device)
    out["wall_s"] = time.perf_counter() - start
    return out


def worker_map(args):
    import pycolmap
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = args["num_threads"]
    # A fixed seed where the options have one: reruns pick the same images.
    for obj in (options, options.mapper, options.triangulation):
        if hasattr(obj, "random_seed"):
            obj.random_seed = 0
    if hasattr(options, "extract_colors"):
        options.extract_colors = False
    os.makedirs(args["output_path"], exist_ok=True)
    start = time.perf_counter()
    maps = pycolmap.incremental_mapping(args["database_path"], args["image_path"], args["output_path"],
                                        options=options)
    wall = time.perf_counter() - start
    out = {"wall_s": wall, "num_models": len(maps)}
    if not maps:
        out.update({"registered_images": 0, "points3D": 0, "mean_track_length": None,
                    "mean_reprojection_error": None, "poses": {}})
        return out
    index, rec = max(maps.items(), key=lambda item: item[1].num_reg_images())
    poses = {}
    for image_id in rec.reg_image_ids():
        image = rec.image(image_id)
        pose = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
        r_cw = np.array(pose.rotation.matrix())
        t = np.array(pose.translation)
        poses[image.name] = {"R_cam_to_world": (r_cw.T).tolist(), "centre": (-r_cw.T @ t).tolist()}
    out.update({"model": int(index), "registered_images": int(rec.num_reg_images()),
                "points3D": int(rec.num_points3D()),
                "mean_track_length": float(rec.compute_mean_track_length()),
                "mean_reprojection_error": float(rec.compute_mean_reprojection_error()),
                "registered_per_model": [int(m.num_reg_images()) for m in maps.values()],
                "poses": poses})
    return out


def worker_main(kind, args_path):
    with open(args_path) as f:
        args = json.load(f)
    result = {"ok": False}
    try:
        result = worker_match(args) if kind == "match" else worker_map(args)
        result["ok"] = True
    except Exception as error:  # reported by the parent
        result["error"] = "%s: %s" % (type(error).__name__, error)
    with open(args["result_path"], "w") as f:
        json.dump(result, f)
    return 0 if result["ok"] else 1


def run_worker(kind, args, work_dir, log_path, time_limit=None):
    """Runs worker_main in a fresh interpreter; returns its result dict (ok False on any failure).

    With time_limit (seconds) the interpreter is killed then and the result
    says stopped, with the seconds it ran."""
    name = os.path.splitext(os.path.basename(log_path))[0]
    args = dict(args, result_path=os.path.join(work_dir, name + ".result.json"))
    args_path = os.path.join(work_dir, name + ".args.json")
    with open(args_path, "w") as f:
        json.dump(args, f)
    if os.path.exists(args["result_path"]):
        os.remove(args["result_path"])
    start = time.perf_counter()
    with open(log_path, "a") as log:
        try:
            proc = subprocess.run([sys.executable, os.path.abspath(__file__), "_worker", kind, args_path],
                                  stdout=log, stderr=subprocess.STDOUT, timeout=time_limit)
        except subprocess.TimeoutExpired:
            process_wall = time.perf_counter() - start
            return {"ok": True, "stopped": True, "wall_s": process_wall, "process_wall_s": process_wall}
    process_wall = time.perf_counter() - start
    try:
        with open(args["result_path"]) as f:
            result = json.load(f)
    except (OSError, ValueError):
        result = {"ok": False, "error": "pycolmap process ended with code %d and no result (crash?); see %s"
                  % (proc.returncode, log_path)}
    result["process_wall_s"] = process_wall
    return result


# ---------------------------------------------------------------------------
# Databases

def prepare_copy(source, target):
    """Copies source to target and clears matching results there, so every pair is matched."""
    for path in (target, target + "-wal", target + "-shm"):
        if os.path.exists(path):
            os.remove(path)
    tools.copy_database(source, target)
    conn = sqlite3.connect(target)
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    for table in ("matches", "two_view_geometries", "cashash_empty_pairs"):
        if table in tables:
            conn.execute("DELETE FROM %s" % table)
    conn.commit()
    conn.close()


def database_summary(path):
    conn = sqlite3.connect("file:%s?mode=ro" % path, uri=True)
    try:
        num_images = conn.execute("SELECT COUNT(*) FROM images").fetchone()[0]
        num_keypoints = conn.execute("SELECT COALESCE(SUM(rows), 0) FROM keypoints").fetchone()[0]
        existing = conn.execute("SELECT COUNT(*) FROM two_view_geometries").fetchone()[0]
    finally:
        conn.close()
    return {"num_images": num_images, "num_pairs": num_images * (num_images - 1) // 2,
            "mean_features_per_image": num_keypoints / num_images if num_images else 0,
            "existing_two_view_geometries": existing}


def _blob_pairs(rows, data):
    if not rows or data is None:
        return np.zeros(0, dtype=np.int64)
    m = np.frombuffer(data, dtype=np.uint32).reshape(rows, 2).astype(np.int64)
    return np.unique((m[:, 0] << 32) | m[:, 1])  # one int64 per index pair


def read_results(path):
    """{'raw': {pair_id: rows}, 'tvg': {pair_id: (config, encoded inlier pairs)}}."""
    conn = sqlite3.connect(path)
    try:
        raw = {pid: rows or 0 for pid, rows in conn.execute("SELECT pair_id, rows FROM matches")}
        tvg = {pid: (config, _blob_pairs(rows, data))
               for pid, rows, data, config in conn.execute("SELECT pair_id, rows, data, config FROM two_view_geometries")}
    finally:
        conn.close()
    return {"raw": raw, "tvg": tvg}


def verified(result):
    return {pid: inl for pid, (config, inl) in result["tvg"].items() if config in VERIFIED_CONFIGS and len(inl)}


def counts(result):
    configs = {}
    for config, _ in result["tvg"].values():
        name = CONFIG_NAMES.get(config, str(config))
        configs[name] = configs.get(name, 0) + 1
    ver = verified(result)
    return {"raw_matches": int(sum(result["raw"].values())),
            "pairs_with_raw_matches": sum(1 for r in result["raw"].values() if r > 0),
            "pairs_written": len(result["tvg"]),
            "verified_pairs": len(ver),
            "inlier_matches": int(sum(len(v) for v in ver.values())),
            "pairs_per_config": dict(sorted(configs.items()))}


def agreement(colmap, cashash):
    vc, vh = verified(colmap), verified(cashash)
    common = sorted(set(vc) & set(vh))
    c_inl = sum(len(vc[p]) for p in common)
    h_inl = sum(len(vh[p]) for p in common)
    shared = sum(len(np.intersect1d(vc[p], vh[p], assume_unique=True)) for p in common)
    ratios = [len(vh[p]) / len(vc[p]) for p in common]
    share = lambda num, den: num / den if den else None  # noqa: E731
    return {
        "colmap_verified_pairs": len(vc), "cashash_verified_pairs": len(vh), "both_verified_pairs": len(common),
        "colmap_verified_also_by_cashash": share(len(common), len(vc)),
        "cashash_verified_also_by_colmap": share(len(common), len(vh)),
        "colmap_inliers_on_common_pairs": c_inl, "cashash_inliers_on_common_pairs": h_inl,
        "cashash_over_colmap_inliers": share(h_inl, c_inl),
        "median_pair_cashash_over_colmap_inliers": float(np.median(ratios)) if ratios else None,
        "colmap_inlier_matches_also_in_cashash": share(shared, c_inl),
        "only_colmap_verified_pairs": len(set(vc) - set(vh)), "only_cashash_verified_pairs": len(set(vh) - set(vc)),
    }


def per_pair_inliers(colmap, cashash):
    vc, vh = verified(colmap), verified(cashash)
    pairs = sorted(set(vc) | set(vh))
    return [(p, len(vc.get(p, ())), len(vh.get(p, ()))) for p in pairs]


# ---------------------------------------------------------------------------
# Matchers

def first_line(text, pattern):
    for line in text.splitlines():
        if re.search(pattern, line):
            return line.strip()
    return ""


def run_command(command, log_path, time_limit=None):
    """(returncode, wall seconds, output); never raises on the command's failure. A command stopped at
    time_limit returns code None."""
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    start = time.perf_counter()
    try:
        proc = subprocess.run([str(c) for c in command], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, errors="replace", timeout=time_limit)
        code, output = proc.returncode, proc.stdout
    except subprocess.TimeoutExpired as stopped:
        code = None
        output = stopped.stdout if isinstance(stopped.stdout, str) else (stopped.stdout or b"").decode(errors="replace")
        output += "\n(stopped after %s s by --colmap_time_limit)" % time_limit
    except OSError as error:
        code, output = 127, str(error)
    wall = time.perf_counter() - start
    with open(log_path, "a") as log:
        log.write("$ " + " ".join(str(c) for c in command) + "\n" + output + "\n")
    return code, wall, output


def tail(text, lines=8):
    """The last lines of a tool's output, led by its first error line (glog's stack trace says little)."""
    last = text.strip().splitlines()[-lines:]
    error = first_line(text, r"Check failed|ERROR|[Ee]rror:|[Ee]xception")
    return "\n".join(([error, "..."] if error and error not in last else []) + last)


def colmap_cli_info(colmap):
    """Version, whether it was built with CUDA and its option spelling ('3.x' or '4.x')."""
    info = {"implementation": "colmap executable", "path": colmap}
    code, _, help_text = run_command([colmap, "help"], os.devnull)
    version_line = first_line(help_text, r"COLMAP \S+")
    match = re.search(r"COLMAP (\S+)", version_line)
    info["version"] = match.group(1) if match else "unknown"
    # "COLMAP 3.8 -- ...\n (Commit ... without CUDA)": the build line may be the next one.
    build_line = first_line(help_text, r"without CUDA|with CUDA")
    info["version_line"] = " ".join(dict.fromkeys(l for l in (version_line, build_line) if l))
    info["has_cuda"] = bool(version_line) and "without CUDA" not in help_text
    _, _, options = run_command([colmap, "exhaustive_matcher", "-h"], os.devnull)
    if "FeatureMatching.use_gpu" in options:
        info["spelling"] = "4.x"
    elif "SiftMatching.use_gpu" in options:
        info["spelling"] = "3.x"
    else:
        info["spelling"] = None
        info["error"] = "`%s exhaustive_matcher -h` lists neither FeatureMatching.use_gpu nor SiftMatching.use_gpu: %s" % (
            colmap, tail(options or help_text, 3))
    return info


def colmap_cli_command(colmap, spelling, database, use_gpu, options):
    index = 3 if spelling == "3.x" else 4
    gpu_name = "SiftMatching.use_gpu" if spelling == "3.x" else "FeatureMatching.use_gpu"
    command = [colmap, "exhaustive_matcher", "--database_path", database, "--" + gpu_name, int(use_gpu)]
    for key, value in options.items():
        command += ["--" + SHARED_OPTIONS[key][index], value]
    return [str(c) for c in command]


def run_colmap_side(args, options, database, source, work_dir, logs):
    """Matches database with COLMAP. Returns the description dict (ok, wall_s, label, notes, ...)."""
    side = {"gpu_requested": bool(args.use_gpu), "notes": []}
    log = os.path.join(logs, "colmap_match.log")
    attempts = [True, False] if args.use_gpu else [False]

    if args.colmap == "pycolmap":
        side["implementation"] = "pycolmap match_exhaustive"
        probe = run_command([sys.executable, "-c", "import pycolmap, json; print(json.dumps({'v': pycolmap.__version__, "
                             "'c': getattr(pycolmap, 'COLMAP_version', ''), 'cuda': bool(getattr(pycolmap, 'has_cuda', False)), "
                             "'file': pycolmap.__file__}))"], log)
        try:
            meta = json.loads(probe[2].strip().splitlines()[-1])
        except (ValueError, IndexError):
            side.update({"ok": False, "error": "pycolmap cannot be imported: " + tail(probe[2], 3),
                         "label": "COLMAP (pycolmap not importable)", "version": None, "gpu_used": False})
            return side
        side["version"] = "pycolmap %s (%s)" % (meta["v"], meta["c"])
        side["module_path"] = meta["file"]
        side["has_cuda"] = meta["cuda"]
        if args.use_gpu and not meta["cuda"]:
            side["notes"].append("GPU requested but this pycolmap has no CUDA (pycolmap.has_cuda is False): "
                                 "COLMAP's CPU matcher was run instead")
            attempts = [False]
        for use_gpu in attempts:
            if use_gpu is not attempts[0]:
                prepare_copy(source, database)
            result = run_worker("match", {"database_path": database, "use_gpu": use_gpu, "options": options},
                                work_dir, log, time_limit=args.colmap_time_limit)
            if result.get("stopped"):
                side.update({"ok": True, "stopped": True, "wall_s": result["wall_s"], "gpu_used": use_gpu,
                             "process_wall_s": result["process_wall_s"]})
                side["notes"].append("COLMAP's matcher was stopped after %.0f s (--colmap_time_limit); its rate, the "
                                     "counts and the agreement are over the pairs it committed" % result["wall_s"])
                break
            if result.get("ok"):
                side.update({"ok": True, "wall_s": result["wall_s"], "process_wall_s": result["process_wall_s"],
                             "gpu_used": use_gpu, "matching_options": result.get("matching_options"),
                             "verification_options": result.get("verification_options")})
                side["command"] = ("pycolmap.match_exhaustive(db, matching_options=FeatureMatchingOptions(use_gpu=%s, %s), "
                                   "verification_options=TwoViewGeometryOptions(...), device=Device.%s)"
                                   % (use_gpu, ", ".join("%s=%s" % kv for kv in options.items()),
                                      "cuda" if use_gpu else "cpu"))
                break
            side["notes"].append("COLMAP %s matcher failed: %s" % ("GPU" if use_gpu else "CPU", result.get("error")))
            if use_gpu:
                side["notes"].append("COLMAP's CPU matcher was run instead")
        else:
            side.update({"ok": False, "gpu_used": False, "error": side["notes"][-1]})
    else:
        info = colmap_cli_info(args.colmap)
        side.update({"implementation": "colmap executable " + args.colmap, "version": "COLMAP " + info["version"],
                     "version_line": info["version_line"], "has_cuda": info["has_cuda"],
                     "option_spelling": info["spelling"]})
        if info["spelling"] is None:
            side.update({"ok": False, "gpu_used": False, "error": info["error"],
                         "label": "COLMAP %s exhaustive_matcher" % info["version"]})
            return side
        if args.use_gpu and not info["has_cuda"]:
            side["notes"].append("GPU requested but this colmap was built without CUDA (%s): COLMAP's CPU matcher "
                                 "was run instead" % info["version_line"])
            attempts = [False]
        for use_gpu in attempts:
            if use_gpu is not attempts[0]:
                prepare_copy(source, database)
            command = colmap_cli_command(args.colmap, info["spelling"], database, use_gpu, options)
            code, wall, output = run_command(command, log, time_limit=args.colmap_time_limit)
            if code is None:
                side.update({"ok": True, "stopped": True, "wall_s": wall, "gpu_used": use_gpu,
                             "command": " ".join(command)})
                side["notes"].append("COLMAP's matcher was stopped after %.0f s (--colmap_time_limit); its rate, the "
                                     "counts and the agreement are over the pairs it committed" % wall)
                break
            if code == 0:
                side.update({"ok": True, "wall_s": wall, "gpu_used": use_gpu, "command": " ".join(command)})
                break
            side["notes"].append("COLMAP %s matcher failed (exit %d): %s" % ("GPU" if use_gpu else "CPU", code,
                                                                            tail(output, 4)))
            if use_gpu:
                side["notes"].append("COLMAP's CPU matcher was run instead")
        else:
            side.update({"ok": False, "gpu_used": False, "error": side["notes"][-1]})
    side["label"] = "COLMAP exhaustive matcher, %s, %s" % (side.get("version"), device_label(side))
    return side


def run_cashash_side(args, options, extra, database, logs):
    side = {"gpu_requested": bool(args.use_gpu), "notes": [], "implementation": "cashash exhaustive_matcher",
            "path": args.cashash}
    log = os.path.join(logs, "cashash_match.log")
    if not (os.path.isfile(args.cashash) and os.access(args.cashash, os.X_OK)):
        side.update({"ok": False, "gpu_used": False, "error": "no cashash executable at %s" % args.cashash,
                     "label": "cashash"})
        return side
    command = [args.cashash, "exhaustive_matcher", "--database_path", database,
               "--FeatureMatching.use_gpu", str(int(args.use_gpu))]
    for key, value in options.items():
        command += ["--" + SHARED_OPTIONS[key][4], str(value)]
    command += extra
    code, wall, output = run_command(command, log)
    side["command"] = " ".join(command)
    side["version"] = cashash_version()
    gpu_used = bool(args.use_gpu) and not re.search(r"matching on the CPU", output)
    if args.use_gpu and not gpu_used:
        side["notes"].append("GPU requested but cashash matched on the CPU: " + first_line(output, "matching on the CPU"))
    if code != 0:
        side.update({"ok": False, "gpu_used": gpu_used, "error": "cashash failed (exit %d): %s" % (code, tail(output, 6))})
    else:
        side.update({"ok": True, "wall_s": wall, "gpu_used": gpu_used})
    side["label"] = "cashash exhaustive_matcher, %s, %s" % (side["version"], device_label(side))
    return side


def device_label(side):
    if side.get("gpu_used"):
        return "GPU"
    return "CPU (GPU requested, not used)" if side["gpu_requested"] else "CPU"


def cashash_version():
    try:
        proc = subprocess.run(["git", "-C", REPO, "describe", "--always", "--dirty"], stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True)
        if proc.returncode == 0 and proc.stdout.strip():
            return "checkout " + proc.stdout.strip()
    except OSError:
        pass
    return "version unknown"


def split_extra(extra):
    """Moves options COLMAP also has out of extra: returns (shared overrides, options for cashash only).

    Raises ValueError for a GPU switch (that is --use_gpu's job)."""
    by_name = {}
    for key, spec in SHARED_OPTIONS.items():
        by_name[spec[3]] = key
        by_name[spec[4]] = key
    overrides, rest = {}, []
    i = 0
    while i < len(extra):
        token = extra[i]
        name, value = token[2:], None
        if "=" in name:
            name, value = name.split("=", 1)
        if token.startswith("--") and name in GPU_OPTION_NAMES:
            raise ValueError("give the GPU switch as --use_gpu, not %s after --" % token)
        if token.startswith("--") and name in by_name:
            if value is None:
                if i + 1 >= len(extra):
                    raise ValueError("%s needs a value" % token)
                value = extra[i + 1]
                i += 1
            key = by_name[name]
            overrides[key] = SHARED_OPTIONS[key][1](float(value)) if SHARED_OPTIONS[key][1] is int else float(value)
        else:
            rest.append(token)
        i += 1
    return overrides, rest


# ---------------------------------------------------------------------------
# Reconstruction

def reconstruct_side(name, database, args, work_dir, logs, gt):
    out_dir = os.path.join(work_dir, "sparse_" + name)
    if os.path.isdir(out_dir):
        shutil.rmtree(out_dir)
    result = run_worker("map", {"database_path": database, "image_path": args.image_path, "output_path": out_dir,
                                "num_threads": args.num_threads}, work_dir, os.path.join(logs, name + "_mapper.log"))
    poses = result.pop("poses", None)
    result["output_path"] = out_dir
    if result.get("ok") and gt is not None:
        model = {n: (np.array(p["R_cam_to_world"]), np.array(p["centre"])) for n, p in (poses or {}).items()}
        result["gt"] = cameras.camera_errors(gt, model) if model else {"gt_images": len(gt), "registered": 0}
    return result


# ---------------------------------------------------------------------------
# Report

def fmt(value, digits=3):
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return "{:,}".format(value)
    if isinstance(value, float):
        if value != value:
            return "n/a"
        if abs(value) >= 1000:
            return "{:,.0f}".format(value)
        return ("{:.%dg}" % digits).format(value) if abs(value) < 1 else "{:.{}f}".format(value, 2 if abs(value) < 100 else 1)
    return str(value)


def pct(value):
    return "n/a" if value is None else "%.1f %%" % (100 * value)


def machine():
    info = {"platform": platform.platform(), "cpu_cores": os.cpu_count(), "python": platform.python_version()}
    if shutil.which("nvidia-smi"):
        proc = subprocess.run(["nvidia-smi", "--query-gpu=name,memory.total", "--format=csv,noheader"],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        if proc.returncode == 0:
            info["gpus"] = [line.strip() for line in proc.stdout.splitlines() if line.strip()]
    return info


def side_value(report, section, side, key):
    return (report.get(section, {}).get(side) or {}).get(key)


def markdown(report):
    c, h = report["matchers"]["colmap"], report["matchers"]["cashash"]
    ds, m = report["dataset"], report["machine"]
    lines = ["# cashash against COLMAP's exhaustive matcher", "",
             "Database `%s`: %d images, %s pairs, %.0f features per image on average. %s, %d CPU cores%s. %s." % (
                 ds["database_path"], ds["num_images"], fmt(ds["num_pairs"]), ds["mean_features_per_image"],
                 m["platform"], m["cpu_cores"], (", GPU " + "; ".join(m["gpus"])) if m.get("gpus") else ", no GPU",
                 report["date"]), "",
             "| | COLMAP | cashash |", "|---|---|---|",
             "| run | %s | %s |" % (c.get("label"), h.get("label")),
             "| GPU requested / used | %s / %s | %s / %s |" % (fmt(c["gpu_requested"]), fmt(c.get("gpu_used")),
                                                              fmt(h["gpu_requested"]), fmt(h.get("gpu_used"))),
             "| finished | %s | %s |" % (fmt(c.get("ok")), fmt(h.get("ok")))]
    t = report["time"]
    lines += ["| matching + verification, wall s | %s | %s |" % (fmt(side_value(report, "time", "colmap", "wall_s")),
                                                                   fmt(side_value(report, "time", "cashash", "wall_s"))),
              "| pairs/s | %s | %s |" % (fmt(side_value(report, "time", "colmap", "pairs_per_s")),
                                         fmt(side_value(report, "time", "cashash", "pairs_per_s")))]
    for key, label in (("raw_matches", "raw matches"), ("pairs_with_raw_matches", "pairs with raw matches"),
                       ("verified_pairs", "verified pairs"), ("inlier_matches", "inlier matches (verified pairs)")):
        lines.append("| %s | %s | %s |" % (label, fmt(side_value(report, "counts", "colmap", key)),
                                          fmt(side_value(report, "counts", "cashash", key))))
    configs = sorted(set((side_value(report, "counts", "colmap", "pairs_per_config") or {}))
                     | set((side_value(report, "counts", "cashash", "pairs_per_config") or {})))
    for config in configs:
        lines.append("| pairs %s | %s | %s |" % (
            config, fmt((side_value(report, "counts", "colmap", "pairs_per_config") or {}).get(config, 0)),
            fmt((side_value(report, "counts", "cashash", "pairs_per_config") or {}).get(config, 0))))
    rec = report["reconstruction"]
    if "colmap" in rec:
        for key, label in (("registered_images", "registered images"), ("points3D", "3D points"),
                           ("mean_track_length", "mean track length"),
                           ("mean_reprojection_error", "mean reprojection error, px")):
            lines.append("| %s | %s | %s |" % (label, fmt(rec["colmap"].get(key)), fmt(rec["cashash"].get(key))))
        if "gt" in rec["colmap"] or "gt" in rec["cashash"]:
            for key, label in (("position_median", "camera centre error, median"),
                               ("position_max", "camera centre error, max"),
                               ("rotation_median_deg", "rotation error, median, deg"),
                               ("rotation_max_deg", "rotation error, max, deg"),
                               ("relative_rotation_median_deg", "pairwise relative rotation error, median, deg")):
                lines.append("| %s | %s | %s |" % (label, fmt(rec["colmap"].get("gt", {}).get(key)),
                                                   fmt(rec["cashash"].get("gt", {}).get(key))))
    lines.append("")
    if (t.get("colmap") or {}).get("stopped"):
        lines.append("COLMAP's matcher was stopped after %.0f s (`--colmap_time_limit`) with %s of the %s pairs "
                     "committed: its pairs/s are over those, and the counts above and the agreement below are over "
                     "those pairs on both sides. cashash matched every pair." % (
                         t["colmap"]["wall_s"], fmt(t["colmap"]["pairs_done"]), fmt(ds["num_pairs"])))
        lines.append("")
    if t.get("speedup") is not None:
        lines.append("cashash's pairs/s are **%.1fx** COLMAP's." % t["speedup"])
        lines.append("")
    a = report["agreement"]
    if a:
        lines += ["Agreement, pair by pair:", "",
                  "| | |", "|---|---|",
                  "| COLMAP-verified pairs that cashash verifies too | %s (%d of %d) |" % (
                      pct(a["colmap_verified_also_by_cashash"]), a["both_verified_pairs"], a["colmap_verified_pairs"]),
                  "| cashash-verified pairs that COLMAP verifies too | %s (%d of %d) |" % (
                      pct(a["cashash_verified_also_by_colmap"]), a["both_verified_pairs"], a["cashash_verified_pairs"]),
                  "| on pairs both verify: cashash's inliers / COLMAP's | %s (median pair %s) |" % (
                      fmt(a["cashash_over_colmap_inliers"]), fmt(a["median_pair_cashash_over_colmap_inliers"])),
                  "| on those pairs: COLMAP's inlier matches that cashash has too | %s |" % pct(
                      a["colmap_inlier_matches_also_in_cashash"]), ""]
    if "skipped" in rec:
        lines += ["Reconstruction skipped: %s." % rec["skipped"], ""]
    elif "colmap" in rec:
        lines += ["Reconstruction: pycolmap incremental mapping (largest model, seed 0) on each database%s." % (
            "; camera errors after a similarity alignment of the centres to `%s` (centre errors in its units)"
            % report["options"]["gt_cameras"] if report["options"].get("gt_cameras") else ""), ""]
    if report.get("plot"):
        lines += ["![cashash against COLMAP](%s)" % os.path.basename(report["plot"]), ""]
    else:
        lines += ["No plot: %s." % report.get("plot_note", "not drawn"), ""]
    notes = report["problems"]
    if notes:
        lines += ["Notes and problems:", ""] + ["- " + n.replace("\n", " ") for n in notes] + [""]
    lines += ["Same options on both: %s." % ", ".join("%s %s" % kv for kv in report["options"]["shared"].items()),
              "cashash only: `%s`." % (" ".join(report["options"]["cashash_only"]) or "none"), "",
              "Commands:", "", "```",
              "COLMAP:  %s" % c.get("command", "(not run)"),
              "cashash: %s" % h.get("command", "(not run)"),
              "this:    %s" % report["command_line"], "```", ""]
    return "\n".join(lines)


def stdout_table(report):
    rows = [("", "COLMAP", "cashash"),
            ("GPU used", fmt(report["matchers"]["colmap"].get("gpu_used")),
             fmt(report["matchers"]["cashash"].get("gpu_used"))),
            ("wall s", fmt(side_value(report, "time", "colmap", "wall_s")),
             fmt(side_value(report, "time", "cashash", "wall_s"))),
            ("pairs/s", fmt(side_value(report, "time", "colmap", "pairs_per_s")),
             fmt(side_value(report, "time", "cashash", "pairs_per_s"))),
            ("verified pairs", fmt(side_value(report, "counts", "colmap", "verified_pairs")),
             fmt(side_value(report, "counts", "cashash", "verified_pairs"))),
            ("inlier matches", fmt(side_value(report, "counts", "colmap", "inlier_matches")),
             fmt(side_value(report, "counts", "cashash", "inlier_matches")))]
    rec = report["reconstruction"]
    if "colmap" in rec:
        rows += [("registered", fmt(rec["colmap"].get("registered_images")), fmt(rec["cashash"].get("registered_images"))),
                 ("3D points", fmt(rec["colmap"].get("points3D")), fmt(rec["cashash"].get("points3D")))]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    text = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)) for row in rows]
    speedup = report["time"].get("speedup")
    if speedup is not None:
        text.append("speed-up %.1fx" % speedup)
    a = report["agreement"]
    if a:
        text.append("COLMAP pairs also cashash %s, cashash pairs also COLMAP %s, inliers %s of COLMAP's, "
                    "COLMAP inliers kept %s" % (pct(a["colmap_verified_also_by_cashash"]),
                                                pct(a["cashash_verified_also_by_colmap"]),
                                                fmt(a["cashash_over_colmap_inliers"]),
                                                pct(a["colmap_inlier_matches_also_in_cashash"])))
    return "\n".join(text)


def plot(report, pairs, path):
    """Per-pair inliers (log-log) and the two times. Returns (path or None, note)."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except Exception as error:  # optional
        return None, "matplotlib is not available (%s)" % error
    try:
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [3, 2]})
        if pairs:
            arr = np.array([[c, h] for _, c, h in pairs], dtype=float)
            both = (arr[:, 0] > 0) & (arr[:, 1] > 0)
            drawn = np.maximum(arr, 1)
            for mask, style in ((both, dict(s=12, alpha=0.6, label="verified by both")),
                                (arr[:, 1] == 0, dict(s=20, marker="x", color="tab:red",
                                                      label="verified by COLMAP only (drawn at 1)")),
                                (arr[:, 0] == 0, dict(s=20, marker="+", color="tab:green",
                                                      label="verified by cashash only (drawn at 1)"))):
                if mask.any():
                    ax1.scatter(drawn[mask, 0], drawn[mask, 1], **style)
            top = drawn.max() * 1.5
            ax1.plot([1, top], [1, top], color="grey", lw=0.8, ls="--")
            ax1.set_xscale("log")
            ax1.set_yscale("log")
            ax1.legend(fontsize=8, loc="upper left")
        ax1.set_xlabel("COLMAP inlier matches per pair")
        ax1.set_ylabel("cashash inlier matches per pair")
        ax1.set_title("Verified inliers per image pair")
        # A stopped COLMAP did not match every pair: compare rates then.
        stopped = bool(side_value(report, "time", "colmap", "stopped"))
        key, unit = ("pairs_per_s", "pairs/s") if stopped else ("wall_s", "s")
        labels, values = [], []
        for side, name in (("colmap", "COLMAP"), ("cashash", "cashash")):
            value = side_value(report, "time", side, key)
            if value is not None:
                used = report["matchers"][side].get("gpu_used")
                labels.append("%s\n(%s)" % (name, "GPU" if used else "CPU"))
                values.append(value)
        bars = ax2.bar(labels, values, color=["tab:blue", "tab:orange"][:len(values)])
        for bar, value in zip(bars, values):
            ax2.annotate("%.1f %s" % (value, unit), (bar.get_x() + bar.get_width() / 2, value), ha="center",
                         va="bottom")
        if stopped:
            ax2.set_ylabel("matching + verification, pairs/s")
            ax2.set_title("Rate (COLMAP stopped after %.0f s)" % side_value(report, "time", "colmap", "wall_s"))
        else:
            ax2.set_ylabel("matching + verification, wall s")
            ax2.set_title("Time, %d pairs" % report["dataset"]["num_pairs"])
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return path, None
    except Exception as error:
        return None, "plotting failed (%s: %s)" % (type(error).__name__, error)


# ---------------------------------------------------------------------------

def parse_args(argv):
    if "--" in argv:
        cut = argv.index("--")
        argv, extra = argv[:cut], argv[cut + 1:]
    else:
        extra = []
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="Options after -- go to cashash exhaustive_matcher.")
    parser.add_argument("--database_path", required=True, help="COLMAP database with features (never modified)")
    parser.add_argument("--output_dir", required=True)
    parser.add_argument("--use_gpu", type=int, choices=(0, 1), default=1,
                        help="match on the GPU, both sides (default 1; falls back to the CPU and says so)")
    parser.add_argument("--colmap", default="pycolmap", help="'pycolmap' (default) or a colmap executable")
    parser.add_argument("--mapper", type=int, choices=(0, 1), default=0,
                        help="also reconstruct both with pycolmap's incremental mapper (needs --image_path)")
    parser.add_argument("--image_path", help="the images (for --mapper 1; colours are not extracted, so the "
                        "mapper does not read them and an empty folder will do where they are absent)")
    parser.add_argument("--gt_cameras", help="folder of Strecha *.camera files (with --mapper 1)")
    parser.add_argument("--cashash", default=os.path.join(REPO, "build", "colmap_bridge", "cashash"))
    parser.add_argument("--num_threads", type=int, default=-1, help="CPU threads of both matchers and the mapper")
    parser.add_argument("--colmap_time_limit", type=float, default=None,
                        help="stop COLMAP's matcher after this many seconds and compare over the pairs it committed "
                        "(no mapper then)")
    args = parser.parse_args(argv)
    return args, extra


def main(argv):
    args, extra = parse_args(argv)
    problems = []
    exit_code = EXIT_OK
    args.database_path = os.path.abspath(args.database_path)
    args.cashash = os.path.abspath(args.cashash)
    if args.colmap != "pycolmap":
        args.colmap = shutil.which(args.colmap) or os.path.abspath(args.colmap)
    if not os.path.isfile(args.database_path):
        print("error: no database at %s" % args.database_path, file=sys.stderr)
        return EXIT_CASHASH
    try:
        overrides, cashash_only = split_extra(extra)
    except ValueError as error:
        print("error: %s" % error, file=sys.stderr)
        return EXIT_USAGE
    options = {key: spec[0] for key, spec in SHARED_OPTIONS.items()}
    options["num_threads"] = args.num_threads
    options.update(overrides)

    out_dir = os.path.abspath(args.output_dir)
    logs = os.path.join(out_dir, "logs")
    os.makedirs(logs, exist_ok=True)
    for name in os.listdir(logs):
        os.remove(os.path.join(logs, name))
    dataset = dict(database_summary(args.database_path), database_path=args.database_path)
    if dataset["existing_two_view_geometries"]:
        problems.append("the database already held %d verified-pair rows; they were cleared in both copies (not in "
                        "the database) so that both matchers match every pair" % dataset["existing_two_view_geometries"])
    colmap_db, cashash_db = os.path.join(out_dir, "colmap.db"), os.path.join(out_dir, "cashash.db")
    prepare_copy(args.database_path, colmap_db)
    prepare_copy(args.database_path, cashash_db)

    print("Matching with COLMAP (%s) ..." % args.colmap, flush=True)
    colmap_side = run_colmap_side(args, options, colmap_db, args.database_path, out_dir, logs)
    print("Matching with cashash ...", flush=True)
    cashash_side = run_cashash_side(args, options, cashash_only, cashash_db, logs)
    problems += colmap_side["notes"] + cashash_side["notes"]
    if not cashash_side["ok"]:
        problems.append(cashash_side["error"])
        exit_code = EXIT_CASHASH
    if not colmap_side["ok"]:
        problems.append("COLMAP's side failed: %s" % colmap_side.get("error"))
        exit_code = exit_code or EXIT_COLMAP

    report = {"date": datetime.datetime.now().strftime("%Y-%m-%d %H:%M"), "command_line": " ".join(
        ["scripts/compare_with_colmap.py"] + [shlex.quote(a) for a in argv]),
              "machine": machine(), "dataset": dataset,
              "options": {"shared": options, "cashash_only": cashash_only, "use_gpu": bool(args.use_gpu),
                          "colmap": args.colmap, "mapper": bool(args.mapper), "image_path": args.image_path,
                          "gt_cameras": args.gt_cameras},
              "matchers": {"colmap": colmap_side, "cashash": cashash_side},
              "time": {}, "counts": {}, "agreement": {}, "reconstruction": {}, "problems": problems}
    results = {}
    for name, side, db in (("colmap", colmap_side, colmap_db), ("cashash", cashash_side, cashash_db)):
        if not side["ok"]:
            continue
        try:
            results[name] = read_results(db)
        except sqlite3.Error as error:
            problems.append("cannot read %s's results from %s: %s" % (name, db, error))
            exit_code = exit_code or (EXIT_COLMAP if name == "colmap" else EXIT_CASHASH)
            continue
        # A stopped COLMAP committed some of the pairs: its rate is over those.
        pairs_done = len(results[name]["tvg"]) if side.get("stopped") else dataset["num_pairs"]
        report["time"][name] = {"wall_s": side["wall_s"], "pairs_done": pairs_done, "stopped": bool(side.get("stopped")),
                                "pairs_per_s": pairs_done / side["wall_s"] if side["wall_s"] > 0 else None}
    if colmap_side.get("stopped") and "colmap" in results and "cashash" in results:
        # Counts and agreement over the pairs COLMAP reached, on both sides.
        done = set(results["colmap"]["tvg"]) | set(results["colmap"]["raw"])
        results["cashash"] = {key: {p: v for p, v in table.items() if p in done}
                              for key, table in results["cashash"].items()}
        report["dataset"]["pairs_compared"] = len(done)
    for name in results:
        report["counts"][name] = counts(results[name])
    if "colmap" in report["time"] and "cashash" in report["time"] and report["time"]["colmap"]["pairs_per_s"]:
        report["time"]["speedup"] = report["time"]["cashash"]["pairs_per_s"] / report["time"]["colmap"]["pairs_per_s"]
    pairs = []
    if len(results) == 2:
        report["agreement"] = agreement(results["colmap"], results["cashash"])
        pairs = per_pair_inliers(results["colmap"], results["cashash"])

    if not args.mapper:
        report["reconstruction"] = {"skipped": "--mapper 0"}
    elif colmap_side.get("stopped"):
        report["reconstruction"] = {"skipped": "COLMAP's matcher was stopped (--colmap_time_limit)"}
        problems.append("mapper skipped: COLMAP's matcher did not match every pair")
    elif not args.image_path:
        report["reconstruction"] = {"skipped": "--mapper 1 needs --image_path"}
        problems.append("mapper skipped: no --image_path")
    elif len(results) < 2:
        report["reconstruction"] = {"skipped": "a matcher failed"}
    else:
        gt = None
        if args.gt_cameras:
            gt_dir = args.gt_cameras
            if os.path.isdir(os.path.join(gt_dir, "gt_dense_cameras")):
                gt_dir = os.path.join(gt_dir, "gt_dense_cameras")
            gt = cameras.read_gt_camera_files(gt_dir)
            if not gt:
                problems.append("no *.camera files in %s: no camera errors" % args.gt_cameras)
                gt = None
        for name, db in (("colmap", colmap_db), ("cashash", cashash_db)):
            print("Reconstructing the %s database ..." % name, flush=True)
            rec = reconstruct_side(name, db, args, out_dir, logs, gt)
            report["reconstruction"][name] = rec
            if not rec.get("ok"):
                problems.append("reconstruction of the %s database failed: %s" % (name, rec.get("error")))
                exit_code = exit_code or EXIT_MAPPER

    png = os.path.join(out_dir, "comparison.png")
    if os.path.exists(png):
        os.remove(png)
    if report["time"]:
        report["plot"], note = plot(report, pairs, png)
    else:
        report["plot"], note = None, "no matcher finished"
    if note:
        report["plot_note"] = note
        problems.append("no plot: " + note)
    report["per_pair_inliers"] = [{"image_id1": p // PAIR_ID_FACTOR, "image_id2": p % PAIR_ID_FACTOR,
                                   "colmap": c, "cashash": h} for p, c, h in pairs]
    report["exit_code"] = exit_code
    with open(os.path.join(out_dir, "comparison.json"), "w") as f:
        json.dump(report, f, indent=1)
    with open(os.path.join(out_dir, "comparison.md"), "w") as f:
        f.write(markdown(report))
    print()
    print(stdout_table(report))
    for problem in problems:
        print("note: " + problem.replace("\n", " "))
    print("Written: %s/comparison.{md,json%s}" % (out_dir, ",png" if report["plot"] else ""))
    return exit_code


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "_worker":
        sys.exit(worker_main(sys.argv[2], sys.argv[3]))
    sys.exit(main(sys.argv[1:]))
