"""Shared fixtures: a synthetic scene seen by several cameras, and a COLMAP
database holding it."""

import shutil
import sqlite3
import subprocess

import numpy as np
import pytest

WIDTH, HEIGHT, FOCAL = 1280, 960, 1000.0


class View:
    def __init__(self, keypoints, descriptors, point_of_row):
        self.keypoints = keypoints  # N x 2 float32 pixels
        self.descriptors = descriptors  # N x 128 uint8
        self.point_of_row = point_of_row  # the 3-D point each row sees


def make_views(num_points=700, num_views=3, seed=1):
    """Views of one random point cloud from cameras stepping sideways; each
    point has its own SIFT-like descriptor (L2 norm ~512), rows shuffled."""
    rng = np.random.default_rng(seed)
    points = np.column_stack([rng.uniform(-2.5, 2.5, num_points), rng.uniform(-2.5, 2.5, num_points),
                              rng.uniform(5.0, 9.0, num_points)])
    raw = rng.integers(0, 61, (num_points, 128)).astype(np.float64)
    descriptors = np.round(raw * 512.0 / np.linalg.norm(raw, axis=1, keepdims=True))
    views = []
    for i in range(num_views):
        local = points - np.array([0.4 * i, 0.05 * i, 0.0])
        x = FOCAL * local[:, 0] / local[:, 2] + WIDTH / 2 + rng.normal(0, 0.3, num_points)
        y = FOCAL * local[:, 1] / local[:, 2] + HEIGHT / 2 + rng.normal(0, 0.3, num_points)
        visible = np.flatnonzero((x >= 0) & (x < WIDTH) & (y >= 0) & (y < HEIGHT))
        rows = rng.permutation(visible)
        noisy = np.clip(descriptors[rows] + rng.integers(-2, 3, (len(rows), 128)), 0, 255)
        views.append(View(np.column_stack([x[rows], y[rows]]).astype(np.float32), noisy.astype(np.uint8), rows))
    return views


def write_database(path, views):
    """A COLMAP 3.8 database (schema by `colmap database_creator`) holding
    the views as view1.jpg, view2.jpg, ... with one PINHOLE camera."""
    subprocess.run(["colmap", "database_creator", "--database_path", str(path)], check=True,
                   capture_output=True, env={"QT_QPA_PLATFORM": "offscreen", "PATH": "/usr/bin:/bin"})
    db = sqlite3.connect(str(path))
    params = np.array([FOCAL, FOCAL, WIDTH / 2, HEIGHT / 2], dtype=np.float64)
    db.execute("INSERT INTO cameras(camera_id, model, width, height, params, prior_focal_length) "
               "VALUES (1, 1, ?, ?, ?, 0)", (WIDTH, HEIGHT, params.tobytes()))
    for i, view in enumerate(views, start=1):
        keypoints = np.zeros((len(view.keypoints), 6), dtype=np.float32)
        keypoints[:, :2] = view.keypoints
        keypoints[:, 2] = keypoints[:, 5] = 1.0
        db.execute("INSERT INTO images(image_id, name, camera_id) VALUES (?, ?, 1)", (i, f"view{i}.jpg"))
        db.execute("INSERT INTO keypoints VALUES (?, ?, 6, ?)", (i, len(keypoints), keypoints.tobytes()))
        db.execute("INSERT INTO descriptors VALUES (?, ?, 128, ?)",
                   (i, len(view.descriptors), view.descriptors.tobytes()))
    db.commit()
    db.close()


@pytest.fixture
def views():
    return make_views()


@pytest.fixture
def scene_database(tmp_path, views):
    if shutil.which("colmap") is None:
        pytest.skip("colmap is not installed")
    path = tmp_path / "scene.db"
    write_database(path, views)
    return path
