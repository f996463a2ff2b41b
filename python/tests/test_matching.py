"""cashash's Python API: in-memory matching and matching a database."""

import inspect
import sqlite3

import numpy as np
import pytest

import cashash

from conftest import FOCAL, HEIGHT, WIDTH


def correct_fraction(matches, view1, view2):
    return np.mean(view1.point_of_row[matches[:, 0]] == view2.point_of_row[matches[:, 1]])


def test_match_in_memory_finds_and_verifies_true_matches(views):
    a, b = views[0], views[1]
    result = cashash.match(a.descriptors, b.descriptors, a.keypoints, b.keypoints)
    assert result["matches"].dtype == np.uint32 and result["matches"].shape[1] == 2
    assert len(result["matches"]) > 400
    assert correct_fraction(result["matches"], a, b) > 0.98
    assert result["verified"]
    assert result["config_name"] == "UNCALIBRATED"  # no intrinsics: F/H only
    assert len(result["inlier_matches"]) >= 0.95 * len(result["matches"])
    assert result["F"].shape == (3, 3)


def test_match_with_intrinsics_is_calibrated(views):
    a, b = views[0], views[1]
    camera = {"model": "PINHOLE", "width": WIDTH, "height": HEIGHT,
              "params": [FOCAL, FOCAL, WIDTH / 2, HEIGHT / 2]}
    result = cashash.match(a.descriptors, b.descriptors, a.keypoints, b.keypoints, camera, camera)
    assert result["config_name"] == "CALIBRATED"
    assert np.abs(result["E"]).max() > 0  # E is estimated only with intrinsics


def test_match_descriptors_only_and_float_descriptors(views):
    a, b = views[0], views[1]
    raw = cashash.match(a.descriptors, b.descriptors)
    assert not raw["verified"] and raw["config_name"] == "UNDEFINED"
    as_float = cashash.match(a.descriptors / 512.0, b.descriptors / 512.0)
    np.testing.assert_array_equal(as_float["matches"], raw["matches"])


def test_bad_input_raises():
    with pytest.raises(ValueError, match="N x 128"):
        cashash.match(np.zeros((4, 64), np.uint8), np.zeros((4, 128), np.uint8))
    with pytest.raises(ValueError, match="image 1 has 3 keypoints but 4 descriptors"):
        cashash.match(np.zeros((4, 128), np.uint8), np.zeros((4, 128), np.uint8), np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="CasHash.top_k must be >= 1"):
        cashash.match(np.zeros((4, 128), np.uint8), np.zeros((4, 128), np.uint8), top_k=0)
    with pytest.raises(TypeError, match="unknown matching option 'no_such_option'"):
        cashash.make_options(no_such_option=1)


def test_match_checks_options_as_the_runs_do(views):
    a, b = views[0], views[1]
    with pytest.raises(ValueError, match="--max_gpu_memory must be a size such as 16G"):
        cashash.match(a.descriptors, b.descriptors, max_gpu_memory="abc")
    with pytest.raises(ValueError, match="--FeatureMatching.gpu_index: expected an integer"):
        cashash.match(a.descriptors, b.descriptors, gpu_index="first")
    with pytest.raises(ValueError, match="gpu_verifications_in_flight must be 1 to 8"):
        cashash.match(a.descriptors, b.descriptors, gpu_verifications_in_flight=0)


def test_use_gpu_without_a_usable_gpu_matches_as_the_cpu():
    # 40 shared features under heavy descriptor noise among 300 others each:
    # the cascade misses a few of them, the CPU run's exact rematch of the
    # pairs with 12 to 63 cascade matches finds them. Which algorithm ran
    # shows in the matches.
    rng = np.random.default_rng(0)

    def sift_like(n):
        raw = rng.integers(0, 61, (n, 128)).astype(np.float64)
        return np.round(raw * 512.0 / np.linalg.norm(raw, axis=1, keepdims=True))

    shared = sift_like(40)
    d1 = np.vstack([shared, sift_like(300)]).astype(np.uint8)
    d2 = np.vstack([np.clip(shared + rng.integers(-16, 17, shared.shape), 0, 255), sift_like(300)]).astype(np.uint8)
    cpu = cashash.match(d1, d2, use_gpu=False)
    asked = cashash.match(d1, d2, use_gpu=True)
    if asked["run"]["gpu_index"] >= 0:
        pytest.skip("a usable GPU matched the pair")
    assert asked["run"] == cpu["run"]
    assert cpu["run"]["exact_rematch_max_matches"] > 0  # the CPU's rematch window
    np.testing.assert_array_equal(asked["matches"], cpu["matches"])
    assert len(cpu["matches"]) == 40


