#!/usr/bin/env python3
"""Table and plot of a scripts/bench/scale_curve.sh run.

    plot_scale_curve.py scale_curve.csv [--png scale_curve.png] [--table scale_curve.md]

Prints (and with --table writes) a Markdown table (one row per street: the whole command's time and
pairs/s beside COLMAP's rate over its fixed time) and a projection to
20,000 and 50,000 images at the largest street's whole-command rate;
draws pairs/s and wall time against images for both matchers (COLMAP's
time for all pairs is its measured rate applied to them, dashed).
"""
import argparse
import csv


def pairs_of(n):
    return n * (n - 1) // 2


def number(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def duration(seconds):
    if seconds < 120:
        return "%.0f s" % seconds
    if seconds < 2 * 3600:
        return "%.1f min" % (seconds / 60)
    if seconds < 3 * 86400:
        return "%.1f h" % (seconds / 3600)
    return "%.1f days" % (seconds / 86400)


def read_rows(path):
    header = None
    rows = []
    with open(path) as f:
        lines = [line for line in f if not line.startswith("#")]
    for r in csv.DictReader(lines):
        header = header or list(r.keys())
        rows.append(r)
    return rows


def table(rows):
    out = [
        "| street | mean features | pairs | wall s | pairs/s (whole command) | matching / verification / writing s "
        "| verified pairs | peak GPU MiB | peak host MiB | COLMAP pairs/s | vs COLMAP | COLMAP for all pairs (projected) |",
        "|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        n = int(r["images"])
        wall = number(r["wall_s"])
        pairs = number(r["pairs"]) or 0
        rate = pairs / wall if wall else None
        colmap = number(r["colmap_pairs_per_s"])
        ratio = "%.0fx" % (rate / colmap) if rate and colmap else ""
        projected = duration(pairs_of(n) / colmap) if colmap else ""
        out.append("| %s %s | %s | %s | %s | %s | %s / %s / %s | %s | %s | %s | %s | %s | %s |" % (
            r["kind"], "{:,}".format(n), "{:,}".format(int(number(r["mean_features"]) or 0)),
            "{:,}".format(int(pairs)), "%.1f" % wall if wall else "", "{:,.0f}".format(rate) if rate else "",
            r["matching_s"], r["verification_s"], r["writing_s"], r["verified_pairs"], r["peak_gpu_mib"],
            r["peak_rss_mib"], "{:,.0f}".format(colmap) if colmap else "", ratio, projected))
    return "\n".join(out)


def projection(rows):
    out = []
    for kind in sorted({r["kind"] for r in rows}):
        mine = [r for r in rows if r["kind"] == kind and number(r["wall_s"])]
        if not mine:
            continue
        last = max(mine, key=lambda r: int(r["images"]))
        rate = number(last["pairs"]) / number(last["wall_s"])
        for n in (20000, 50000):
            out.append("- %s, %s images: %s pairs at %s pairs/s (the %s-image rate): %s" % (
                kind, "{:,}".format(n), "{:,}".format(pairs_of(n)), "{:,.0f}".format(rate),
                "{:,}".format(int(last["images"])), duration(pairs_of(n) / rate)))
    return "\n".join(out)


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    colours = {"equal": "tab:blue", "extraction": "tab:orange"}
    for kind in sorted({r["kind"] for r in rows}):
        mine = sorted((r for r in rows if r["kind"] == kind and number(r["wall_s"])), key=lambda r: int(r["images"]))
        if not mine:
            continue
        n = [int(r["images"]) for r in mine]
        rate = [number(r["pairs"]) / number(r["wall_s"]) for r in mine]
        wall = [number(r["wall_s"]) for r in mine]
        colour = colours.get(kind)
        left.plot(n, rate, "o-", color=colour, label="cashash, %s" % kind)
        right.plot(n, wall, "o-", color=colour, label="cashash, %s" % kind)
        colmap = [(int(r["images"]), number(r["colmap_pairs_per_s"])) for r in mine if number(r["colmap_pairs_per_s"])]
        if colmap:
            left.plot([c[0] for c in colmap], [c[1] for c in colmap], "s--", color=colour, alpha=0.7,
                      label="COLMAP, %s" % kind)
            right.plot([c[0] for c in colmap], [pairs_of(c[0]) / c[1] for c in colmap], "s--", color=colour,
                       alpha=0.7, label="COLMAP, %s (projected)" % kind)
    left.set_xscale("log")
    left.set_yscale("log")
    left.set_xlabel("images")
    left.set_ylabel("pairs/s, whole command")
    left.set_title("Exhaustive matching rate")
    right.set_xscale("log")
    right.set_yscale("log")
    right.set_xlabel("images")
    right.set_ylabel("seconds for every pair")
    right.set_title("Time to match and verify every pair")
    sizes = sorted({int(r["images"]) for r in rows})
    for axis in (left, right):
        axis.set_xticks(sizes)
        axis.set_xticklabels(["{:,}".format(n) for n in sizes])
        axis.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        axis.yaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: "{:,.0f}".format(v) if v >= 1
                                                                        else "{:g}".format(v)))
        axis.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("csv")
    parser.add_argument("--png", default=None)
    parser.add_argument("--table", default=None, help="also write the table and the projection here")
    args = parser.parse_args()
    # Calls that append (APPEND=1) may add sizes in any order.
    rows = sorted(read_rows(args.csv), key=lambda r: (r["kind"], int(r["images"])))
    with open(args.csv) as f:
        notes = [line[2:].strip() for line in f if line.startswith("# ")]
    text = "\n".join(notes) + "\n\n" + table(rows) + "\n\n" + projection(rows) + "\n"
    print(text)
    if args.table:
        with open(args.table, "w") as f:
            f.write(text)
    if args.png:
        plot(rows, args.png)
        print("\nWritten: %s" % args.png)


if __name__ == "__main__":
    main()
