"""Writes docs/ACCURACY.md, the users' page of the accuracy figures, and its
plots, from the results of one scripts/evaluate_accuracy.py run.

The full report (report.py) holds every pair and every sweep; this page
states the rules the run checks, with the tables and plots that show them,
so that the page's figures are always those of the run that wrote it.
"""
import datetime
import os
import platform
import subprocess
import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from eval import loss_analysis, report  # noqa: E402

DOC_MATCHERS = ["cascade", "cascade_gpu", "bruteforce", "colmap"]
SEQUENCE_NAMES = {"hpatches_v_graffiti": "v_graffiti"}
DPI = 90


def _name(sequence):
    return SEQUENCE_NAMES.get(sequence, sequence)


def _legend_above(fig, axis):
    handles, labels = axis.get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=len(labels), fontsize=8, frameon=False)


def _save(fig, img_dir, name):
    os.makedirs(img_dir, exist_ok=True)
    fig.tight_layout(rect=(0, 0, 1, 0.92))
    fig.savefig(os.path.join(img_dir, name), dpi=DPI)
    plt.close(fig)
    return name


def plot_precision(results, img_dir):
    """Precision at 6 px and correct matches against brute force's, per sequence and matcher."""
    names = list(results)
    matchers = [m for m in DOC_MATCHERS if any(m in by for by in results.values())]
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6))
    width = 0.8 / len(matchers)
    x = np.arange(len(names))
    for k, matcher in enumerate(matchers):
        precision = [100 * report._totals(results[n], matcher, 6)[2] if matcher in results[n] else np.nan
                     for n in names]
        left.bar(x + (k - (len(matchers) - 1) / 2) * width, precision, width, color=report.COLOURS[matcher],
                 label=report.LABELS[matcher])
        if matcher != "bruteforce":
            kept = []
            for n in names:
                if matcher not in results[n]:
                    kept.append(np.nan)
                    continue
                correct = report._totals(results[n], matcher, 6)[1]
                kept.append(100 * correct / max(report._totals(results[n], "bruteforce", 6)[1], 1))
            right.bar(x + (k - (len(matchers) - 1) / 2) * width, kept, width, color=report.COLOURS[matcher],
                      label=report.LABELS[matcher])
    low = min(100 * report._totals(by, m, 6)[2] for by in results.values() for m in matchers if m in by)
    left.set_ylim(max(0, 5 * int(low / 5) - 5), 100)
    left.set_ylabel("precision at 6 px (%)")
    left.set_title("Share of the raw matches that are correct")
    right.axhline(90, color="k", lw=0.8, ls="--")
    right.set_ylim(min(80, left.get_ylim()[0]), 102)
    right.set_ylabel("correct matches, % of brute force's")
    right.set_title("Correct matches found (dashed: the 90 % rule)")
    for axis in (left, right):
        axis.set_xticks(x)
        axis.set_xticklabels([_name(n) for n in names])
        axis.grid(axis="y", alpha=0.3)
    _legend_above(fig, left)
    return _save(fig, img_dir, "accuracy_homography.png")


def plot_loss_by_angle(by_angle, img_dir, tables, bits):
    fig, ax = plt.subplots(figsize=(5.6, 3.6))
    centres = [r[0] for r in by_angle]
    ax.plot(centres, [100 * r[2] for r in by_angle], "o-", ms=4, label="measured: correct brute-force matches kept")
    theta = np.radians(np.linspace(0, 90, 91))
    ax.plot(np.degrees(theta), 100 * loss_analysis.collision_probability(theta, tables, bits), "k--",
            label="model: same bucket in >= 1 of %d tables of %d bits" % (tables, bits))
    ax.set_xlabel("angle between the mean-centred descriptors (deg)")
    ax.set_ylabel("kept by the cascade (%)")
    ax.set_title("Where the cascade loses matches")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return _save(fig, img_dir, "accuracy_loss_by_angle.png")


