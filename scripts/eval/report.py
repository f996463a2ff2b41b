"""Writes the full accuracy report and its PNG plots from the evaluation results."""
import datetime
import os
import platform
import subprocess

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from eval import loss_analysis  # noqa: E402

LABELS = {"cascade": "cashash cascade (CPU)", "cascade_gpu": "cashash cascade (GPU)",
          "bruteforce": "cashash brute force", "colmap": "COLMAP 3.8 CPU matcher",
          "cascade_r078": "cashash cascade, max_ratio 0.78"}
COLOURS = {"cascade": "tab:blue", "cascade_gpu": "tab:cyan", "bruteforce": "tab:orange", "colmap": "tab:green",
           "cascade_r078": "tab:purple"}
DPI = 80


def _save(fig, out_dir, name):
    path = os.path.join(out_dir, name)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return name


def _precision(pair, eps):
    return pair["correct"][str(eps)] / pair["matches"] if pair["matches"] else 0.0


def _totals(by_matcher, matcher, eps):
    pairs = by_matcher[matcher]["pairs"].values()
    matches = sum(p["matches"] for p in pairs)
    correct = sum(p["correct"][str(eps)] for p in pairs)
    return matches, correct, correct / matches if matches else 0.0


def plot_homography(results, out_dir):
    names = list(results)
    fig, axes = plt.subplots(2, len(names), figsize=(2.6 * len(names), 4.6), sharex=True)
    for col, name in enumerate(names):
        for matcher, data in results[name].items():
            keys = list(data["pairs"])
            x = [int(k.split("-")[1]) for k in keys]
            axes[0, col].plot(x, [data["pairs"][k]["correct"]["6"] for k in keys], "o-", ms=3,
                              color=COLOURS[matcher], label=LABELS[matcher])
            axes[1, col].plot(x, [100 * _precision(data["pairs"][k], 6) for k in keys], "o-", ms=3,
                              color=COLOURS[matcher])
        axes[0, col].set_title(name, fontsize=9)
        axes[1, col].set_xlabel("pair 1-N", fontsize=8)
        axes[1, col].set_ylim(0, 102)
    axes[0, 0].set_ylabel("correct matches (6 px)", fontsize=8)
    axes[1, 0].set_ylabel("precision at 6 px (%)", fontsize=8)
    axes[0, 0].legend(fontsize=6)
    for ax in axes.flat:
        ax.tick_params(labelsize=7)
    return _save(fig, out_dir, "homography_correct_precision.png")


def plot_tau(tau, out_dir):
    taus = sorted(tau)
    fig, (a, b) = plt.subplots(1, 2, figsize=(8, 3.2))
    a.plot(taus, [tau[t]["scene_matches"] for t in taus], "o-", color="tab:blue", ms=3)
    a.set_xlabel("tau", fontsize=8)
    a.set_ylabel("raw matches (fountain-P11, 55 pairs)", fontsize=8, color="tab:blue")
    a2 = a.twinx()
    a2.plot(taus, [tau[t]["scene_cpu_s"] for t in taus], "s--", color="tab:red", ms=3)
    a2.set_ylabel("process CPU s, 1 thread", fontsize=8, color="tab:red")
    a.set_title("(a) matches and time", fontsize=9)
    for name in tau[taus[0]]["precision"]:
        b.plot(taus, [100 * tau[t]["precision"][name] for t in taus], "o-", ms=3, label=name)
    b.plot(taus, [100 * np.mean(list(tau[t]["precision"].values())) for t in taus], "k-", lw=2, label="mean")
    b.set_xlabel("tau", fontsize=8)
    b.set_ylabel("precision at 6 px (%)", fontsize=8)
    b.set_title("(b) precision, pairs 1-2 ... 1-6", fontsize=9)
    b.legend(fontsize=6)
    for ax in (a, a2, b):
        ax.tick_params(labelsize=7)
    return _save(fig, out_dir, "tau_sweep.png")


