"""Cascade Hashing feature matching for COLMAP databases.

    import cashash
    cashash.match_exhaustive("database.db")                 # like pycolmap.match_exhaustive
    cashash.match_pairs("database.db", [("a.jpg", "b.jpg")])
    cashash.match_retrieval("database.db", num_images=50)   # like pycolmap.match_vocabtree, no tree
    cashash.match_sequential("database.db", pairing_options={"overlap": 10})
    cashash.match_spatial("database.db", pairing_options=cashash.SpatialPairingOptions())
    result = cashash.match(desc1, desc2, kp1, kp2)         # numpy in, numpy out

Options are keywords named as the fields of MatchingOptions and of its parts
(SiftMatchingOptions, CasHashOptions, TwoViewGeometryOptions), e.g.
``max_ratio=0.8, num_tables=7, min_num_inliers=15, block_size=50``; a
prepared ``options=MatchingOptions()`` may be passed as well. Errors raise
ValueError (an option out of range) or RuntimeError (unusable input) with
the messages of the ``cashash`` command line.
"""

import numpy as np

from . import _core
from ._core import (CasHashOptions, MatchingOptions, RetrievalOptions, SequentialPairingOptions, SiftMatchingOptions,
                    SpatialPairingOptions, TwoViewGeometryOptions)

__all__ = [
    "CasHashOptions",
    "build_info",
    "MatchingOptions",
    "SiftMatchingOptions",
    "TwoViewGeometryOptions",
    "make_options",
    "match",
    "match_exhaustive",
    "match_pairs",
    "match_retrieval",
    "match_vocabtree",
    "RetrievalOptions",
    "match_sequential",
    "match_spatial",
    "SequentialPairingOptions",
    "SpatialPairingOptions",
    "with_cuda",
]

with_cuda = _core.with_cuda


def build_info():
    """Version and GPU code of this build: {"version", "cuda", "cuda_sass",
    "cuda_ptx", "cuda_architectures"} (SASS and PTX as compute capabilities
    times ten, e.g. 75 for sm_75)."""
    return _core.build_info()

# COLMAP's two-view configuration names by value (TwoViewGeometry config).
TWO_VIEW_CONFIGS = {
    0: "UNDEFINED", 1: "DEGENERATE", 2: "CALIBRATED", 3: "UNCALIBRATED", 4: "PLANAR",
    5: "PANORAMIC", 6: "PLANAR_OR_PANORAMIC", 7: "WATERMARK", 8: "MULTIPLE",
}


def _fields(obj):
    return [name for name in dir(obj) if not name.startswith("_")]


# The parts of MatchingOptions; keywords name the fields of the first four
# (pairing options travel in pairing_options, whose names would clash).
_PARTS = ("sift", "cashash", "two_view", "retrieval", "sequential", "spatial")


def make_options(options=None, **kwargs):
    """A MatchingOptions from `options` (copied) with keyword fields set.

    A keyword names a field of MatchingOptions or of one of its parts; an
    unknown keyword raises TypeError.
    """
    result = MatchingOptions()
    if options is None:
        # The GPU is used only where it was built, so that CPU builds do
        # not warn on every call.
        result.use_gpu = with_cuda
    else:
        for part in _PARTS:
            source, target = getattr(options, part), getattr(result, part)
            for name in _fields(source):
                if name != "check":
                    setattr(target, name, getattr(source, name))
        for name in _fields(options):
            if name not in _PARTS:
                setattr(result, name, getattr(options, name))
    for name, value in kwargs.items():
        for target in (result, result.sift, result.cashash, result.two_view):
            if name in _fields(target) and name not in _PARTS:
                setattr(target, name, value)
                break
        else:
            raise TypeError(f"unknown matching option '{name}'")
    return result


