#include "colmap_bridge/sqlite_statement.h"

#include <sqlite3.h>

namespace cashash {
namespace colmap {
namespace {

// "on /path/db: database is locked (...)": which file, what SQLite says, and
// for the errors a user can act on, what to do.
std::string WhereAndWhy(sqlite3* db, const char* sqlite_message) {
  const char* file = sqlite3_db_filename(db, "main");
  std::string text = std::string(" on ") + (file != nullptr && *file ? file : "the database") +
                     ": " + sqlite_message;
  switch (sqlite3_errcode(db) & 0xff) {
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
      text += " (another process held the lock for longer than the busy timeout)";
      break;
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
      text += " (the file is damaged; PRAGMA integrity_check tells more)";
      break;
    case SQLITE_FULL:
      text += " (no space left for the database or its journal)";
      break;
    case SQLITE_IOERR:
      text += " (disk full, file size limit or failing storage; committed chunks are kept)";
      break;
    case SQLITE_READONLY:
    case SQLITE_CANTOPEN:
      text += " (check that the file and its directory are writable)";
      break;
    default:
      break;
  }
  return text;
}

}  // namespace

SqliteStatement::SqliteStatement(sqlite3* db, const std::string& sql) : db_(db), sql_(sql) {
  if (sqlite3_prepare_v2(db_, sql_.c_str(), -1, &stmt_, nullptr) != SQLITE_OK) {
    Fail("preparing");
  }
}

SqliteStatement::~SqliteStatement() { sqlite3_finalize(stmt_); }

void SqliteStatement::Fail(const char* action) const {
  throw DatabaseError(std::string("SQLite error ") + action + " \"" + sql_ + "\"" +
                      WhereAndWhy(db_, sqlite3_errmsg(db_)));
}

void SqliteStatement::BindInt64(int index, int64_t value) {
  if (sqlite3_bind_int64(stmt_, index, value) != SQLITE_OK) Fail("binding");
}

void SqliteStatement::BindDouble(int index, double value) {
  if (sqlite3_bind_double(stmt_, index, value) != SQLITE_OK) Fail("binding");
}

void SqliteStatement::BindNull(int index) {
  if (sqlite3_bind_null(stmt_, index) != SQLITE_OK) Fail("binding");
}

void SqliteStatement::BindBlob(int index, const void* data, size_t num_bytes) {
  if (num_bytes == 0) {
    BindNull(index);
    return;
  }
  if (sqlite3_bind_blob64(stmt_, index, data, num_bytes, SQLITE_STATIC) != SQLITE_OK) {
    Fail("binding");
  }
}

void SqliteStatement::BindText(int index, const std::string& text) {
  if (sqlite3_bind_text(stmt_, index, text.c_str(), static_cast<int>(text.size()),
                        SQLITE_TRANSIENT) != SQLITE_OK) {
    Fail("binding");
  }
}

bool SqliteStatement::Step() {
  const int rc = sqlite3_step(stmt_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  Fail("running");
}

void SqliteStatement::Execute() {
  while (Step()) {
  }
}

int64_t SqliteStatement::ColumnInt64(int col) const { return sqlite3_column_int64(stmt_, col); }

bool SqliteStatement::ColumnIsNull(int col) const {
  return sqlite3_column_type(stmt_, col) == SQLITE_NULL;
}

double SqliteStatement::ColumnDouble(int col) const { return sqlite3_column_double(stmt_, col); }

const void* SqliteStatement::ColumnBlob(int col) const { return sqlite3_column_blob(stmt_, col); }

size_t SqliteStatement::ColumnBytes(int col) const {
  return static_cast<size_t>(sqlite3_column_bytes(stmt_, col));
}

std::string SqliteStatement::ColumnText(int col) const {
  const unsigned char* text = sqlite3_column_text(stmt_, col);
  return text == nullptr ? std::string()
                         : std::string(reinterpret_cast<const char*>(text),
                                       static_cast<size_t>(sqlite3_column_bytes(stmt_, col)));
}

void SqliteStatement::Reset() {
  // sqlite3_reset repeats the last step's error, which was already reported.
  sqlite3_reset(stmt_);
  sqlite3_clear_bindings(stmt_);
}

void SqliteStatement::ResetKeepingBindings() { sqlite3_reset(stmt_); }

void ExecuteSql(sqlite3* db, const std::string& sql) {
  char* message = nullptr;
  if (sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &message) != SQLITE_OK) {
    const std::string text = WhereAndWhy(db, message != nullptr ? message : sqlite3_errmsg(db));
    sqlite3_free(message);
    throw DatabaseError("SQLite error running \"" + sql + "\"" + text);
  }
}

}  // namespace colmap
}  // namespace cashash
