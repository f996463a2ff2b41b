"""End to end with pycolmap: pycolmap extracts SIFT on sceaux_castle, cashash
matches every pair, pycolmap reconstructs; all 11 images must register."""

import os
from pathlib import Path

import pytest

import cashash

pycolmap = pytest.importorskip("pycolmap")

SHARED = Path(os.environ.get("CASHASH_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
IMAGES = SHARED / "sceaux_castle" / "images"


@pytest.mark.skipif(not IMAGES.is_dir(), reason=f"no sceaux_castle images at {IMAGES}")
def test_pycolmap_extract_cashash_match_pycolmap_map(tmp_path):
    database = tmp_path / "database.db"
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.max_image_size = 1600  # keeps CPU extraction short
    extraction.use_gpu = False
    pycolmap.extract_features(database, IMAGES, camera_mode=pycolmap.CameraMode.SINGLE,
                              extraction_options=extraction, device=pycolmap.Device.cpu)

    summary = cashash.match_exhaustive(database)
    assert summary["pairs_done"] == 55
    assert summary["verified_pairs"] >= 50

    reconstructions = pycolmap.incremental_mapping(database, IMAGES, tmp_path / "sparse")
    assert reconstructions, "no model was reconstructed"
    best = max(reconstructions.values(), key=lambda r: r.num_reg_images())
    assert best.num_reg_images() == 11
    assert best.compute_mean_reprojection_error() < 1.0
