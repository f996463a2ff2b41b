#!/usr/bin/env python3
"""Table and plot of a scripts/bench/host_memory_scale.sh run: peak resident
memory against the number of images, one line per build and process count.

    plot_host_memory.py host_memory.csv --png host_memory.png [--table host_memory.md]

host_memory_scale.sh calls it on its own CSV, so the table and the plot come
from one run. Prints the table.
"""
import argparse
import csv


def read_rows(path):
    with open(path) as f:
        lines = f.readlines()
    notes = [line[2:].strip() for line in lines if line.startswith("# ")]
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    for r in rows:
        r["images"] = int(r["images"])
        r["processes"] = int(r["processes"])
        r["peak_mib"] = float(r["peak_mib"] or 0)
    return notes, rows


def series(rows):
    """{(build, processes): rows by images}."""
    out = {}
    for r in rows:
        out.setdefault((r["build"], r["processes"]), []).append(r)
    return {k: sorted(v, key=lambda r: r["images"]) for k, v in out.items()}


def table(notes, rows):
    lines = notes + ["", "| build | images | processes | peak MiB (largest process) | vs the fewest images "
                     "| first chunk committed after, s | pairs committed |", "|---|---:|---:|---:|---:|---:|---:|"]
    for (build, processes), mine in series(rows).items():
        base = mine[0]["peak_mib"]
        for r in mine:
            lines.append("| %s | %s | %d | %.0f | %s | %s | %s |" % (
                build, "{:,}".format(r["images"]), processes, r["peak_mib"],
                "%.1fx" % (r["peak_mib"] / base) if base else "", r["first_chunk_s"] or "none",
                "{:,}".format(int(r["pairs_committed"])) if r["pairs_committed"] else "0"))
    builds = sorted({(r["build"], r["binary"]) for r in rows})
    lines += ["", "Builds: " + ", ".join("%s = `%s`" % b for b in builds)]
    return "\n".join(lines) + "\n"


def plot(notes, rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4))
    for (build, processes), mine in series(rows).items():
        label = "%s, %s" % (build, "1 process" if processes == 1 else "%d MPI ranks (largest)" % processes)
        ax.plot([r["images"] for r in mine], [r["peak_mib"] for r in mine], "o-", label=label)
    ax.set_xscale("log")
    sizes = sorted({r["images"] for r in rows})
    ax.set_xticks(sizes)
    ax.set_xticklabels(["{:,}".format(n) for n in sizes])
    ax.minorticks_off()
    ax.set_ylim(bottom=0)
    ax.set_xlabel("images")
    ax.set_ylabel("peak resident memory (MiB)")
    ax.set_title("Host memory of exhaustive_matcher against the images", fontsize=10)
    if notes:
        fig.text(0.01, 0.01, notes[0][:140], fontsize=6, color="0.4")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("csv")
    parser.add_argument("--png", required=True)
    parser.add_argument("--table")
    args = parser.parse_args()
    notes, rows = read_rows(args.csv)
    text = table(notes, rows)
    print(text)
    if args.table:
        with open(args.table, "w") as f:
            f.write(text)
    plot(notes, rows, args.png)
    print("Written: %s" % args.png)


if __name__ == "__main__":
    main()
