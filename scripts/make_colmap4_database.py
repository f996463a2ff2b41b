#!/usr/bin/env python3
"""Creates an empty COLMAP 4.x database with pycolmap, or reads one back.

  make_colmap4_database.py PATH          create PATH (must not exist) with the
                                         schema of the installed pycolmap
  make_colmap4_database.py --dump PATH   print, as pycolmap reads them, the
                                         matches and two-view geometries of the
                                         pairs given as "id1 id2" lines on stdin

The dump format is one line per value, so that a C++ test can parse it:
  pair ID1 ID2
  matches N i1 j1 i2 j2 ...
  config C
  inliers N i1 j1 ...
  F|E|H none            (unset) or  F|E|H m00 m01 ... m22 (row-major)
  pose none             or  pose qw qx qy qz tx ty tz (cam2_from_cam1)
Exit status 2: pycolmap cannot be imported (callers skip their test).
"""
import os
import sys

try:
    import pycolmap
except ImportError as error:  # pragma: no cover - depends on the machine
    print(f"pycolmap not available: {error}", file=sys.stderr)
    sys.exit(2)


def create(path):
    if os.path.exists(path):
        sys.exit(f"refusing to overwrite existing file: {path}")
    pycolmap.Database.open(path).close()


def matrix_line(name, matrix):
    if matrix is None:
        return f"{name} none"
    return name + " " + " ".join(repr(float(v)) for v in matrix.reshape(-1))


def dump(path):
    db = pycolmap.Database.open(path)
    for line in sys.stdin:
        if not line.strip():
            continue
        id1, id2 = (int(v) for v in line.split())
        print(f"pair {id1} {id2}")
        matches = db.read_matches(id1, id2)
        print(f"matches {len(matches)} " + " ".join(str(int(v)) for v in matches.reshape(-1)))
        geometry = db.read_two_view_geometry(id1, id2)
        print(f"config {int(geometry.config)}")
        inliers = geometry.inlier_matches
        print(f"inliers {len(inliers)} " + " ".join(str(int(v)) for v in inliers.reshape(-1)))
        for name in ("F", "E", "H"):
            print(matrix_line(name, getattr(geometry, name)))
        pose = geometry.cam2_from_cam1
        if pose is None:
            print("pose none")
        else:
            x, y, z, w = pose.rotation.quat  # Eigen order: x, y, z, w
            values = [w, x, y, z, *pose.translation]
            print("pose " + " ".join(repr(float(v)) for v in values))
    db.close()


def main(argv):
    if len(argv) == 2 and not argv[1].startswith("-"):
        create(argv[1])
    elif len(argv) == 3 and argv[1] == "--dump":
        dump(argv[2])
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv)
