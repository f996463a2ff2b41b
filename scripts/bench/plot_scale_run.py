#!/usr/bin/env python3
"""Plot and tabulate a scripts/bench/scale_run.sh run.

    plot_scale_run.py RUN_DIR [--png RUN_DIR/scale_run.png] [--table RUN_DIR/scale_run.md]
        [--paper-rome16k-s 1.565e5]

Reads RUN_DIR/samples.csv and RUN_DIR/summary.txt (and the phase logs for
the run's closing lines); writes the PNG (pairs/s over time, pairs
committed, resident and GPU memory) and the Markdown section, which it
also prints: what was
measured per phase, the share of busy time per stage, and the
extrapolation to 20,000 images and to Rome16K (15,178 images) at the
measured rates.
"""
import argparse
import contextlib
import csv
import io
import os
import re
import sys

ROME16K_IMAGES = 15178


def pairs_of(n):
    return n * (n - 1) // 2


def read_samples(path):
    rows = []
    with open(path) as f:
        for r in csv.DictReader(f):
            rows.append({
                "t": float(r["t_s"]),
                "phase": r["phase"],
                "done": int(r["pairs_done"] or 0),
                "total": int(r["pairs_total"]) if r["pairs_total"] else None,
                "rss": float(r["rss_mib"]) if r["rss_mib"] else None,
                "gpu": float(r["gpu_used_mib"]) if r["gpu_used_mib"] else None,
            })
    return rows


def phase_summary(log_path):
    """The closing lines of one exhaustive_matcher run."""
    out = {}
    if not os.path.exists(log_path):
        return out
    text = open(log_path).read()
    m = re.search(r"^Summary: (\d+) pairs in ([0-9.]+) s .* with (\S+); (\d+) raw matches, (\d+) verified pairs",
                  text, re.M)
    if m:
        out.update(pairs=int(m.group(1)), seconds=float(m.group(2)), matcher=m.group(3),
                   raw=int(m.group(4)), verified=int(m.group(5)))
    m = re.search(r"^Time: loading ([0-9.]+) s, hashing ([0-9.]+) s, matching ([0-9.]+) s, "
                  r"verification ([0-9.]+) s[^,]*, writing ([0-9.]+) s", text, re.M)
    if m:
        out["stages"] = dict(zip(["loading", "hashing", "matching", "verification", "writing"],
                                 map(float, m.groups())))
    m = re.search(r"^Memory: (.*)$", text, re.M)
    if m:
        out["memory"] = m.group(1)
    m = re.search(r"^Schedule: (.*)$", text, re.M)
    if m:
        out["schedule"] = m.group(1)
    m = re.search(r"^Skipping (\d+) of (\d+) pairs", text, re.M)
    if m:
        out["skipped"] = int(m.group(1))
    m = re.search(r"^Stopped after (\d+) of (\d+) pairs", text, re.M)
    if m:
        out["stopped_of"] = int(m.group(2))
    return out


def steady_rate(samples):
    """Pairs per second between the first and the last commit seen."""
    moving = [s for s in samples if s["done"] > 0]
    if len(moving) < 2:
        return None, None, None
    first = moving[0]
    last = max(moving, key=lambda s: s["done"])
    # The time of the last change, not of the last sample.
    last_t = min(s["t"] for s in moving if s["done"] == last["done"])
    if last_t <= first["t"]:
        return None, None, None
    return (last["done"] - first["done"]) / (last_t - first["t"]), first["t"], last_t