def plot_topk_bits(bench, out_dir, setting):
    """Recall and CPU time per pair when one of top_k, bits per table, number
    of tables moves away from setting = (tables, bits, tau, top_k)."""
    tables, bits, tau, top_k = setting
    rows = bench["rows"]
    series = [
        ("top_k", sorted((r for r in rows if (r["tables"], r["bits"]) == (tables, bits)), key=lambda r: r["top_k"]),
         "(a) top_k (%d x %d bits, tau %d)" % (tables, bits, tau)),
        ("bits", sorted((r for r in rows if r["tables"] == tables and r["top_k"] == top_k), key=lambda r: r["bits"]),
         "(b) bits per table (%d tables, top_k %d)" % (tables, top_k)),
        ("tables", sorted((r for r in rows if r["bits"] == bits and r["top_k"] == top_k), key=lambda r: r["tables"]),
         "(c) tables (%d bits, top_k %d)" % (bits, top_k)),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.2))
    for ax, (key, sel, title) in zip(axes, series):
        x = [r[key] for r in sel]
        ax.plot(x, [100 * r["recall"] for r in sel], "o-", color="tab:blue", ms=3)
        ax.set_ylabel("recall vs brute force (%)", fontsize=8, color="tab:blue")
        ax.set_xlabel(key, fontsize=8)
        ax.set_title(title, fontsize=9)
        twin = ax.twinx()
        twin.plot(x, [1000.0 / r["pairs_per_cpu_s"] for r in sel], "s--", color="tab:red", ms=3)
        twin.set_ylabel("CPU ms per pair", fontsize=8, color="tab:red")
        twin.set_ylim(bottom=0)
        ax.tick_params(labelsize=7)
        twin.tick_params(labelsize=7)
    axes[0].set_xscale("log")
    # Neighbouring values (10, 12) would print on top of each other on the log axis.
    ticks = [k for k in (1, 2, 3, 5, 10, 16, 32) if any(r["top_k"] == k for r in series[0][1])]
    axes[0].set_xticks(ticks)
    axes[0].set_xticklabels([str(k) for k in ticks])
    axes[0].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    return _save(fig, out_dir, "topk_bits_sweep.png")


def plot_loss_by_angle(by_angle, out_dir, tables, bits):
    fig, ax = plt.subplots(figsize=(4.8, 3.2))
    centres = [r[0] for r in by_angle]
    ax.plot(centres, [100 * r[2] for r in by_angle], "o-", ms=3, label="measured (correct brute-force matches)")
    theta = np.radians(np.linspace(0, 90, 91))
    ax.plot(np.degrees(theta), 100 * loss_analysis.collision_probability(theta, tables, bits), "k--",
            label="P(same bucket in >= 1 of %d tables of %d bits)" % (tables, bits))
    ax.set_xlabel("angle between mean-centred descriptors (deg)", fontsize=8)
    ax.set_ylabel("kept by the cascade (%)", fontsize=8)
    ax.legend(fontsize=6)
    ax.tick_params(labelsize=7)
    return _save(fig, out_dir, "loss_by_angle.png")


def _fmt(value, digits=3):
    return "-" if value is None else ("%.*f" % (digits, value))


def gpu_paragraph(results, gpu_info, cascade_setting):
    """What the GPU rows are (device, options, where they ran) and how they agree with the CPU cascade."""
    ran_on = gpu_info["ran_on"]
    on_gpu = all(m.startswith("gpu-cascade") for m in ran_on.values())
    lines = ["The GPU cascade rows come from `--gpu-results`: `--export-gpu-inputs DIR` wrote the feature databases "
             "of the sequences and `run.sh`, which matched each with `cashash exhaustive_matcher "
             "--FeatureMatching.use_gpu 1` and the CPU cascade's --CasHash setting on the GPU machine (%s). Matcher that finished "
             "each run: %s." % (gpu_info["device"] or "device not recorded",
                                ", ".join("%s %s" % (n, m) for n, m in ran_on.items()))]
    if not on_gpu:
        lines[-1] += (" **Not a GPU measurement**: at least one run finished on the CPU (no GPU, or a fallback), so "
                      "these rows only check the export, run.sh and the read-back path.")
    defaults = gpu_info["defaults"]
    if defaults != cascade_setting:
        lines[-1] += (" **Setting mismatch**: the GPU run's setting (tables, bits, tau, top_k) is %s, the CPU "
                      "cascade ran with %s, so the rows below need not agree." % (defaults, cascade_setting))
    else:
        lines[-1] += " The GPU run's setting (tables, bits, tau, top_k = %s) equals the CPU cascade's." % defaults
    lines += ["", "Agreement with the CPU cascade (identical (idx1, idx2) rows of the raw matches):", "",
              "| sequence | CPU matches | GPU matches | identical rows | pairs with identical lists | "
              "GPU matching s (15 pairs) |", "|---|---|---|---|---|---|"]
    for name, per_pair in gpu_info["agreement"].items():
        cpu = sum(r["cpu"] for r in per_pair.values())
        gpu = sum(r["gpu"] for r in per_pair.values())
        same = sum(1 for r in per_pair.values() if r["same"])
        seconds = results[name]["cascade_gpu"]["timing"].get("matching_s")
        lines.append("| %s | %d | %d | %d (%.2f %%) | %d / %d | %s |" % (
            name, cpu, gpu, sum(r["identical"] for r in per_pair.values()),
            100.0 * sum(r["identical"] for r in per_pair.values()) / max(cpu, 1), same, len(per_pair),
            _fmt(seconds, 3)))
    return lines + [""]


