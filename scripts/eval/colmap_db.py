"""Reads what the evaluation needs from a COLMAP SQLite database with numpy."""
import sqlite3

import numpy as np

PAIR_ID_FACTOR = 2147483647


def pair_id(id1, id2):
    return PAIR_ID_FACTOR * min(id1, id2) + max(id1, id2)


class Database:
    def __init__(self, path):
        # Read-only URI so that evaluation can never modify a database.
        self.conn = sqlite3.connect("file:%s?mode=ro" % path, uri=True)

    def close(self):
        self.conn.close()

    def image_ids_by_name(self):
        return {name: image_id for image_id, name in self.conn.execute("SELECT image_id, name FROM images")}

    def keypoints(self, image_id):
        """N x 2 keypoint positions (COLMAP convention: upper-left pixel centre at 0.5)."""
        rows, cols, data = self.conn.execute(
            "SELECT rows, cols, data FROM keypoints WHERE image_id = ?", (image_id,)).fetchone()
        return np.frombuffer(data, dtype=np.float32).reshape(rows, cols)[:, :2].astype(np.float64)

    def descriptors(self, image_id):
        rows, cols, data = self.conn.execute(
            "SELECT rows, cols, data FROM descriptors WHERE image_id = ?", (image_id,)).fetchone()
        return np.frombuffer(data, dtype=np.uint8).reshape(rows, cols)

    def _pair_rows(self, table, id1, id2):
        row = self.conn.execute("SELECT rows, data FROM %s WHERE pair_id = ?" % table,
                                (pair_id(id1, id2),)).fetchone()
        if row is None or row[0] == 0 or row[1] is None:
            return np.zeros((0, 2), dtype=np.int64)
        m = np.frombuffer(row[1], dtype=np.uint32).reshape(row[0], 2).astype(np.int64)
        # Column 0 indexes the smaller image id; return (feature in id1, feature in id2).
        return m if id1 < id2 else m[:, ::-1].copy()

    def raw_matches(self, id1, id2):
        """Raw matches (before geometric verification) as (idx in id1, idx in id2)."""
        return self._pair_rows("matches", id1, id2)

    def inlier_matches(self, id1, id2):
        return self._pair_rows("two_view_geometries", id1, id2)

    def all_inlier_rows(self):
        """{pair_id: {(idx in the smaller image id, idx in the larger)}} of every verified pair."""
        out = {}
        for pid, rows, data in self.conn.execute("SELECT pair_id, rows, data FROM two_view_geometries"):
            if rows and data is not None:
                m = np.frombuffer(data, dtype=np.uint32).reshape(rows, 2)
                out[pid] = set(zip(m[:, 0].tolist(), m[:, 1].tolist()))
        return out
