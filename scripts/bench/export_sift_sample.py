#!/usr/bin/env python3
"""Writes SIFT rows of a COLMAP feature database as a raw uint8 file.

  export_sift_sample.py --database_path features.db --output sift_sample.u8 [--rows 65536]

The GPU benchmarks (gpu_matching_bench_gpu --sample, generate_database on a
machine without the photographs) draw their descriptors from such a file: N
rows of 128 bytes, no header. Rows are taken from every image in turn so
that the sample mixes all views; fewer are written when the database holds
fewer.
"""
import argparse
import sqlite3
import sys

import numpy as np


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--database_path", required=True)
    parser.add_argument("--output", required=True)
    parser.add_argument("--rows", type=int, default=65536)
    args = parser.parse_args()

    connection = sqlite3.connect(f"file:{args.database_path}?mode=ro", uri=True)
    per_image = []
    for image_id, rows, cols, data in connection.execute(
            "SELECT image_id, rows, cols, data FROM descriptors ORDER BY image_id"):
        if cols != 128 or data is None or len(data) != rows * cols:
            print(f"descriptors of image {image_id} are not {rows} x 128 uint8 rows: skipped", file=sys.stderr)
            continue
        per_image.append(np.frombuffer(data, dtype=np.uint8).reshape(rows, 128))
    if not per_image:
        print(f"no 128-column uint8 descriptors in {args.database_path}", file=sys.stderr)
        return 1

    # Round robin over the images: row i of every image before row i + 1.
    longest = max(len(d) for d in per_image)
    picked = []
    for i in range(longest):
        for d in per_image:
            if i < len(d):
                picked.append(d[i])
            if len(picked) == args.rows:
                break
        if len(picked) == args.rows:
            break
    np.stack(picked).tofile(args.output)
    print(f"wrote {len(picked)} rows of 128 bytes from {len(per_image)} images to {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