def homography_section(results, use_gpu, eps_list, plot, cascade_text, gpu_info=None, cascade_setting=None):
    lines = ["## 1. Homography ground truth", "",
             "Features: COLMAP 3.8 CPU SIFT, default settings (images converted to PNG with Pillow first). "
             "Matches: the **raw** `matches` rows, before geometric verification, of pairs 1-2 ... 1-6. "
             "A match is correct when the ground-truth homography maps the keypoint of image 1 to within eps "
             "pixels of its partner in image N (eps = 6 px as in the paper, and 3 px). All matchers use "
             "COLMAP's defaults (ratio 0.8, max distance 0.7, cross check); the cascade %s." % cascade_text
             + " hpatches_v_graffiti holds the graf images (pixel for pixel "
             "the same, hence the same matches) with HPatches' own homographies, so only the correct counts "
             "differ. Pixel convention: COLMAP puts the centre of the upper-left pixel at (0.5, 0.5), the "
             "homographies at (0, 0); keypoints are shifted by 0.5 px before mapping (this gives the smallest "
             "median error on graf 1-2, 0.50 px against 0.56 px without the shift).", ""]
    gpu_rows = use_gpu or gpu_info is not None
    if gpu_info is not None:
        lines += gpu_paragraph(results, gpu_info, cascade_setting)
    elif not use_gpu:
        lines += ["The GPU cascade column is **not run here**: this machine has no GPU (the GPU cascade is checked "
                  "against the CPU cascade by its own tests). To fill it from a GPU machine without COLMAP or the "
                  "data: `scripts/evaluate_accuracy.py --export-gpu-inputs DIR` (the five feature databases and "
                  "`run.sh`, about 25 MB), there `DIR/run.sh <cashash binary>`, and back here the usual command "
                  "with `--reuse --gpu-results DIR`.", ""]
    lines += ["### Totals per sequence (pairs 1-2 ... 1-6) and the targets", "",
              "| sequence | matcher | matches | correct 6 px | precision 6 px | correct 3 px | precision 3 px |",
              "|---|---|---|---|---|---|---|"]
    checks = []
    for name, by in results.items():
        for matcher in by:
            m, c6, p6 = _totals(by, matcher, 6)
            _, c3, p3 = _totals(by, matcher, 3)
            lines.append("| %s | %s | %d | %d | %.1f %% | %d | %.1f %% |" % (name, LABELS[matcher], m, c6, 100 * p6,
                                                                           c3, 100 * p3))
        if not gpu_rows:
            lines.append("| %s | %s | not run here | | | | |" % (name, LABELS["cascade_gpu"]))
        _, bc, bp = _totals(by, "bruteforce", 6)
        for variant in ("cascade", "cascade_gpu", "cascade_r078"):
            if variant in by:
                _, cc, cp = _totals(by, variant, 6)
                checks.append((name, variant, 100 * (cp - bp), cc / bc if bc else 0.0))
    lines += ["", "Targets: cascade precision at 6 px within 2 points of brute force (ratio 0.8), and at least "
              "90 % of brute force's correct matches:", "",
              "| sequence | cascade | precision cascade - brute force (points) | correct cascade / brute force "
              "| met |", "|---|---|---|---|---|"]
    for name, variant, dp, ratio in checks:
        lines.append("| %s | %s | %+.2f | %.1f %% | %s |" % (
            name, LABELS[variant], dp, 100 * ratio, "yes" if abs(dp) <= 2 and ratio >= 0.9 else "**no**"))
    lines += ["", "![correct matches and precision](accuracy/%s)" % plot, "", "### Per pair", ""]
    for name, by in results.items():
        lines += ["**%s**" % name, "",
                  "| pair | matcher | matches | correct 6 px | precision 6 px | correct 3 px | precision 3 px |",
                  "|---|---|---|---|---|---|---|"]
        for key in next(iter(by.values()))["pairs"]:
            for matcher in by:
                p = by[matcher]["pairs"][key]
                lines.append("| %s | %s | %d | %d | %.1f %% | %d | %.1f %% |" % (
                    key, matcher, p["matches"], p["correct"]["6"], 100 * _precision(p, 6), p["correct"]["3"],
                    100 * _precision(p, 3)))
        lines.append("")
    return lines


