#!/usr/bin/env python3
"""Where a matching run's time went, from its pipeline trace.

    cashash exhaustive_matcher --database_path db.db --pipeline_trace_path trace.csv
    pipeline_trace_summary.py trace.csv

The run's summary line gives each stage's busy and waiting time; the trace
(one line per chunk and stage: load, match, rematch, verify, write_ahead,
write) says
what overlapped what. This prints, in Markdown:
- per stage, the busy time summed over threads and the wall time during
  which at least one was busy;
- how long 0, 1, 2, ... verifier calls were in flight;
- the tail: from the end of the last match to the end of the run, what ran
  in it, and how much of it was writing alone (nothing left for the device);
- verifier calls: how many, chunks per call, mean and longest duration.
"""
import argparse
import csv
import sys
from collections import defaultdict


def read_events(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    events = []
    for r in rows:
        events.append({"stage": r["stage"], "chunk": int(r["chunk"]), "call": int(r["call"]),
                       "thread": int(r["thread"]), "start": float(r["start"]), "end": float(r["end"]),
                       "pairs": int(r["pairs"])})
    return events


def union_length(intervals):
    """Wall time covered by at least one of the intervals."""
    total, current_start, current_end = 0.0, None, None
    for start, end in sorted(intervals):
        if current_end is None or start > current_end:
            if current_end is not None:
                total += current_end - current_start
            current_start, current_end = start, end
        else:
            current_end = max(current_end, end)
    if current_end is not None:
        total += current_end - current_start
    return total


def time_at_depth(intervals, end_of_run):
    """Seconds during which exactly k intervals were open, for each k."""
    edges = sorted([(s, 1) for s, _ in intervals] + [(e, -1) for _, e in intervals])
    depth, last, out = 0, 0.0, defaultdict(float)
    for t, step in edges:
        out[depth] += t - last
        depth, last = depth + step, t
    out[depth] += max(0.0, end_of_run - last)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("trace", help="the CSV that --pipeline_trace_path named")
    args = parser.parse_args()
    events = read_events(args.trace)
    if not events:
        sys.exit(f"{args.trace}: no events")
    end_of_run = max(e["end"] for e in events)
    print(f"Run: {end_of_run:.3f} s from the pipeline's start to its last write, "
          f"{len({e['chunk'] for e in events})} chunks\n")

    calls = {}
    for e in events:
        if e["stage"] == "verify":
            calls.setdefault(e["call"], {"start": e["start"], "end": e["end"], "chunks": 0, "pairs": 0})
            calls[e["call"]]["chunks"] += 1
            calls[e["call"]]["pairs"] += e["pairs"]

    print("| stage | busy s (summed over threads) | wall s with one or more busy |")
    print("|---|---:|---:|")
    for stage in ["load", "match", "rematch", "verify", "write_ahead", "write"]:
        if stage == "verify":
            intervals = [(c["start"], c["end"]) for c in calls.values()]
        else:
            intervals = [(e["start"], e["end"]) for e in events if e["stage"] == stage]
        if not intervals:
            continue
        busy = sum(end - start for start, end in intervals)
        print(f"| {stage} | {busy:.3f} | {union_length(intervals):.3f} |")

    if calls:
        print("\n| verifier calls in flight | s |")
        print("|---:|---:|")
        depth = time_at_depth([(c["start"], c["end"]) for c in calls.values()], end_of_run)
        for k in sorted(depth):
            print(f"| {k} | {depth[k]:.3f} |")
        durations = [c["end"] - c["start"] for c in calls.values()]
        chunks = [c["chunks"] for c in calls.values()]
        print(f"\nVerifier calls: {len(calls)}, {sum(chunks) / len(calls):.2f} chunks per call "
              f"(at most {max(chunks)}), {1e3 * sum(durations) / len(calls):.1f} ms each on average, "
              f"longest {1e3 * max(durations):.1f} ms")

    matching = [e for e in events if e["stage"] == "match"]
    if matching:
        last_match = max(e["end"] for e in matching)
        tail = [e for e in events if e["end"] > last_match and e["stage"] != "match"]
        print(f"\nTail: {end_of_run - last_match:.3f} s after the last match ended "
              f"({last_match:.3f} s into the run), in which:")
        for stage in ["rematch", "verify", "write_ahead", "write"]:
            if stage == "verify":
                intervals = [(max(c["start"], last_match), c["end"]) for c in calls.values() if c["end"] > last_match]
            else:
                intervals = [(max(e["start"], last_match), e["end"]) for e in tail if e["stage"] == stage]
            if intervals:
                print(f"- {stage}: {union_length(intervals):.3f} s of wall time, {len(intervals)} intervals")
        device = [e["end"] for e in events if e["stage"] in ("match", "rematch", "verify")]
        print(f"- writing alone, after the last match, rematch and verification: {end_of_run - max(device):.3f} s")


if __name__ == "__main__":
    main()
