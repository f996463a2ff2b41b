#!/usr/bin/env python3
"""What a traced run would have taken with the pipeline's two opt-in stages,
by a model replayed over its own trace (CASHASH_PIPELINE_TRACE).

    pipeline_trace_replay.py trace.csv [more.csv ...] [--diagonal_share 0.65] [--other_share 0.44]

The model keeps everything the trace measured: when each chunk's matching
ended, each verifier call's chunks, thread and duration, each chunk's rematch
and write durations. It then replays the verification threads and the writer
under four arrangements:
- as run: a verification thread completes its chunks' rematch, then calls
  the verifier (the trace's own arrangement: this row checks the model);
- ahead (CASHASH_WRITE_MATCHES_AHEAD=1): a chunk's matches are written when
  its verifier call starts, and after the call only the geometries' share of
  the chunk's write is left (--diagonal_share for chunks of fewer than 2,000
  pairs, i.e. one block against itself at blocks of 50, --other_share for
  the others; write_rows_bench --two_steps 1 measures them);
- thread (CASHASH_REMATCH_THREAD=1): one thread completes the rematches in
  matching order as chunks are matched, and a verifier call starts once its
  chunks' rematches are done and its thread is free;
- both.
Device times are taken as they were: the model ignores that a rematch
beside a verifier call shares the device with it. So it says how much of
the run was the arrangement's; only a run on the GPU says how much of that
remains. On one H100 none did: the model gave -19 % at 8,192 features, the
runs were no shorter, because the stages' kernels slowed each other once
they overlapped.
"""
import argparse
import csv


def load(path):
    matched, rematch, write, pairs, calls = {}, {}, {}, {}, {}
    end_of_run = 0.0
    with open(path) as f:
        for row in csv.DictReader(f):
            chunk, start, end = int(row["chunk"]), float(row["start"]), float(row["end"])
            end_of_run = max(end_of_run, end)
            pairs[chunk] = int(row["pairs"])
            if row["stage"] == "match":
                matched[chunk] = end
            elif row["stage"] == "rematch":
                rematch[chunk] = end - start
            elif row["stage"] == "write":
                write[chunk] = end - start
            elif row["stage"] == "verify":
                call = calls.setdefault(int(row["call"]), {"chunks": [], "start": start, "end": end,
                                                           "thread": int(row["thread"])})
                call["chunks"].append(chunk)
    return matched, rematch, write, pairs, calls, end_of_run


def replay(trace, rematch_thread, ahead, diagonal_share, other_share):
    matched, rematch, write, pairs, calls, _ = trace
    n = len(matched)
    first_call = min(c["start"] for c in calls.values())  # the gate, as traced
    ready = {}
    t = 0.0
    for c in range(n):
        t = max(t, matched[c]) + rematch.get(c, 0.0) if rematch_thread else matched[c]
        ready[c] = t
    free, call_start, call_end = {}, {}, {}
    for call in sorted(calls.values(), key=lambda c: c["start"]):
        chunks = sorted(call["chunks"])
        start = max(free.get(call["thread"], first_call), max(ready[c] for c in chunks))
        if not rematch_thread:
            start += sum(rematch.get(c, 0.0) for c in chunks)
        free[call["thread"]] = start + call["end"] - call["start"]
        for c in chunks:
            call_start[c], call_end[c] = start, free[call["thread"]]

    def share(c):
        if not ahead:
            return 1.0
        return diagonal_share if pairs[c] < 2000 else other_share

    # One writer, first come first served: matches ahead when their call
    # starts, geometries in matching order once verified.
    ahead_items = sorted((call_start[c], c) for c in range(n)) if ahead else []
    in_order, verified = [], 0.0
    for c in range(n):
        verified = max(verified, call_end[c])
        in_order.append(verified)
    writer, a, g = 0.0, 0, 0
    while g < n:
        next_ahead = ahead_items[a][0] if a < len(ahead_items) else float("inf")
        if next_ahead <= in_order[g]:
            c = ahead_items[a][1]
            writer = max(writer, next_ahead) + (1.0 - share(c)) * write[c]
            a += 1
        else:
            writer = max(writer, in_order[g]) + share(g) * write[g]
            g += 1
    return writer


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("traces", nargs="+")
    parser.add_argument("--diagonal_share", type=float, default=0.65)
    parser.add_argument("--other_share", type=float, default=0.44)
    args = parser.parse_args()
    print("| trace | traced s | model as run s | ahead s | thread s | both s | both against as run |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for path in args.traces:
        trace = load(path)
        ends = [replay(trace, thread, ahead, args.diagonal_share, args.other_share)
                for thread, ahead in [(False, False), (False, True), (True, False), (True, True)]]
        print(f"| {path} | {trace[5]:.3f} | {ends[0]:.3f} | {ends[1]:.3f} | {ends[2]:.3f} | {ends[3]:.3f} | "
              f"{100.0 * (ends[3] - ends[0]) / ends[0]:+.1f} % |")


if __name__ == "__main__":
    main()
