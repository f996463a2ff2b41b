#!/usr/bin/env python3
"""Checks of the evaluation's own arithmetic on synthetic data (no tools run).

  python3 scripts/eval/selftest.py
"""
import os
import sys

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

from eval import cameras, gpu_column, homography, loss_analysis  # noqa: E402


def check_umeyama_recovers_similarity(rng):
    source = rng.normal(size=(12, 3))
    rotation = cameras.quaternion_to_matrix(rng.normal(size=4))
    target = 2.5 * source @ rotation.T + np.array([1.0, -2.0, 0.5])
    scale, r, t = cameras.umeyama(source, target)
    assert abs(scale - 2.5) < 1e-9 and np.allclose(r, rotation) and np.allclose(t, [1.0, -2.0, 0.5])


def check_camera_errors(rng):
    gt = {}
    for i in range(6):
        gt["%d.jpg" % i] = (cameras.quaternion_to_matrix(rng.normal(size=4)), rng.normal(size=3) * 5)
    align = cameras.quaternion_to_matrix(rng.normal(size=4))
    model = {n: (align.T @ r, 0.3 * align.T @ c + 1.0) for n, (r, c) in gt.items()}
    exact = cameras.camera_errors(gt, model)
    assert exact["registered"] == 6 and exact["position_max"] < 1e-9 and exact["rotation_max_deg"] < 1e-6
    assert exact["relative_rotation_max_deg"] < 1e-6
    # One camera rotated by 2 degrees about its own axis: rotation error 2 degrees for it.
    tilt = np.radians(2.0)
    turn = np.array([[np.cos(tilt), -np.sin(tilt), 0], [np.sin(tilt), np.cos(tilt), 0], [0, 0, 1]])
    name = "3.jpg"
    model[name] = (model[name][0] @ turn, model[name][1])
    tilted = cameras.camera_errors(gt, model)
    assert abs(tilted["rotation_max_deg"] - 2.0) < 1e-6, tilted
    assert tilted["position_max"] < 1e-9


def check_images_txt_centres(tmp):
    # A camera at centre (1, 2, 3) looking along world +z: R = I, t = -R C.
    path = os.path.join(tmp, "images.txt")
    with open(path, "w") as f:
        f.write("# comment\n1 1 0 0 0 -1 -2 -3 1 a.jpg\n10 20 -1\n")
    rotation, centre = cameras.read_model_images(path)["a.jpg"]
    assert np.allclose(rotation, np.eye(3)) and np.allclose(centre, [1, 2, 3])


def check_reprojection_convention():
    # A pure shift by (10, 5) in pixel-index coordinates is the same shift in
    # COLMAP's half-pixel coordinates; a scale by 2 is not (0.5 offset).
    shift = np.array([[1, 0, 10], [0, 1, 5], [0, 0, 1.0]])
    p1 = np.array([[0.5, 0.5], [100.5, 40.5]])
    assert np.allclose(homography.reprojection_errors(shift, p1, p1 + [10, 5]), 0)
    scale = np.diag([2.0, 2.0, 1.0])
    assert np.allclose(homography.reprojection_errors(scale, p1, 2 * (p1 - 0.5) + 0.5), 0)


def check_collision_probability():
    p = loss_analysis.collision_probability(np.radians(np.array([0.0, 30.0, 90.0, 180.0])), 7, 8)
    assert p[0] == 1.0 and p[-1] == 0.0 and np.all(np.diff(p) < 0)


def check_extra_match_reasons():
    # Descriptors of norm about 512, as COLMAP stores them: four dimensions per value.
    def descriptor(a, b):
        d = np.zeros(128, dtype=np.uint8)
        d[0:4], d[4:8] = a, b
        return d
    d2 = np.array([descriptor(255, 0), descriptor(0, 255), descriptor(180, 180)])
    # Query 0 equals d2[0]: nearest and unambiguous -> 'other'. Query 1 lies
    # between d2[0] (21 degrees) and d2[2] (25 degrees) -> ratio 0.84 -> 'ratio'.
    # Query 2 equals d2[2] but was matched to feature 1 -> 'not_nearest'.
    d1 = np.array([descriptor(255, 0), descriptor(240, 90), descriptor(180, 180)])
    extra = np.array([[0, 0], [1, 0], [2, 1]])
    counts = loss_analysis.classify_extra_matches(d1, d2, extra, np.array([True, False, False]))
    assert counts["other"]["correct"] == 1 and counts["ratio"]["wrong"] == 1, counts
    assert counts["not_nearest"]["wrong"] == 1, counts


def check_gpu_column_reading(tmp):
    # Option help as boost prints it: a default may wrap onto the next line.
    with open(os.path.join(tmp, "options.txt"), "w") as f:
        f.write("  --CasHash.num_tables arg              First-level hash tables (=8)\n"
                "  --CasHash.bits_per_table arg          Bits per first-level table (=7)\n"
                "  --CasHash.tau arg                     Largest 128-bit remap Hamming distance \n"
                "                                        ranked (=43)\n"
                "  --CasHash.top_k arg                   Candidates per query whose exact \n"
                "                                        distance is computed (=16)\n"
                "  --CasHash.matcher arg                 cascade | bruteforce\n")
    assert gpu_column.binary_defaults(tmp) == "8,7,43,16", gpu_column.binary_defaults(tmp)
    with open(os.path.join(tmp, "graf.log"), "w") as f:
        f.write("WARNING: no CUDA device; matching on the CPU\n"
                "Summary: 15 pairs in 2.4 s (6.2 pairs/s) with cpu-cascade; 10770 raw matches\n"
                "Time: loading 0.3 s, matching 1.447 s, verification 0.6 s, writing 0.01 s\n")
    assert gpu_column.run_summary(tmp, "graf") == ("cpu-cascade", 1.447)
    cpu = {"1-2": {"pairs": np.array([[0, 1], [2, 3], [4, 5]])}}
    gpu = {"1-2": {"pairs": np.array([[0, 1], [2, 7]])}}
    assert gpu_column.agreement(cpu, gpu)["1-2"] == {"cpu": 3, "gpu": 2, "identical": 1, "same": False}
    assert gpu_column.agreement(cpu, cpu)["1-2"]["same"]


def main():
    import tempfile
    rng = np.random.default_rng(7)
    check_umeyama_recovers_similarity(rng)
    check_camera_errors(rng)
    with tempfile.TemporaryDirectory() as tmp:
        check_images_txt_centres(tmp)
    with tempfile.TemporaryDirectory() as tmp:
        check_gpu_column_reading(tmp)
    check_reprojection_convention()
    check_collision_probability()
    check_extra_match_reasons()
    print("selftest: all checks passed")


if __name__ == "__main__":
    main()
