#include "sqlite.hpp"

#include <cerrno>

namespace sglc::storage::sql {

StorageError::Code classify(int rc) {
  switch (rc & 0xFF) {
    case SQLITE_FULL:
      return StorageError::Code::kFull;
    case SQLITE_READONLY:
    case SQLITE_PERM:
    case SQLITE_CANTOPEN:
      return StorageError::Code::kReadOnly;
    case SQLITE_NOTADB:
    case SQLITE_CORRUPT:
      return StorageError::Code::kCorrupt;
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
      return StorageError::Code::kBusy;
    case SQLITE_CONSTRAINT:
      return StorageError::Code::kAlreadyExists;
    default:
      return StorageError::Code::kIo;
  }
}

namespace {

// The errno of the last failed system call on the database file or, when that has none, on its journal or WAL
// file. A COMMIT that fails writing the WAL leaves sqlite3_system_errno at 0; the WAL file keeps the errno.
int lastFileErrno(sqlite3* db) {
  int e = 0;
  sqlite3_file_control(db, "main", SQLITE_FCNTL_LAST_ERRNO, &e);
  if (e != 0) return e;
  sqlite3_file* journal = nullptr;
  if (sqlite3_file_control(db, "main", SQLITE_FCNTL_JOURNAL_POINTER, &journal) == SQLITE_OK && journal &&
      journal->pMethods && journal->pMethods->xFileControl)
    journal->pMethods->xFileControl(journal, SQLITE_FCNTL_LAST_ERRNO, &e);
  return e;
}

// A read-only file system shows up as an I/O error (EROFS) rather than SQLITE_READONLY, as a full disk may.
StorageError::Code classify(sqlite3* db, int rc) {
  if (db && (rc & 0xFF) == SQLITE_IOERR) {
    int e = sqlite3_system_errno(db);
    if (e == 0) e = lastFileErrno(db);
    if (e == EROFS || e == EACCES || e == EPERM) return StorageError::Code::kReadOnly;
    if (e == ENOSPC || e == EDQUOT) return StorageError::Code::kFull;
  }
  return sql::classify(rc);
}

}  // namespace

std::string meaning(StorageError::Code code) {
  switch (code) {
    case StorageError::Code::kFull:
      return "the map database's disk is full (or the database reached its size limit)";
    case StorageError::Code::kReadOnly:
      return "the map database cannot be written (read-only file or file system, or no permission)";
    case StorageError::Code::kCorrupt:
      return "the map database is damaged";
    case StorageError::Code::kBusy:
      return "the map database is locked by another process";
    case StorageError::Code::kAlreadyExists:
      return "the record already exists";
    default:
      return "the map database had an I/O error";
  }
}

void fail(sqlite3* db, int rc, const std::string& what) {
  std::string detail = what + ": " + sqlite3_errstr(rc);
  if (db) {
    const char* msg = sqlite3_errmsg(db);
    if (msg && detail.find(msg) == std::string::npos) detail += " (" + std::string(msg) + ")";
  }
  const auto code = classify(db, rc);
  throw StorageError(code, meaning(code), detail);
}

Db::Db(const std::string& path, int flags, int busy_timeout_ms) {
  const int rc = sqlite3_open_v2(path.c_str(), &db_, flags | SQLITE_OPEN_NOMUTEX, nullptr);
  if (rc != SQLITE_OK) {
    std::string msg = path + ": cannot open: " + sqlite3_errstr(rc);
    sqlite3_close(db_);
    db_ = nullptr;
    throw StorageError(classify(rc), msg);
  }
  sqlite3_extended_result_codes(db_, 1);
  sqlite3_busy_timeout(db_, busy_timeout_ms);
}

Db& Db::operator=(Db&& other) noexcept {
  if (this != &other) {
    if (db_) sqlite3_close(db_);
    db_ = other.db_;
    other.db_ = nullptr;
  }
  return *this;
}

Db::~Db() {
  if (db_) sqlite3_close(db_);
}

void Db::exec(const std::string& sql) const {
  char* err = nullptr;
  const int rc = sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err);
  if (rc != SQLITE_OK) {
    std::string msg = err ? err : "";
    sqlite3_free(err);
    const auto code = classify(db_, rc);
    throw StorageError(code, meaning(code), "sqlite: " + sql.substr(0, 60) + ": " + msg);
  }
}

Stmt::Stmt(const Db& db, const char* sql) : db_(db.get()) {
  const int rc = sqlite3_prepare_v2(db_, sql, -1, &stmt_, nullptr);
  if (rc != SQLITE_OK) fail(db_, rc, std::string("prepare ") + sql);
}

Stmt::~Stmt() { sqlite3_finalize(stmt_); }

Stmt& Stmt::bind(int i, std::int64_t v) {
  sqlite3_bind_int64(stmt_, i, v);
  return *this;
}
Stmt& Stmt::bind(int i, double v) {
  sqlite3_bind_double(stmt_, i, v);
  return *this;
}
Stmt& Stmt::bind(int i, const std::string& v) {
  sqlite3_bind_text(stmt_, i, v.data(), static_cast<int>(v.size()), SQLITE_TRANSIENT);
  return *this;
}
Stmt& Stmt::bindBlob(int i, std::span<const std::uint8_t> v) {
  sqlite3_bind_blob64(stmt_, i, v.data(), v.size(), SQLITE_STATIC);
  return *this;
}
Stmt& Stmt::bindNull(int i) {
  sqlite3_bind_null(stmt_, i);
  return *this;
}

bool Stmt::step() {
  const int rc = sqlite3_step(stmt_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  fail(db_, rc, std::string("sqlite step: ") + sqlite3_sql(stmt_));
}

void Stmt::run() {
  while (step()) {
  }
  reset();
}

void Stmt::reset() {
  sqlite3_reset(stmt_);
  sqlite3_clear_bindings(stmt_);
}

std::string Stmt::text(int col) const {
  const auto* p = sqlite3_column_text(stmt_, col);
  return p ? std::string(reinterpret_cast<const char*>(p), static_cast<std::size_t>(sqlite3_column_bytes(stmt_, col)))
           : std::string();
}

std::span<const std::uint8_t> Stmt::blob(int col) const {
  const auto* p = static_cast<const std::uint8_t*>(sqlite3_column_blob(stmt_, col));
  return {p, static_cast<std::size_t>(sqlite3_column_bytes(stmt_, col))};
}

Transaction::Transaction(const Db& db) : db_(db) { db_.exec("BEGIN IMMEDIATE"); }

Transaction::~Transaction() {
  if (!done_) sqlite3_exec(db_.get(), "ROLLBACK", nullptr, nullptr, nullptr);
}

void Transaction::commit() {
  db_.exec("COMMIT");
  done_ = true;
}

}  // namespace sglc::storage::sql
