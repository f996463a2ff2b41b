// Reading a COLMAP database file from a test by SQL, on a connection of the
// test's own, so that what it sees is what another process would see.
#pragma once

#include <sqlite3.h>

#include <cstdint>
#include <string>

namespace cashash {
namespace testing_support {

// The first column of `sql`'s first row on an open database; -1 where the
// query fails or returns no row.
inline int64_t ScalarOf(sqlite3* db, const std::string& sql) {
  sqlite3_stmt* s = nullptr;
  int64_t value = -1;
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr) == SQLITE_OK && sqlite3_step(s) == SQLITE_ROW) {
    value = sqlite3_column_int64(s, 0);
  }
  sqlite3_finalize(s);
  return value;
}

// ScalarOf on a read-only connection to `path`.
inline int64_t QueryInt(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr);
  const int64_t value = ScalarOf(db, sql);
  sqlite3_close(db);
  return value;
}

// Rows of `table` in one database and not in the other, both ways; -1 where
// the query fails.
inline int64_t RowsDiffering(const std::string& a, const std::string& b, const std::string& table) {
  sqlite3* db = nullptr;
  sqlite3_open_v2(a.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr);
  sqlite3_exec(db, ("ATTACH DATABASE '" + b + "' AS other").c_str(), nullptr, nullptr, nullptr);
  const std::string sql = "SELECT (SELECT count(*) FROM (SELECT * FROM main." + table + " EXCEPT SELECT * FROM other." +
                          table + ")) + (SELECT count(*) FROM (SELECT * FROM other." + table +
                          " EXCEPT SELECT * FROM main." + table + "))";
  const int64_t value = ScalarOf(db, sql);
  sqlite3_close(db);
  return value;
}

}  // namespace testing_support
}  // namespace cashash