def plot_cameras(cams, img_dir):
    """Median and largest camera position and rotation errors, per scene and matcher."""
    scenes = list(cams)
    matchers = [m for m in ("cascade", "bruteforce", "colmap") if any("position_median" in (cams[s].get(m) or {})
                                                                      for s in scenes)]
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6))
    width = 0.8 / max(len(matchers), 1)
    x = np.arange(len(scenes))
    for k, matcher in enumerate(matchers):
        offset = x + (k - (len(matchers) - 1) / 2) * width
        for axis, key, scale in ((left, "position", 1000.0), (right, "rotation", 1.0)):
            suffix = "" if key == "position" else "_deg"
            median = [scale * cams[s][matcher][key + "_median" + suffix] if "position_median" in
                      (cams[s].get(matcher) or {}) else np.nan for s in scenes]
            largest = [scale * cams[s][matcher][key + "_max" + suffix] if "position_median" in
                       (cams[s].get(matcher) or {}) else np.nan for s in scenes]
            axis.bar(offset, largest, width, color=report.COLOURS[matcher], alpha=0.35)
            axis.bar(offset, median, width, color=report.COLOURS[matcher], label=report.LABELS[matcher])
    left.set_ylabel("camera centre error (mm)")
    left.set_title("Position error (solid: median, light: largest)")
    right.set_ylabel("rotation error (deg)")
    right.set_title("Rotation error (solid: median, light: largest)")
    for axis in (left, right):
        axis.set_xticks(x)
        axis.set_xticklabels(scenes)
        axis.grid(axis="y", alpha=0.3)
    _legend_above(fig, left)
    return _save(fig, img_dir, "accuracy_cameras.png")


def _commit():
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, stdout=subprocess.PIPE,
                          text=True).stdout.strip()


def homography_lines(results, gpu_info, img_rel, plot):
    lines = ["| sequence | precision at 6 px, cascade / brute force / COLMAP 3.8 | cascade - brute force | "
             "correct, cascade / brute force |", "|---|---|---:|---:|"]
    for name, by in results.items():
        precision = {m: 100 * report._totals(by, m, 6)[2] for m in ("cascade", "bruteforce", "colmap") if m in by}
        correct = report._totals(by, "cascade", 6)[1] / max(report._totals(by, "bruteforce", 6)[1], 1)
        lines.append("| %s | %s %% | %+.2f points | %.1f %% |" % (
            _name(name), " / ".join("%.1f" % precision[m] if m in precision else "-"
                                    for m in ("cascade", "bruteforce", "colmap")),
            precision["cascade"] - precision["bruteforce"], 100 * correct))
    misses = []
    for name, by in results.items():
        diff = 100 * (report._totals(by, "cascade", 6)[2] - report._totals(by, "bruteforce", 6)[2])
        kept = report._totals(by, "cascade", 6)[1] / max(report._totals(by, "bruteforce", 6)[1], 1)
        if abs(diff) > 2 or kept < 0.9:
            misses.append(_name(name))
    lines += ["", "Met on %s." % ("every sequence" if not misses else "all but " + ", ".join(misses)
                                  + " (**not met** there)"),
              "", "![precision and correct matches per sequence](%s/%s)" % (img_rel, plot), ""]
    if gpu_info:
        cpu = sum(r["cpu"] for p in gpu_info["agreement"].values() for r in p.values())
        same = sum(r["identical"] for p in gpu_info["agreement"].values() for r in p.values())
        lines += ["The GPU cascade (%s) returned %s of the CPU cascade's %s rows on these sequences." % (
            gpu_info["device"] or "device not recorded", "{:,}".format(same), "{:,}".format(cpu)), ""]
    else:
        lines += ["The GPU cascade is not in this run (no GPU here); its tests compare it with the CPU cascade, "
                  "and `--export-gpu-inputs DIR` with `--gpu-results DIR` adds its column from a GPU machine.", ""]
    return lines