def match_exhaustive(database_path, options=None, progress=None, **kwargs):
    """Matches and verifies every image pair of a COLMAP database.

    Writes the matches and two_view_geometries tables as
    ``colmap exhaustive_matcher`` does; pairs already there are skipped
    unless ``overwrite=True``. ``progress(pairs_done, pairs_total)`` is
    called after each committed block; an exception it raises stops the run
    (finished blocks stay committed) and is raised again. Returns a dict of
    counts: pairs_requested, pairs_skipped, pairs_done, raw_matches,
    verified_pairs, inlier_matches, seconds, matcher, stopped,
    gpu_memory_peak_held_bytes (what the run's owner of GPU memory held at
    most, 0 without a GPU), gpu_memory_fallbacks (times a GPU part went on
    on the CPU for want of device memory); and run, a
    dict of how the run was resolved from the options and the database
    (matcher, num_tables, bits_per_table, tau, exact_rematch_min_matches,
    exact_rematch_max_matches, rematch_on_matching_thread, exact_rematch_where, block_size, blocks_per_group, gpu_index,
    gpu_memory_budget_bytes, max_host_bytes), as the command line resolves
    the same inputs.
    """
    return _core.match_exhaustive(str(database_path), make_options(options, **kwargs), progress)


def match_pairs(database_path, pairs, options=None, progress=None, **kwargs):
    """Like match_exhaustive, for the given (name1, name2) image pairs."""
    pairs = [(str(a), str(b)) for a, b in pairs]
    return _core.match_pairs(str(database_path), pairs, make_options(options, **kwargs), progress)


def match_retrieval(database_path, num_images=None, options=None, progress=None, num_nearest_neighbors=None,
                    max_num_features=None, retrieval_num_tables=None, bits_per_word=None, transitive_rounds=None,
                    vocab_tree_path=None, **kwargs):
    """Like match_exhaustive, for the pairs retrieval chooses: each image with
    its num_images most similar images, similarity from visual words taken
    from the cascade's hash codes (no vocabulary tree; docs/retrieval.md).

    num_images, num_nearest_neighbors and max_num_features are COLMAP's
    VocabTreeMatching options; retrieval_num_tables and bits_per_word shape
    the words (Retrieval.num_tables, Retrieval.bits_per_word; 0 bits =
    chosen from the features per image). transitive_rounds > 0 then matches
    the pairs the verified graph implies, as COLMAP's transitive_matcher.
    vocab_tree_path is accepted and not used (a warning says so). A keyword
    left out keeps the value of ``options`` (by default RetrievalOptions'
    and MatchingOptions', the command line's defaults).
    """
    opts = make_options(options, **kwargs)
    retrieval = opts.retrieval
    given = {"num_images": num_images, "num_nearest_neighbors": num_nearest_neighbors,
             "max_num_features": max_num_features, "num_tables": retrieval_num_tables, "bits_per_word": bits_per_word}
    for name, value in given.items():
        if value is not None:
            setattr(retrieval, name, int(value))
    opts.retrieval = retrieval
    if transitive_rounds is not None:
        opts.transitive_rounds = int(transitive_rounds)
    if vocab_tree_path is not None:
        opts.vocab_tree_path = str(vocab_tree_path)
    return _core.match_retrieval(str(database_path), opts, progress)


# pycolmap's name for the matcher it replaces.
match_vocabtree = match_retrieval