def loss_section(losses, by_angle, plot, tables, bits):
    lines = ["## 2. Where the cascade loses matches", "",
             "Correct brute-force matches (6 px) that the cascade does not return, per pair. *replaced*: the "
             "cascade matched the query to another feature (its true nearest neighbour was not among the "
             "candidates, so a worse one passed, or the missing second best changed the ratio test); "
             "*absent*: the query got no cascade match (ratio test or cross check failed with the candidates "
             "it had). *cascade-only correct*: correct cascade matches that brute force does not return. "
             "Angles are between the mean-centred descriptors, the quantity that decides whether two "
             "descriptors share a bucket.", "",
             "| sequence | pair | brute-force correct | kept | lost | replaced | absent | cascade-only correct "
             "| median angle kept | median angle lost |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, per_pair in losses.items():
        for key, r in per_pair.items():
            lines.append("| %s | %s | %d | %d | %d (%.1f %%) | %d | %d | %d | %s | %s |" % (
                name, key, r["brute_correct"], r["kept"], r["lost"],
                100.0 * r["lost"] / r["brute_correct"] if r["brute_correct"] else 0.0, r["lost_replaced"],
                r["lost_absent"], r["cascade_only_correct"], _fmt(r["median_angle_kept_deg"], 1),
                _fmt(r["median_angle_lost_deg"], 1)))
    lines += ["", "Why the cascade's precision is lower: the matches it returns that brute force does not "
              "(*cascade-only*), split by what exact matching says about them. *ratio*: the feature is the "
              "exact nearest neighbour but the exact second best is close enough to fail the ratio test (0.8), "
              "so the cascade, which never ranked that second best, accepted an ambiguous match; *not nearest*: "
              "the exact nearest neighbour was not a candidate and a worse feature passed the ratio test against "
              "the other candidates; *cross check*: nearest and unambiguous from image 1, but brute force's reverse match of the image-N feature is another feature that the cascade did not rank.", "",
              "| sequence | wrong matches brute force | wrong matches cascade | cascade-only | wrong: ratio "
              "| wrong: not nearest | wrong: cross check | correct cascade-only |",
              "|---|---|---|---|---|---|---|---|"]
    for name, per_pair in losses.items():
        total = {"bw": 0, "cw": 0, "co": 0, "ratio": 0, "not_nearest": 0, "other": 0, "ok": 0}
        for r in per_pair.values():
            total["bw"] += r["brute_wrong"]
            total["cw"] += r["cascade_wrong"]
            total["co"] += r["cascade_only"]
            for reason, c in (r["cascade_only_reasons"] or {}).items():
                total[reason] += c["wrong"]
                total["ok"] += c["correct"]
        lines.append("| %s | %d | %d | %d | %d | %d | %d | %d |" % (
            name, total["bw"], total["cw"], total["co"], total["ratio"], total["not_nearest"], total["other"],
            total["ok"]))
    lines += ["", "Kept fraction of the correct brute-force matches by descriptor angle (all sequences), "
              "against the probability that two descriptors at that angle share a bucket in at least one "
              "of the %d tables of %d random-hyperplane bits, 1 - (1 - (1 - theta/pi)^%d)^%d:" % (
                 tables, bits, bits, tables), "",
              "| angle (deg) | matches | kept | model |", "|---|---|---|---|"]
    for centre, count, kept in by_angle:
        model = loss_analysis.collision_probability(np.radians(centre), tables, bits)
        lines.append("| %.1f | %d | %.1f %% | %.1f %% |" % (centre, count, 100 * kept, 100 * model))
    lines += ["", "![kept by angle](accuracy/%s)" % plot, ""]
    return lines


def settings_lines(rows, results, setting):
    """The table behind the choice of the defaults: precision and correct
    matches against brute force per sequence, and the scene's matching time."""
    names = list(rows[0]["matches"])
    brute = {n: _totals(results[n], "bruteforce", 6) for n in names if n in results}
    base = next((r for r in rows if r["setting"] == [8, 7, 40, 10, 0]), None)
    lines = ["| tables x bits | tau | top_k | seed | " + " | ".join("%s: precision - brute force, correct / brute "
                                                                    "force" % n for n in names)
             + " | target met | matching s, 1 thread (least of 5) | vs 8 x 7 / 40 / 10 |",
             "|---|---|---|---|" + "---|" * len(names) + "---|---|---|"]
    for r in rows:
        tables, bits, tau, top_k, seed = r["setting"]
        cells, met = [], True
        for n in names:
            _, bc, bp = brute[n]
            m, c = r["matches"][n], r["correct"][n]
            dp, ratio = 100 * ((c / m if m else 0.0) - bp), c / bc if bc else 0.0
            met = met and abs(dp) <= 2 and ratio >= 0.9
            cells.append("%+.2f, %.1f %%" % (dp, 100 * ratio))
        time_cells = ["-", "-"]
        if "scene_matching_s" in r:
            time_cells = ["%.2f" % r["scene_matching_s"],
                          "%+.0f %%" % (100 * (r["scene_matching_s"] / base["scene_matching_s"] - 1)) if base else "-"]
        bold = "**" if [tables, bits, tau, top_k] == list(setting) and seed == 0 else ""
        lines.append("| %s%d x %d%s | %d | %d | %d | %s | %s | %s |" % (
            bold, tables, bits, bold, tau, top_k, seed, " | ".join(cells), "yes" if met else "**no**",
            " | ".join(time_cells)))
    return lines


def sweep_section(sweeps, plots, scene, setting, results):
    tables, bits, tau0, top_k = setting
    tau, bench = sweeps["tau"], sweeps["topk_bits"]
    names = list(tau[min(tau)]["precision"])
    lines = ["## 3. Parameter sweeps (the paper's tau figure, top_k, bits per table, tables)", ""]
    if sweeps.get("settings"):
        lines += ["### Choice of tau and top_k", "",
                  "At 8 x 7 / tau 40 / top_k 10 the cascade missed the precision target on graf and "
                  "hpatches_v_graffiti, because it accepts ambiguous matches whose close second best it never "
                  "ranked (section 2). Only numbers change here, not what the options mean: each row is the "
                  "cascade at one setting on every homography sequence (precision at 6 px minus brute force's, "
                  "correct matches as a share of brute force's) and its matching time on the 55 pairs of %s "
                  "(the `matching` seconds cashash prints: hashing and matching, one thread, no verification; "
                  "the least of five rounds over all settings on a shared 2-core machine, so still +-15 %%; "
                  "docs/cascade_parameters.md has the same comparison on an idle machine, +7 to +9 %% for "
                  "43 / 16). Seeds 1 and 2 draw other random projections." % scene, ""]
        lines += settings_lines(sweeps["settings"], results, setting) + [""]
    lines += ["### tau", "",
              "Raw matches and matching time (one thread, no verification; the `matching` seconds cashash prints, "
              "the least of three rounds over all taus on a shared 2-core machine, so +-15 %%) over the 55 pairs of %s, and precision at 6 px "
              "over pairs 1-2 ... 1-6 of each homography sequence (%d tables x %d bits, top_k %d); the last row "
              "is brute force." % (scene, tables, bits, top_k), "",
              "| tau | raw matches (%s) | matching s | process CPU s | " % scene
              + " | ".join("precision %s" % n for n in names) + " |",
              "|---|---|---|---|" + "---|" * len(names)]
    for t in sorted(tau):
        r = tau[t]
        mark = "**" if t == tau0 else ""
        lines.append("| %s%d%s | %d | %.2f | %.1f | " % (mark, t, mark, r["scene_matches"], r["scene_matching_s"],
                                                     r["scene_cpu_s"])
                     + " | ".join("%.1f %%" % (100 * v) for v in r["precision"].values()) + " |")
    lines.append("| brute force | | | | " + " | ".join("%.1f %%" % (100 * _totals(results[n], "bruteforce", 6)[2])
                                                     for n in names) + " |")
    top = max(tau)
    same = [t for t in sorted(tau) if tau[t]["scene_matches"] == tau[top]["scene_matches"]]
    mean_precision = {t: 100 * np.mean(list(tau[t]["precision"].values())) for t in tau}
    most = max(tau, key=lambda t: tau[t]["scene_matches"])
    lines += ["", "From tau = %d on, the raw matches equal those of tau = %d (%d); at tau = %d they are %d and the "
              "mean precision is %.1f %% against %.1f %% at tau = %d. Below about 36 the candidate lists get so "
              "short that the ratio test loses its second best: more raw matches (%d at tau = %d) but far lower "
              "precision (%.1f %%). Process CPU time (load, hash, match; noisy on the shared machine) %.1f s at "
              "tau = %d against %.1f s at tau = %d." % (
                  same[0], top, tau[top]["scene_matches"], tau0, tau[tau0]["scene_matches"] if tau0 in tau else -1,
                  mean_precision.get(tau0, float("nan")), mean_precision[top], top,
                  tau[most]["scene_matches"], most, mean_precision[most],
                  tau[tau0]["scene_cpu_s"] if tau0 in tau else float("nan"), tau0, tau[top]["scene_cpu_s"], top)]
    lines += ["", "![tau sweep](accuracy/%s)" % plots[0], "",
              "### top_k, bits per table, tables", "",
              "`matcher_recall_bench` on %s, one parameter at a time around %d x %d / tau %d / top_k %d (recall = "
              "share of the exact brute-force matches that the cascade returns; min pair recall over the pairs "
              "with >= 100 of them; CPU time per pair of the matching alone, one thread); brute force runs at %s "
              "pairs per CPU second. The GPU backend needs tables x bits <= 64 and top_k <= 32." % (
                  scene, tables, bits, tau0, top_k, _fmt(bench["brute_force_pairs_per_cpu_s"], 2)), "",
              "| tables x bits | tau | top_k | recall | min pair recall | precision vs brute force | "
              "candidates within tau | ranked | pairs per CPU s |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in bench["rows"]:
        mark = "**" if [r["tables"], r["bits"], r["tau"], r["top_k"]] == list(setting) else ""
        lines.append("| %s%d x %d%s | %d | %d | %.4f | %.4f | %.4f | %.1f | %.2f | %.1f |" % (
            mark, r["tables"], r["bits"], mark, r["tau"], r["top_k"], r["recall"], r["min_pair_recall"],
            r["precision"], r["within_tau"], r["ranked"], r["pairs_per_cpu_s"]))
    lines += ["", "![top_k, bits and tables](accuracy/%s)" % plots[1], ""]
    return lines


def camera_section(cams):
    lines = ["## 4. Camera ground truth (Strecha fountain-P11, herzjesu-P25)", "",
             "Each matcher matches all pairs of a copy of the COLMAP 3.8 feature database (CPU SIFT, default "
             "settings, one camera) and verifies them; `colmap mapper` (defaults) reconstructs; the largest model "
             "is aligned to the ground-truth centres by a similarity transform (Umeyama, least squares over the "
             "registered cameras). Position error in scene units and relative to the scene size (largest "
             "distance between two ground-truth centres); rotation error = angle of R_gt^T R_aligned; relative "
             "rotation error = for every pair of cameras, the angle between the ground-truth and the model's "
             "relative rotation (independent of the alignment).", "",
             "| scene | matcher | registered | median position error | max position error | median rel. | "
             "max rel. | median rotation (deg) | max rotation (deg) | median / max relative rotation (deg) "
             "| matching wall s |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for scene, by in cams.items():
        for matcher in ("cascade", "bruteforce", "colmap"):
            s = by.get(matcher)
            if s is None:
                lines.append("| %s | %s | not run (time) | | | | | | | | |" % (scene, LABELS[matcher]))
                continue
            lines.append("| %s | %s | %d / %d | %s | %s | %s | %s | %s | %s | %s / %s | %.0f |" % (
                scene, LABELS[matcher], s["registered"], s["gt_images"], _fmt(s.get("position_median"), 4),
                _fmt(s.get("position_max"), 4), _fmt(s.get("position_median_rel"), 5),
                _fmt(s.get("position_max_rel"), 5), _fmt(s.get("rotation_median_deg"), 3),
                _fmt(s.get("rotation_max_deg"), 3), _fmt(s.get("relative_rotation_median_deg"), 3),
                _fmt(s.get("relative_rotation_max_deg"), 3), s["match_wall_s"]))
    lines += ["", "The rotation errors (a third to a half of a degree) are the same for all matchers: COLMAP keeps "
              "the principal point at the image centre (1536, 1024 for these 3072 x 2048 images), while the "
              "ground-truth K puts it about 15 px left of and 17 px above that (1520.7, 1006.8), 23 px off; "
              "at a focal length of about 2760 px that alone tilts a camera by up to atan(23 / 2760) = 0.48 "
              "degrees. Compare the matchers with each other, not with zero. Matching wall times include verification and ran on a "
              "shared 2-core machine.", ""]
    return lines


def _setting_row_text(row, results):
    """'graf -2.60 / 99.3 %, ...' for one row of the settings sweep."""
    parts = []
    for n in row["matches"]:
        _, bc, bp = _totals(results[n], "bruteforce", 6)
        m, c = row["matches"][n], row["correct"][n]
        parts.append("%s %+.2f points / %.1f %%" % (n, 100 * ((c / m if m else 0.0) - bp), 100.0 * c / max(bc, 1)))
    return ", ".join(parts)


def defaults_lines(sweeps, results, setting, scene):
    """The summary's account of the defaults change, from the settings sweep."""
    rows = (sweeps or {}).get("settings") or []
    find = {tuple(r["setting"]): r for r in rows}
    old, new = find.get((8, 7, 40, 10, 0)), find.get(tuple(setting) + (0,))
    if not old or not new or old is new:
        return []
    line = ("- Defaults: tau %d and top_k %d (were 40 and 10; 8 tables x 7 bits unchanged). Precision - brute force "
            "and correct / brute force before: %s; after: %s. Matching time on %s, one thread: %.2f s against "
            "%.2f s (%+.0f %%)." % (setting[2], setting[3], _setting_row_text(old, results),
                                    _setting_row_text(new, results), scene, new["scene_matching_s"],
                                    old["scene_matching_s"],
                                    100 * (new["scene_matching_s"] / old["scene_matching_s"] - 1)))
    top_k_only = [r for r in rows if r["setting"][2] == 40 and r["setting"][3] > 10 and r["setting"][4] == 0]
    if top_k_only:
        worst = []
        for r in top_k_only:
            deltas = []
            for n in r["matches"]:
                _, _, bp = _totals(results[n], "bruteforce", 6)
                deltas.append(100 * (r["correct"][n] / max(r["matches"][n], 1) - bp))
            worst.append("top_k %d: %+.2f" % (r["setting"][3], min(deltas)))
        line += (" A larger top_k alone is cheap but not enough (worst sequence, points: %s): the missing second "
                 "bests lie beyond tau 40 in Hamming distance or in no shared bucket at all." % ", ".join(worst))
    return [line]


def summary_section(results, losses, by_angle, cams, tables, bits, sweeps=None, setting=None, gpu_info=None,
                    scene=None):
    """Targets and the main findings, with the numbers they rest on."""
    lines = ["## Summary against the targets", ""]
    misses, ratios, diffs = [], [], []
    for name, by in results.items():
        _, cc, cp = _totals(by, "cascade", 6)
        _, bc, bp = _totals(by, "bruteforce", 6)
        diffs.append(100 * (cp - bp))
        ratios.append(cc / bc if bc else 0.0)
        if abs(100 * (cp - bp)) > 2:
            misses.append("%s (%+.1f points)" % (name, 100 * (cp - bp)))
    variant = []
    for name, by in results.items():
        if "cascade_r078" in by:
            _, vc, vp = _totals(by, "cascade_r078", 6)
            _, bc, bp = _totals(by, "bruteforce", 6)
            variant.append((100 * (vp - bp), vc / bc if bc else 0.0))
    lines.append("- Correct matches at 6 px, cascade / brute force: %.1f %% to %.1f %% over the %d sequences "
                 "(target >= 90 %%: %s)." % (100 * min(ratios), 100 * max(ratios), len(ratios),
                                            "met" if min(ratios) >= 0.9 else "**not met**"))
    lines.append("- Precision at 6 px, cascade - brute force: %+.1f to %+.1f points (target within 2 points: %s)."
                 % (min(diffs), max(diffs), "met" if not misses else "**not met** on " + ", ".join(misses)))
    if variant:
        lines.append("- With `--SiftMatching.max_ratio 0.78` for the cascade only (brute force at 0.8): precision "
                     "%+.1f to %+.1f points, correct matches %.1f %% to %.1f %% of brute force's (both targets %s)."
                     % (min(v[0] for v in variant), max(v[0] for v in variant), 100 * min(v[1] for v in variant),
                        100 * max(v[1] for v in variant),
                        "met" if all(abs(v[0]) <= 2 and v[1] >= 0.9 for v in variant) else "**not met**"))
    total_lost = sum(r["lost"] for p in losses.values() for r in p.values())
    total_bc = sum(r["brute_correct"] for p in losses.values() for r in p.values())
    absent = sum(r["lost_absent"] for p in losses.values() for r in p.values())
    worst = sorted(((r["lost"] / r["brute_correct"], n, k, r) for n, p in losses.items() for k, r in p.items()
                    if r["brute_correct"] >= 50), key=lambda t: t[0], reverse=True)[:4]
    lines.append("- Where matches are lost: %d of %d correct brute-force matches (%.1f %%), %d of them because the "
                 "query got no cascade match at all. Worst pairs (>= 50 correct): %s. The lost matches are the "
                 "dissimilar ones: the kept fraction falls from %.0f %% below 20 degrees between the mean-centred "
                 "descriptors to %.0f %% at 30-35 degrees, as the first-level bucket collision probability of %d "
                 "tables x %d random-hyperplane bits predicts (table in section 2); pairs with a large viewpoint or "
                 "scale change have more such matches, hence the higher loss rates of the pairs above." % (
                     total_lost, total_bc, 100.0 * total_lost / max(total_bc, 1), absent,
                     ", ".join("%s %s %.1f %% (%d of %d)" % (n, k, 100 * f, r["lost"], r["brute_correct"])
                               for f, n, k, r in worst),
                     100 * _kept_range(by_angle, 0, 20), 100 * _kept_range(by_angle, 30, 35), tables, bits))
    reasons = {"ratio": 0, "not_nearest": 0, "other": 0}
    for per_pair in losses.values():
        for r in per_pair.values():
            for reason, c in (r["cascade_only_reasons"] or {}).items():
                reasons[reason] += c["wrong"]
    lines.append("- Why precision is lower: over all sequences the cascade returns %d wrong matches (> 6 px) where "
                 "brute force returns %d. Of the wrong matches only the cascade returns, %d are exact nearest "
                 "neighbours that fail the exact ratio test (the cascade never ranked the close second best), "
                 "%d are not the nearest neighbour (it was not a candidate) and %d pass brute force's first "
                 "direction but not its cross check." % (
                     sum(r["cascade_wrong"] for p in losses.values() for r in p.values()),
                     sum(r["brute_wrong"] for p in losses.values() for r in p.values()),
                     reasons["ratio"], reasons["not_nearest"], reasons["other"]))
    if variant:
        wrong = 0
        for by in results.values():
            m, c, _ = _totals(by, "cascade_r078", 6)
            wrong += m - c
        lines[-1] += " With max_ratio 0.78 the cascade returns %d wrong matches." % wrong
    if setting:
        lines += defaults_lines(sweeps, results, setting, scene)
    if gpu_info:
        cpu = sum(r["cpu"] for p in gpu_info["agreement"].values() for r in p.values())
        same = sum(r["identical"] for p in gpu_info["agreement"].values() for r in p.values())
        gpu = sum(r["gpu"] for p in gpu_info["agreement"].values() for r in p.values())
        on_gpu = all(m.startswith("gpu-cascade") for m in gpu_info["ran_on"].values())
        lines.append("- GPU cascade%s: %d raw matches against the CPU cascade's %d, %d rows identical (%.2f %%)." % (
            "" if on_gpu else " (**CPU fallback stand-in, not a GPU measurement**)", gpu, cpu, same,
            100.0 * same / max(cpu, 1)))
    if cams:
        for scene, by in cams.items():
            c, o = by.get("cascade"), by.get("colmap")
            if c and o and "position_median" in c and "position_median" in o:
                keys = ["position_median", "position_max", "rotation_median_deg", "relative_rotation_median_deg"]
                ok = c["registered"] >= o["registered"] and all(c[k] <= 1.1 * o[k] for k in keys)
                lines.append("- %s: %d / %d cameras registered after the cascade (%d after COLMAP's matcher); "
                             "position error median %.4f / max %.4f (cascade) vs %.4f / %.4f (COLMAP's "
                             "matcher), %.5f vs %.5f of the scene size; rotation error median %.3f vs %.3f "
                             "degrees, relative rotation median %.3f vs %.3f degrees (target: cascade no worse "
                             "than COLMAP's matcher + 10 %%: %s). Matching took %.0f s vs %.0f s (wall, with "
                             "verification)." % (
                                 scene, c["registered"], c["gt_images"], o["registered"], c["position_median"],
                                 c["position_max"], o["position_median"], o["position_max"],
                                 c["position_median_rel"], o["position_median_rel"], c["rotation_median_deg"],
                                 o["rotation_median_deg"], c["relative_rotation_median_deg"],
                                 o["relative_rotation_median_deg"], "met" if ok else "**not met**",
                                 c["match_wall_s"], o["match_wall_s"]))
                if c.get("inliers_kept_vs_bruteforce") is not None:
                    lines[-1] += (" The cascade verifies %.1f %% of the inlier matches that brute force verifies "
                                  "(target >= 95 %%)." % (100 * c["inliers_kept_vs_bruteforce"]))
            elif c and "position_median" in c:
                b = by.get("bruteforce") or {}
                lines.append("- %s: median camera position error %.4f (%.5f of the scene) after the cascade, "
                             "%s after brute force; COLMAP's matcher was not run on this scene (time)." % (
                                 scene, c["position_median"], c["position_median_rel"],
                                 _fmt(b.get("position_median"), 4)))
    lines.append("")
    return lines


def _kept_range(by_angle, lo, hi):
    rows = [r for r in by_angle if lo <= r[0] < hi]
    count = sum(r[1] for r in rows)
    return sum(r[1] * r[2] for r in rows) / count if count else float("nan")


def write(args, results, losses, by_angle, sweeps, cams, use_gpu, eps_list, gpu_info=None):
    os.makedirs(args.out, exist_ok=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                            stdout=subprocess.PIPE, text=True).stdout.strip()
    lines = ["# Accuracy against ground truth", "",
             "Generated by `scripts/evaluate_accuracy.py` on %s (commit %s, %s, %d CPU cores%s). "
             "Rerun: `python3 scripts/evaluate_accuracy.py --build-dir <build>` (builds needed: the `cashash` "
             "and `matcher_recall_bench` targets; about 40 minutes on 2 cores, most of it COLMAP's CPU matcher "
             "and mapper; `--skip-colmap-matcher`, `--skip-sweeps`, `--skip-cameras` shorten it, `--reuse` "
             "picks up finished steps from `--work-dir`). Arithmetic self-test: "
             "`python3 scripts/eval/selftest.py`." % (
                 datetime.date.today().isoformat(), commit, platform.machine(), os.cpu_count(),
                 ", GPU present" if use_gpu else ", no GPU"), ""]
    tables, bits = int(args.cascade.split(",")[0]), int(args.cascade.split(",")[1])
    lines += summary_section(results, losses, by_angle, cams, tables, bits, sweeps,
                             [int(v) for v in args.cascade.split(",")], gpu_info, args.sweep_scene)
    cascade_text = "%s tables x %s bits, tau %s, top_k %s" % tuple(args.cascade.split(","))
    lines += homography_section(results, use_gpu, eps_list, plot_homography(results, args.out),
                                "(--CasHash.*) " + cascade_text, gpu_info, args.cascade)
    lines += loss_section(losses, by_angle, plot_loss_by_angle(by_angle, args.out, tables, bits), tables, bits)
    if sweeps:
        setting = [int(v) for v in args.cascade.split(",")]
        lines += sweep_section(sweeps, [plot_tau(sweeps["tau"], args.out),
                                        plot_topk_bits(sweeps["topk_bits"], args.out, setting)], args.sweep_scene,
                               setting, results)
    if cams:
        lines += camera_section(cams)
    with open(args.report, "w") as f:
        f.write("\n".join(lines) + "\n")