def loss_lines(losses, by_angle, tables, bits, img_rel, plot):
    total_lost = sum(r["lost"] for p in losses.values() for r in p.values())
    total_bc = sum(r["brute_correct"] for p in losses.values() for r in p.values())
    absent = sum(r["lost_absent"] for p in losses.values() for r in p.values())
    replaced = sum(r["lost_replaced"] for p in losses.values() for r in p.values())
    worst = max(((r["lost"] / r["brute_correct"], n, k) for n, p in losses.items() for k, r in p.items()
                 if r["brute_correct"] >= 50), default=None)
    lines = ["*Measured:* of %s correct brute-force matches the cascade lost %s (%.1f %%): %s because the query "
             "got no cascade match at all, %s because a wrong candidate replaced the right one." % (
                 "{:,}".format(total_bc), "{:,}".format(total_lost), 100.0 * total_lost / max(total_bc, 1),
                 "{:,}".format(absent), "{:,}".format(replaced))]
    if worst:
        lines[-1] += " The worst pair (%s %s) lost %.1f %%." % (_name(worst[1]), worst[2], 100 * worst[0])
    lines += ["", "The share kept, by the angle between the mean-centred descriptors, against the collision model "
              "1 - (1 - (1 - theta/pi)^%d)^%d:" % (bits, tables), "",
              "| angle (deg) | correct brute-force matches | kept | model |", "|---:|---:|---:|---:|"]
    for centre, count, kept in by_angle:
        if count:
            lines.append("| %.1f | %s | %.1f %% | %.1f %% |" % (
                centre, "{:,}".format(count), 100 * kept,
                100 * loss_analysis.collision_probability(np.radians(centre), tables, bits)))
    lines += ["", "![kept share by descriptor angle](%s/%s)" % (img_rel, plot), ""]
    return lines


def camera_lines(cams, img_rel, plot):
    lines = ["| scene | matcher | registered | position error median / max (mm) | rotation error median / max (deg) "
             "| matching CPU s |", "|---|---|---|---|---|---:|"]
    for scene, by in cams.items():
        for matcher in ("cascade", "bruteforce", "colmap"):
            s = by.get(matcher)
            if not s or "position_median" not in s:
                lines.append("| %s | %s | not run | | | |" % (scene, report.LABELS[matcher]))
                continue
            lines.append("| %s | %s | %d / %d | %.1f / %.1f | %.3f / %.3f | %s |" % (
                scene, report.LABELS[matcher], s["registered"], s["gt_images"], 1000 * s["position_median"],
                1000 * s["position_max"], s["rotation_median_deg"], s["rotation_max_deg"],
                report._fmt(s.get("match_cpu_s"), 1)))
    verdicts = []
    for scene, by in cams.items():
        c, o = by.get("cascade") or {}, by.get("colmap") or {}
        if "position_median" in c and "position_median" in o:
            keys = ["position_median", "position_max", "rotation_median_deg"]
            ok = c["registered"] >= o["registered"] and all(c[k] <= 1.1 * o[k] for k in keys)
            verdicts.append("%s: %s" % (scene, "met" if ok else "**not met**"))
    if verdicts:
        lines += ["", "The cascade registers as many cameras as COLMAP's matcher, with median and largest position "
                  "errors and median rotation error at most 10 % above its: " + "; ".join(verdicts) + "."]
    lines += ["", "![camera errors against the ground truth](%s/%s)" % (img_rel, plot), ""]
    kept = ["%s %.1f %%" % (scene, 100 * by["cascade"]["inliers_kept_vs_bruteforce"]) for scene, by in cams.items()
            if by.get("cascade", {}).get("inliers_kept_vs_bruteforce") is not None]
    if kept:
        lines += ["Of brute force's verified inlier matches the cascade's own matches verify: %s." % ", ".join(kept),
                  ""]
    return lines