def test_exact_rematch_is_the_runs_default_and_can_be_turned_off(scene_database):
    # Runs match the pairs that may verify again exactly (12 cascade matches).
    # -1: chosen for the run (12, or 8 with the bucket screening tables).
    assert cashash.make_options().cashash.exact_rematch_min_matches == -1
    summary = cashash.match_exhaustive(scene_database, matcher="cascade", exact_rematch_min_matches=0)
    assert summary["matcher"] == "cpu-cascade" and summary["pairs_done"] == 3


def test_match_exhaustive_writes_every_pair_and_resumes(scene_database):
    calls = []
    # Runs default to matcher="auto" (on the CPU the cascade with the
    # rematch of a window of pairs); the name checked here is the cascade's
    # with the rematch of every pair that may verify.
    summary = cashash.match_exhaustive(scene_database, matcher="cascade",
                                       progress=lambda done, total: calls.append((done, total)))
    assert summary["pairs_requested"] == 3 and summary["pairs_done"] == 3
    assert summary["verified_pairs"] == 3
    assert summary["matcher"] == "cpu-cascade+exact-rematch"
    assert calls and calls[-1] == (3, 3)
    db = sqlite3.connect(str(scene_database))
    assert db.execute("SELECT COUNT(*) FROM two_view_geometries WHERE rows > 100").fetchone()[0] == 3
    db.close()

    again = cashash.match_exhaustive(scene_database)
    assert again["pairs_skipped"] == 3 and again["pairs_done"] == 0
    redone = cashash.match_exhaustive(scene_database, overwrite=True, matcher="bruteforce")
    assert redone["pairs_done"] == 3 and redone["matcher"] == "cpu-bruteforce"


def test_match_pairs_by_name(scene_database):
    summary = cashash.match_pairs(scene_database, [("view1.jpg", "view3.jpg"), ("view3.jpg", "view1.jpg")])
    assert summary["pairs_requested"] == 1 and summary["verified_pairs"] == 1
    with pytest.raises(RuntimeError, match="image pair 0: image 'nope.jpg' is not in table images"):
        cashash.match_pairs(scene_database, [("nope.jpg", "view1.jpg")])


def test_match_retrieval(scene_database):
    # Three views of one scene: with one most similar image each, retrieval
    # pairs every view with another, and the pairs it picks verify.
    with pytest.warns(RuntimeWarning, match="vocab_tree_path unused.bin is not used"):
        summary = cashash.match_retrieval(scene_database, num_images=1, vocab_tree_path="unused.bin")
    assert 2 <= summary["pairs_requested"] <= 3
    assert summary["verified_pairs"] == summary["pairs_requested"]
    again = cashash.match_vocabtree(scene_database, num_images=2)
    assert again["pairs_requested"] == 3 and again["pairs_skipped"] == summary["pairs_requested"]
    with pytest.raises(ValueError, match="--VocabTreeMatching.num_images must be >= 1"):
        cashash.match_retrieval(scene_database, num_images=0)


def test_match_retrieval_keeps_one_set_of_defaults():
    # RetrievalOptions' defaults (the command line's) are the only ones: a
    # keyword default of match_retrieval's own would drift from them.
    for name, parameter in inspect.signature(cashash.match_retrieval).parameters.items():
        if parameter.default is not inspect.Parameter.empty:
            assert parameter.default is None, f"match_retrieval's {name} has a default of its own"


def test_cashash_options_keep_one_set_of_defaults():
    # CasHashOptions() is the C++ struct's defaults, those of the runs'
    # MatchingOptions().cashash: matcher auto, tau and the rematch chosen.
    library, run = cashash.CasHashOptions(), cashash.MatchingOptions().cashash
    names = [name for name in dir(library) if not name.startswith("_")]
    assert "tau" in names and "exact_rematch_min_matches" in names
    for name in names:
        assert getattr(library, name) == getattr(run, name), name
    assert (library.matcher, library.tau, library.exact_rematch_min_matches) == ("auto", 0, -1)


def test_database_errors_carry_cli_messages(tmp_path, scene_database):
    with pytest.raises(RuntimeError, match="database file not found: "):
        cashash.match_exhaustive(tmp_path / "missing.db")
    with pytest.raises(ValueError, match="--ExhaustiveMatching.block_size must be >= 2"):
        cashash.match_exhaustive(scene_database, block_size=1)


def test_progress_callback_error_stops_and_propagates(scene_database):
    def fail(done, total):
        raise KeyError("stop here")

    with pytest.raises(KeyError, match="stop here"):
        cashash.match_exhaustive(scene_database, progress=fail, block_size=2)


def test_warnings_become_runtime_warnings(tmp_path, views):
    import shutil

    from conftest import View, write_database

    if shutil.which("colmap") is None:
        pytest.skip("colmap is not installed")
    tiny = View(views[1].keypoints[:1], views[1].descriptors[:1], views[1].point_of_row[:1])
    path = tmp_path / "tiny.db"
    write_database(path, [views[0], tiny])
    with pytest.warns(RuntimeWarning, match=r"image 2 \(view2.jpg\) has 1 feature; its pairs get empty matches"):
        summary = cashash.match_exhaustive(path)
    assert summary["pairs_done"] == 1 and summary["verified_pairs"] == 0


