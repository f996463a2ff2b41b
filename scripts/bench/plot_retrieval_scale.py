#!/usr/bin/env python3
"""Plot of a scripts/bench/retrieval_scale.sh table: the whole
`retrieval_matcher` command's wall time and retrieval's part of it against
the images, and retrieval's share beside the fifth it should stay under.

    plot_retrieval_scale.py retrieval_scale.md --png retrieval_scale.png

retrieval_scale.sh calls it on its own table, so the table and the plot
come from one run.
"""
import argparse


def read_rows(path):
    """The rows by column name, so that a column added to the table does not
    shift the ones read."""
    rows, header = [], None
    with open(path) as f:
        for line in f:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if header is None and "images" in cells:
                header = cells
                continue
            if header is None or not cells[0].replace(",", "").isdigit():
                continue
            row = dict(zip(header, cells))
            rows.append({"images": int(cells[0].replace(",", "")), "retrieval_s": float(row["command: retrieval s"]),
                         "command_s": float(row["command: wall s"])})
    return sorted(rows, key=lambda r: r["images"])


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    images = [r["images"] for r in rows]
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    left.plot(images, [r["command_s"] for r in rows], "o-", label="whole command")
    left.plot(images, [r["retrieval_s"] for r in rows], "s--", label="retrieval")
    left.set_ylabel("wall s")
    left.set_title("retrieval_matcher, wall time")
    right.plot(images, [100 * r["retrieval_s"] / r["command_s"] for r in rows], "o-", color="tab:green")
    right.axhline(20, color="k", lw=0.8, ls="--", label="a fifth")
    right.set_ylim(0, 100)
    right.set_ylabel("retrieval's share of the command (%)")
    right.set_title("Retrieval's share")
    for axis in (left, right):
        axis.set_xscale("log")
        axis.set_xticks(images)
        axis.set_xticklabels(["{:,}".format(n) for n in images])
        axis.minorticks_off()
        axis.set_xlabel("images")
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("table")
    parser.add_argument("--png", required=True)
    args = parser.parse_args()
    rows = read_rows(args.table)
    if not rows:
        raise SystemExit("%s: no rows" % args.table)
    plot(rows, args.png)
    print("Written: %s" % args.png)


if __name__ == "__main__":
    main()