def _descriptors(array):
    array = np.asarray(array)
    if array.dtype != np.uint8:
        # Float SIFT descriptors (unit length) scale to bytes as COLMAP
        # stores them.
        array = np.clip(np.round(array.astype(np.float64) * 512.0), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(array)


def _camera(camera):
    """A camera as a dict for the C++ side, from a dict or a pycolmap.Camera."""
    if camera is None:
        return None
    get = camera.get if isinstance(camera, dict) else lambda name, default=None: getattr(camera, name, default)
    model = get("model")
    if model is None:
        model = get("model_id")
    if isinstance(model, str):
        names = {_core.camera_model_name(i): i for i in range(32) if _core.camera_model_name(i)}
        if model not in names:
            raise ValueError(f"unknown camera model '{model}'")
        model = names[model]
    elif hasattr(model, "value"):
        model = model.value
    return {
        "model_id": int(model),
        "width": int(get("width")),
        "height": int(get("height")),
        "params": [float(p) for p in get("params")],
        "has_prior_focal_length": bool(get("has_prior_focal_length", True)),
    }


def match(descriptors1, descriptors2, keypoints1=None, keypoints2=None, camera1=None, camera2=None,
          options=None, **kwargs):
    """Matches two images' features in memory, no database involved.

    descriptors: N x 128 uint8 (or float SIFT, scaled by 512). keypoints:
    N x 2 or wider (x, y first) in pixels; with both given the matches are
    verified geometrically. cameras: dicts with model ("PINHOLE" or id),
    width, height, params and has_prior_focal_length (default True), or
    pycolmap.Camera objects; without them the camera is guessed as COLMAP
    does and only F/H are estimated. Returns a dict: matches (M x 2 uint32),
    verified, config, config_name, inlier_matches (K x 2), F, E, H, qvec,
    tvec; and run, how the pair was resolved (as match_exhaustive's). The
    options are checked as match_exhaustive checks them, and the pair is
    matched as a run of two images is: use_gpu without a usable GPU
    matches as use_gpu=False does.
    """
    if options is None and "use_gpu" not in kwargs:
        kwargs["use_gpu"] = False
    kp1 = None if keypoints1 is None else np.asarray(keypoints1, dtype=np.float32)
    kp2 = None if keypoints2 is None else np.asarray(keypoints2, dtype=np.float32)
    result = _core.match(_descriptors(descriptors1), _descriptors(descriptors2), kp1, kp2, _camera(camera1),
                         _camera(camera2), make_options(options, **kwargs))
    result["config_name"] = TWO_VIEW_CONFIGS.get(result["config"], str(result["config"]))
    return result


def _pairing_options(target, pairing_options):
    """Copies `pairing_options` into `target` (a SequentialPairingOptions or
    SpatialPairingOptions): a dict, or any object with fields of the same
    names (cashash's own, or pycolmap's options of the same name). An unknown
    dict key raises TypeError; fields of a foreign object that cashash lacks
    are ignored."""
    if pairing_options is None:
        return
    known = [name for name in _fields(target) if name != "check"]
    if isinstance(pairing_options, dict):
        items = pairing_options.items()
        for name, _ in items:
            if name not in known:
                raise TypeError(f"unknown pairing option '{name}' (known: {', '.join(known)})")
    else:
        items = [(name, getattr(pairing_options, name)) for name in known if hasattr(pairing_options, name)]
    for name, value in items:
        if name == "vocab_tree_path":
            value = "" if str(value) in ("", ".") else str(value)  # pycolmap shows an empty path as "."
        setattr(target, name, value)


def match_sequential(database_path, options=None, pairing_options=None, progress=None, **kwargs):
    """Matches the pairs of ``colmap sequential_matcher``, as
    ``pycolmap.match_sequential`` does: images in name order, each with its
    next ``overlap`` images (1, 2, 4, ... places on with
    ``quadratic_overlap``), rig frames expanded; with ``loop_detection``
    also every ``loop_detection_period``-th image with the images most like
    it (image retrieval from the cascade's codes, no vocabulary tree).
    ``pairing_options`` is a SequentialPairingOptions, a dict of its fields
    or pycolmap's SequentialPairingOptions. Otherwise as match_exhaustive."""
    resolved = make_options(options, **kwargs)
    _pairing_options(resolved.sequential, pairing_options)
    return _core.match_sequential(str(database_path), resolved, progress)


def match_spatial(database_path, options=None, pairing_options=None, progress=None, **kwargs):
    """Matches the pairs of ``colmap spatial_matcher``, as
    ``pycolmap.match_spatial`` does: each image with a position prior with
    its nearest neighbours by that prior (``max_num_neighbors`` within
    ``max_distance``, at least ``min_num_neighbors``; GPS priors compared in
    metres). Images without a prior are left out with a warning, as COLMAP
    leaves them out. ``pairing_options`` is a SpatialPairingOptions, a dict
    of its fields or pycolmap's SpatialPairingOptions. Otherwise as
    match_exhaustive."""
    resolved = make_options(options, **kwargs)
    _pairing_options(resolved.spatial, pairing_options)
    return _core.match_spatial(str(database_path), resolved, progress)
