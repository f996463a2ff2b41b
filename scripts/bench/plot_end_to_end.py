#!/usr/bin/env python3
"""Plot of a scripts/bench/end_to_end_bench.sh table: each run's pairs per
second of the whole command (pairs / wall s; COLMAP's over the pairs it
committed up to its last write), cashash's runs beside COLMAP's matcher.

    plot_end_to_end.py OUT/table.md --png OUT/end_to_end.png

end_to_end_bench.sh calls it on its own table, so the table and the plot
come from one run.
"""
import argparse
import math
import re


def number(text):
    try:
        return float(text.replace(",", ""))
    except ValueError:
        return None


def read_table(path):
    """(title lines, [{run, wall, pairs, rate}]) from the Markdown table."""
    titles, rows = [], []
    with open(path) as f:
        for line in f:
            line = line.rstrip("\n")
            if line.startswith("# "):
                titles.append(line[2:])
            elif line and not line.startswith("|"):
                titles.append(line)
            elif line.startswith("| ") and not line.startswith("| run ") and not line.startswith("|---"):
                cells = [c.strip() for c in line.strip("|").split("|")]
                wall, pairs, rate = number(cells[1]), number(cells[2]), number(cells[3])
                colmap = cells[0].startswith("COLMAP")
                # cashash: the whole command, pairs over the process's wall time;
                # COLMAP: its own rate, up to its last commit when stopped.
                whole = rate if colmap else (pairs / wall if pairs and wall else None)
                rows.append({"run": cells[0], "wall": wall, "pairs": pairs, "rate": whole, "colmap": colmap})
    return titles, rows


def short_label(run):
    """'default (cascade, ...)' -> 'cashash default'; COLMAP rows shortened at their first comma."""
    if run.startswith("COLMAP"):
        return re.sub(r" match_exhaustive", "", run)
    return "cashash " + run.split(" (")[0]


def plot(titles, rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = [r for r in rows if r["rate"]]
    colmap = next((r["rate"] for r in rows if r["colmap"]), None)
    fig, ax = plt.subplots(figsize=(9, 0.55 * len(rows) + 1.6))
    y = list(range(len(rows)))[::-1]
    ax.barh(y, [r["rate"] for r in rows], color=["tab:green" if r["colmap"] else "tab:blue" for r in rows])
    for yy, r in zip(y, rows):
        text = "{:,.0f} pairs/s".format(r["rate"])
        if colmap and not r["colmap"]:
            text += ", %.0fx COLMAP" % (r["rate"] / colmap)
        ax.text(r["rate"] * 1.05, yy, text, va="center", fontsize=8)
    ax.set_yticks(y)
    ax.set_yticklabels([short_label(r["run"]) for r in rows], fontsize=8)
    ax.set_xscale("log")
    # Bars start a decade below the slowest run, so that the slowest is seen.
    ax.set_xlim(10 ** (math.floor(math.log10(min(r["rate"] for r in rows))) - 1), max(r["rate"] for r in rows) * 20)
    ax.set_xlabel("pairs/s of the whole process: pairs / wall s (log scale)")
    ax.set_title("\n".join(titles[:2]), fontsize=8)
    ax.grid(axis="x", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("table")
    parser.add_argument("--png", required=True)
    args = parser.parse_args()
    titles, rows = read_table(args.table)
    if not any(r["rate"] for r in rows):
        raise SystemExit("%s: no row with a rate to plot" % args.table)
    plot(titles, rows, args.png)
    print("Written: %s" % args.png)


if __name__ == "__main__":
    main()
