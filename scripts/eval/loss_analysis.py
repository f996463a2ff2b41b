"""Where cascade hashing loses correct matches, and why.

For every pair the correct brute-force matches (within eps of the ground
truth) are split into those the cascade keeps and those it loses; a lost
match is either absent (the query got no match) or replaced (the query was
matched to another feature). The first level of the cascade finds a
partner only if both descriptors fall into the same bucket of at least one
table; for random hyperplanes a bit agrees with probability 1 - theta/pi,
theta being the angle between the mean-centred descriptors, so a table of b
bits collides with probability (1 - theta/pi)^b and one of T tables with
1 - (1 - (1 - theta/pi)^b)^T. Binning the brute-force matches by theta and
comparing the kept fraction with this curve shows whether the losses are
first-level misses of dissimilar descriptors.
"""
import numpy as np

from eval import colmap_db

ANGLE_BINS = np.radians(np.arange(0, 95, 5))


def centred_angles(d1, d2, mean):
    a = d1.astype(np.float64) - mean
    b = d2.astype(np.float64) - mean
    cos = (a * b).sum(axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) + 1e-12)
    return np.arccos(np.clip(cos, -1, 1))


def collision_probability(theta, tables, bits):
    return 1 - (1 - (1 - theta / np.pi) ** bits) ** tables


def analyse_sequence(features_db, brute, cascade, eps):
    """brute, cascade: homography.evaluate_database results. Returns per-pair
    counts and the (angle, kept) arrays of all correct brute-force matches."""
    db = colmap_db.Database(features_db)
    ids = db.image_ids_by_name()
    descriptors = {i: db.descriptors(ids["img%d.png" % i]) for i in range(1, 7)}
    db.close()
    mean = np.round(np.vstack(list(descriptors.values())).astype(np.float64).mean(axis=0))
    per_pair, angles, kept_flags = {}, [], []
    for key in brute:
        b, c = brute[key], cascade[key]
        b_ok = b["pairs"][b["errors"] <= eps]
        c_ok = c["pairs"][c["errors"] <= eps]
        cascade_set = {tuple(p) for p in c["pairs"].tolist()}
        cascade_query = {p[0] for p in c["pairs"].tolist()}
        kept = np.array([tuple(p) in cascade_set for p in b_ok.tolist()], dtype=bool)
        replaced = sum(1 for p, k in zip(b_ok.tolist(), kept) if not k and p[0] in cascade_query)
        b_set = {tuple(p) for p in b["pairs"].tolist()}
        extra_correct = sum(1 for p in c_ok.tolist() if tuple(p) not in b_set)
        n = int(key.split("-")[1])
        is_extra = np.array([tuple(p) not in b_set for p in c["pairs"].tolist()], dtype=bool)
        extra_reasons = classify_extra_matches(descriptors[1], descriptors[n], c["pairs"][is_extra],
                                               c["errors"][is_extra] <= eps) if len(is_extra) else None
        theta = centred_angles(descriptors[1][b_ok[:, 0]], descriptors[n][b_ok[:, 1]], mean) \
            if len(b_ok) else np.zeros(0)
        per_pair[key] = {
            "brute_correct": int(len(b_ok)), "kept": int(kept.sum()), "lost": int((~kept).sum()),
            "lost_replaced": int(replaced), "lost_absent": int((~kept).sum() - replaced),
            "cascade_only_correct": int(extra_correct),
            "cascade_only": int(is_extra.sum()) if len(is_extra) else 0,
            "cascade_only_reasons": extra_reasons,
            "brute_wrong": int((b["errors"] > eps).sum()), "cascade_wrong": int((c["errors"] > eps).sum()),
            "median_angle_kept_deg": float(np.degrees(np.median(theta[kept]))) if kept.any() else None,
            "median_angle_lost_deg": float(np.degrees(np.median(theta[~kept]))) if (~kept).any() else None,
        }
        angles.append(theta)
        kept_flags.append(kept)
    return per_pair, np.concatenate(angles), np.concatenate(kept_flags)


def classify_extra_matches(d1, d2, extra, correct, max_ratio=0.8):
    """Why the cascade returns matches that brute force does not.

    extra: (i, j) cascade matches absent from brute force; correct: whether
    each is within eps. Returns counts by reason and correctness:
    'ratio': j is i's exact nearest neighbour, but the exact second best makes
    the ratio test fail (the cascade never saw that second best);
    'not_nearest': j is not i's exact nearest neighbour (the nearest was not a
    candidate); 'other': nearest and passing the ratio test (cross check)."""
    counts = {r: {"correct": 0, "wrong": 0} for r in ("ratio", "not_nearest", "other")}
    if len(extra) == 0:
        return counts
    dots = d1[extra[:, 0]].astype(np.int64) @ d2.T.astype(np.int64)
    order = np.argsort(-dots, axis=1, kind="stable")[:, :2]
    for row, ((i, j), ok) in enumerate(zip(extra.tolist(), correct)):
        best, second = order[row]
        angle = np.arccos(np.minimum(dots[row, [best, second]] / 512.0 ** 2, 1.0))
        if best != j:
            reason = "not_nearest"
        elif angle[0] >= max_ratio * angle[1]:
            reason = "ratio"
        else:
            reason = "other"
        counts[reason]["correct" if ok else "wrong"] += 1
    return counts


def kept_by_angle(angles, kept):
    """[(bin centre deg, count, kept fraction)] over ANGLE_BINS."""
    rows = []
    for lo, hi in zip(ANGLE_BINS[:-1], ANGLE_BINS[1:]):
        inside = (angles >= lo) & (angles < hi)
        if inside.sum() >= 20:
            rows.append((float(np.degrees((lo + hi) / 2)), int(inside.sum()), float(kept[inside].mean())))
    return rows