def test_max_gpu_memory_reaches_the_run_of_every_call(scene_database):
    # Each call's max_gpu_memory is its own run's GPU matcher budget, for
    # pair lists too, not the first call's for the whole process.
    for given, expected in (("512M", 512 << 20), ("1G", 1 << 30), ("", 0)):
        summary = cashash.match_exhaustive(scene_database, overwrite=True, max_gpu_memory=given)
        assert summary["run"]["gpu_memory_budget_bytes"] == expected
        summary = cashash.match_pairs(scene_database, [("view1.jpg", "view2.jpg")], overwrite=True,
                                      max_gpu_memory=given)
        assert summary["run"]["gpu_memory_budget_bytes"] == expected


def test_a_given_rematch_threshold_and_block_size_are_kept(scene_database):
    summary = cashash.match_exhaustive(scene_database, exact_rematch_min_matches=12, block_size=2)
    assert summary["run"]["exact_rematch_min_matches"] == 12
    assert summary["run"]["block_size"] == 2
    # Not given: chosen for the run, the block size from the memory caps.
    summary = cashash.match_exhaustive(scene_database, overwrite=True)
    assert summary["run"]["exact_rematch_min_matches"] == 12  # hundreds of features: not the bucket screen
    assert 2 <= summary["run"]["block_size"] <= 50


def test_build_info_names_the_version_and_the_gpu_code():
    info = cashash.build_info()
    assert info["version"]
    assert info["cuda"] == cashash.with_cuda
    if info["cuda"]:
        assert info["cuda_sass"] or info["cuda_ptx"]
        assert info["cuda_architectures"] != "none"
    else:
        assert info["cuda_architectures"] == "none"


def stored_pairs(path):
    db = sqlite3.connect(str(path))
    pairs = {divmod(int(pair_id), 2147483647) for (pair_id,) in db.execute("SELECT pair_id FROM matches")}
    db.close()
    return pairs


def test_match_sequential_pairs_neighbours_in_name_order(scene_database):
    summary = cashash.match_sequential(scene_database, pairing_options={"overlap": 1, "quadratic_overlap": False})
    assert summary["pairs_requested"] == 2 and summary["pairs_done"] == 2
    assert stored_pairs(scene_database) == {(1, 2), (2, 3)}
    options = cashash.SequentialPairingOptions()
    assert options.overlap == 10 and options.quadratic_overlap and not options.loop_detection
    again = cashash.match_sequential(scene_database, pairing_options=options)  # adds 1-3, resumes the others
    assert again["pairs_skipped"] == 2 and again["pairs_done"] == 1
    # Loop detection retrieves from the hash codes; its pairs are among the three matched.
    looped = cashash.match_sequential(scene_database, pairing_options={"loop_detection": True, "overlap": 1})
    assert looped["pairs_done"] == 0 and looped["pairs_skipped"] >= 2
    with pytest.raises(TypeError, match="unknown pairing option 'overlapp'"):
        cashash.match_sequential(scene_database, pairing_options={"overlapp": 3})


def test_match_sequential_takes_pycolmaps_options(scene_database):
    pycolmap = pytest.importorskip("pycolmap")
    options = pycolmap.SequentialPairingOptions(overlap=1, quadratic_overlap=False)
    assert cashash.match_sequential(scene_database, pairing_options=options)["pairs_requested"] == 2


def test_match_spatial_pairs_neighbours_by_prior(scene_database):
    db = sqlite3.connect(str(scene_database))  # COLMAP 3.8: priors in images
    db.executemany("UPDATE images SET prior_tx = ?, prior_ty = 0, prior_tz = 0 WHERE image_id = ?",
                   [(1.0, 1), (2.0, 2), (9.0, 3)])
    db.commit()
    db.close()
    summary = cashash.match_spatial(scene_database, pairing_options={"max_distance": 2.0, "is_gps": False})
    assert summary["pairs_requested"] == 1
    assert stored_pairs(scene_database) == {(1, 2)}
    assert cashash.SpatialPairingOptions().max_num_neighbors == 50
    with pytest.raises(ValueError, match="--SpatialMatching.max_num_neighbors must be > 0"):
        cashash.match_spatial(scene_database, pairing_options={"max_num_neighbors": 0})


def test_match_spatial_names_images_without_prior(scene_database):
    db = sqlite3.connect(str(scene_database))
    db.execute("UPDATE images SET prior_tx = 1, prior_ty = 1 WHERE image_id < 3")
    db.commit()
    db.close()
    with pytest.warns(RuntimeWarning, match="1 of the 3 images has no position prior.*view3.jpg"):
        summary = cashash.match_spatial(scene_database, pairing_options={"is_gps": False})
    assert summary["pairs_requested"] == 1
