// A prepared SQLite statement owned by one object: finalized on destruction,
// reset (bindings cleared) before each reuse, every failure thrown as a
// DatabaseError that quotes the SQL. Preparing once and re-binding is what
// makes writing 100k pairs take seconds instead of minutes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "colmap_bridge/database.h"

struct sqlite3_stmt;

namespace cashash {
namespace colmap {

class SqliteStatement {
 public:
  SqliteStatement(sqlite3* db, const std::string& sql);
  ~SqliteStatement();
  SqliteStatement(const SqliteStatement&) = delete;
  SqliteStatement& operator=(const SqliteStatement&) = delete;

  // Parameter indices are 1-based, as in SQLite.
  void BindInt64(int index, int64_t value);
  void BindDouble(int index, double value);
  void BindNull(int index);
  // Binds NULL when num_bytes is 0 (what COLMAP stores for empty matrices).
  // The bytes must stay alive until Step() returned.
  void BindBlob(int index, const void* data, size_t num_bytes);
  void BindText(int index, const std::string& text);

  // Runs one step: true when a row is available, false when done.
  bool Step();
  // Runs a statement that returns no rows to completion.
  void Execute();

  // Column indices are 0-based, as in SQLite.
  int64_t ColumnInt64(int col) const;
  bool ColumnIsNull(int col) const;
  // SQLite's conversion: NULL reads as 0, text as its leading number.
  double ColumnDouble(int col) const;
  const void* ColumnBlob(int col) const;
  size_t ColumnBytes(int col) const;
  std::string ColumnText(int col) const;

  // Makes the statement reusable and releases the read snapshot it holds.
  void Reset();
  // As Reset, but keeps the bound values: for a write whose every
  // parameter is bound again before it runs.
  void ResetKeepingBindings();

 private:
  [[noreturn]] void Fail(const char* action) const;

  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  std::string sql_;
};

// Resets a statement when leaving scope, also on exceptions, so that no
// half-run statement keeps a read transaction open.
class StatementScope {
 public:
  explicit StatementScope(SqliteStatement& statement) : statement_(statement) {
    statement_.Reset();
  }
  ~StatementScope() { statement_.Reset(); }
  StatementScope(const StatementScope&) = delete;
  StatementScope& operator=(const StatementScope&) = delete;
  SqliteStatement* operator->() { return &statement_; }
  SqliteStatement& operator*() { return statement_; }

 private:
  SqliteStatement& statement_;
};

// Runs SQL without results (BEGIN, COMMIT, DELETE ...).
void ExecuteSql(sqlite3* db, const std::string& sql);

}  // namespace colmap
}  // namespace cashash