def write(args, command, results, losses, by_angle, cams, gpu_info):
    """Writes args.doc and its plots into args.doc_img_dir."""
    tables, bits, tau, top_k = [int(v) for v in args.cascade.split(",")]
    img_rel = os.path.relpath(os.path.abspath(args.doc_img_dir), os.path.dirname(os.path.abspath(args.doc)))
    lines = [
        "# Accuracy against ground truth", "",
        "What the cascade costs in correct matches and in camera accuracy, measured against ground truth rather "
        "than against another matcher. This page, its tables and its plots are written by one command "
        "(COLMAP for the features and the mapper, the photographs of `../shared/data` read in place):", "",
        "```sh", command, "```", "",
        "Written %s from commit %s on %s, %d CPU cores%s. The command also writes a full report (every pair; "
        "with the sweeps unless `--skip-sweeps`) to `--report`, and `python3 scripts/eval/selftest.py` checks "
        "its arithmetic." % (datetime.date.today().isoformat(), _commit(), platform.machine(), os.cpu_count(),
                             ", with a GPU" if gpu_info else ", no GPU"), "",
        "The figures are those of the cascade's **own** matches (%d tables x %d bits, tau %d, top_k %d, "
        "`--CasHash.exact_rematch_min_matches 0`), as guided matching keeps them. The default exact rematch "
        "replaces the matches of every pair with enough cascade matches by exact matching's, so those pairs "
        "have brute force's figures." % (tables, bits, tau, top_k), "",
        "## Rules checked", "",
        "**The cascade's precision at 6 px stays within 2 points of exact matching's, with at least 90 % of its "
        "correct matches.** *Why:* a cascade match whose close second best was never ranked passes the ratio "
        "test wrongly; tau and top_k must rank enough candidates to see it (docs/cascade_parameters.md). "
        "*Measured* on the homography sequences (Oxford graf, boat, bikes, leuven; HPatches v_graffiti; raw "
        "matches of pairs 1-2 ... 1-6, COLMAP 3.8 SIFT; correct = within 6 px of the ground-truth homography):",
        ""]
    lines += homography_lines(results, gpu_info, img_rel, plot_precision(results, args.doc_img_dir))
    lines += ["**The cascade loses matches only through its first level.** *Why:* a true match whose hash bits "
              "differ from its query's in every table is never a candidate.", ""]
    lines += loss_lines(losses, by_angle, tables, bits, img_rel,
                        plot_loss_by_angle(by_angle, args.doc_img_dir, tables, bits))
    if cams:
        lines += ["**Cameras are as accurate as with COLMAP's matcher.** *Why:* what a user finally needs is the "
                  "reconstruction. *Measured* (Strecha's %s, `colmap mapper` after each "
                  "matcher, similarity alignment to the ground-truth centres; matching CPU s is the matcher's whole process, "
                  "verification included):" % " and ".join(cams), ""]
        lines += camera_lines(cams, img_rel, plot_cameras(cams, args.doc_img_dir))
        medians = [s["rotation_median_deg"] for by in cams.values() for s in by.values()
                   if s and "rotation_median_deg" in s]
        if medians:
            spread = "%.2f" % min(medians) if "%.2f" % min(medians) == "%.2f" % max(medians) else \
                "%.2f-%.2f" % (min(medians), max(medians))
            lines += ["The rotation errors (median %s degrees) are alike for every matcher: COLMAP keeps the "
                      "principal point at the image centre, about 23 px from the ground truth's, which alone tilts "
                      "a camera by up to half a degree." % spread, ""]
    lines += ["## Sweeps", "",
              "The full report holds the paper's tau figure and the top_k, bits and tables sweeps on %s. Their "
              "conclusions, with their figures, are the rules of docs/cascade_parameters.md." % args.sweep_scene, ""]
    with open(args.doc, "w") as f:
        f.write("\n".join(_wrapped(lines)))


def _wrapped(lines):
    """Prose wrapped at 76 columns as the other pages are; tables, code and images as they are."""
    out, in_code = [], False
    for line in lines:
        if line.startswith("```"):
            in_code = not in_code
        if in_code or line.startswith(("|", "![", "#", "```")) or not line:
            out.append(line)
        else:
            out.extend(textwrap.wrap(line, 76, break_long_words=False, break_on_hyphens=False))
    return out