def fmt_duration(seconds):
    if seconds is None:
        return "-"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 2 * 3600:
        return f"{seconds / 60:.1f} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir")
    ap.add_argument("--png", help="output plot (default RUN_DIR/scale_run.png)")
    ap.add_argument("--table", help="output Markdown (default RUN_DIR/scale_run.md)")
    ap.add_argument("--paper-rome16k-s", type=float, default=1.565e5,
                    help="CasHashGPU's Rome16K matching time in the GPU cascade hashing paper")
    ap.add_argument("--window", type=float, default=10.0, help="seconds per pairs/s point")
    args = ap.parse_args()

    samples = read_samples(os.path.join(args.run_dir, "samples.csv"))
    summary_text = open(os.path.join(args.run_dir, "summary.txt")).read()
    m = re.search(r"^images: (\d+) x (\d+) features", summary_text, re.M)
    num_images, num_features = (int(m.group(1)), int(m.group(2))) if m else (None, None)
    phases = [p for p in ("A", "B") if any(s["phase"] == p for s in samples)]
    labels = {"A": "matching + verification", "B": "matching only"}

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_rate, ax_done, ax_mem) = plt.subplots(3, 1, figsize=(9, 10), sharex=True)
    for p in phases:
        ss = [s for s in samples if s["phase"] == p]
        t = [s["t"] for s in ss]
        # pairs/s over windows of committed pairs
        wt, wr = [], []
        start = 0
        for i in range(1, len(ss)):
            if ss[i]["t"] - ss[start]["t"] >= args.window or i == len(ss) - 1:
                dt = ss[i]["t"] - ss[start]["t"]
                if dt > 0:
                    wt.append((ss[i]["t"] + ss[start]["t"]) / 2)
                    wr.append((ss[i]["done"] - ss[start]["done"]) / dt)
                start = i
        ax_rate.plot(wt, wr, marker=".", label=f"phase {p}: {labels[p]}")
        ax_done.plot(t, [s["done"] for s in ss], label=f"phase {p}")
        ax_mem.plot(t, [s["rss"] / 1024 if s["rss"] is not None else float("nan") for s in ss],
                    label=f"phase {p}: resident (host)")
        if any(s["gpu"] is not None for s in ss):
            ax_mem.plot(t, [s["gpu"] / 1024 if s["gpu"] is not None else float("nan") for s in ss],
                        linestyle="--", label=f"phase {p}: GPU in use")
    ax_rate.set_ylabel(f"pairs/s ({args.window:.0f} s windows)")
    ax_rate.set_yscale("symlog", linthresh=10)
    ax_done.set_ylabel("pairs committed in the phase")
    ax_mem.set_ylabel("GiB")
    ax_mem.set_xlabel("seconds since the start (generation first)")
    title = "cashash exhaustive_matcher"
    if num_images:
        title += f", {num_images:,} generated images x {num_features:,} features ({pairs_of(num_images):,} pairs)"
    fig.suptitle(title)
    for ax in (ax_rate, ax_done, ax_mem):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    png = args.png or os.path.join(args.run_dir, "scale_run.png")
    fig.tight_layout()
    fig.savefig(png, dpi=110)

    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        tabulate(args, samples, phases, labels, num_images)
    table = args.table or os.path.join(args.run_dir, "scale_run.md")
    with open(table, "w") as f:
        f.write(text.getvalue())
    print(text.getvalue())
    print(f"Written: {png}, {table}")
    return 0


def tabulate(args, samples, phases, labels, num_images):
    """Prints the Markdown section: per phase, the sampled peaks, the extrapolation."""
    print("| phase | wall s | pairs committed | pairs/s (steady) | pairs/s (summary) | "
          "loading | hashing | matching | verification | writing | memory |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    rates = {}
    for p in phases:
        ss = [s for s in samples if s["phase"] == p]
        info = phase_summary(os.path.join(args.run_dir, f"phase_{p}.log"))
        rate, _, _ = steady_rate(ss)
        rates[p] = rate
        wall = ss[-1]["t"] - ss[0]["t"] if ss else 0
        stages = info.get("stages", {})
        total = info.get("seconds") or wall
        shares = [f"{stages[k]:.1f} s ({100 * stages[k] / total:.0f} %)" if k in stages and total else "-"
                  for k in ("loading", "hashing", "matching", "verification", "writing")]
        summary_rate = info["pairs"] / info["seconds"] if info.get("seconds") else None
        print(f"| {p}: {labels[p]} | {wall:.0f} | {info.get('pairs', max((s['done'] for s in ss), default=0)):,} | "
              f"{rate:,.0f} | " if rate else f"| {p}: {labels[p]} | {wall:.0f} | - | - | ", end="")
        print(f"{summary_rate:,.0f} | " if summary_rate else "- | ", end="")
        print(" | ".join(shares) + f" | {info.get('memory', '-')} |")
    peak_rss = max((s["rss"] for s in samples if s["rss"] is not None), default=None)
    peak_gpu = max((s["gpu"] for s in samples if s["gpu"] is not None), default=None)
    print()
    print(f"Sampled peaks (every second): resident {peak_rss / 1024:.2f} GiB" if peak_rss else "Sampled peaks: -", end="")
    print(f", GPU in use {peak_gpu / 1024:.2f} GiB" if peak_gpu else "", end="")
    print(". Stage times are busy times: loading, hashing and matching share one thread, "
          "verification and writing run beside it, so they overlap.")

    print("\nExtrapolation at the measured steady rates (pairs / rate; every pair alike):\n")
    print("| collection | pairs | matching + verification (A) | matching only (B) |")
    print("|---|---:|---:|---:|")
    for name, n in ((f"this run ({num_images:,} images)" if num_images else "this run", num_images),
                    ("20,000 images", 20000), (f"Rome16K ({ROME16K_IMAGES:,} images)", ROME16K_IMAGES)):
        if not n:
            continue
        cells = [fmt_duration(pairs_of(n) / rates[p]) if rates.get(p) else "-" for p in ("A", "B")]
        print(f"| {name} | {pairs_of(n):,} | {cells[0]} | {cells[1]} |")
    print(f"\nPaper (CasHashGPU, Rome16K): {args.paper_rome16k_s:.4g} s = {fmt_duration(args.paper_rome16k_s)}, "
          f"{pairs_of(ROME16K_IMAGES) / args.paper_rome16k_s:,.0f} pairs/s.")


if __name__ == "__main__":
    sys.exit(main())
