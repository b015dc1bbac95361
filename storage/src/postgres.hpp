// Thin RAII wrappers over libpq (PostgreSQL's C client) that turn every failure into a StorageError with a
// code, as sqlite.hpp does for SQLite. Results come back in binary (bytea without hex escaping, exact
// doubles); parameters go as text, except blobs, which go as binary.
#pragma once

#include <libpq-fe.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "sglc/storage/map_store.hpp"

namespace sglc::storage::pg {

// True for "postgresql://..." and "postgres://..." (libpq's URI forms).
bool isUrl(const std::string& path);
// The URL with its password replaced by "***", for messages and logs.
std::string redacted(const std::string& url);

// One statement parameter: NULL, text (numbers, names) or a binary blob. Borrowed bytes must outlive the call.
class Param {
 public:
  Param() = default;                                   // NULL
  Param(std::int64_t v) : text_(std::to_string(v)) {}  // NOLINT(google-explicit-constructor): reads as SQL
  Param(int v) : text_(std::to_string(v)) {}           // NOLINT(google-explicit-constructor)
  Param(double v);                                     // NOLINT(google-explicit-constructor)
  Param(std::string v) : text_(std::move(v)) {}        // NOLINT(google-explicit-constructor)
  Param(const char* v) : text_(v) {}                   // NOLINT(google-explicit-constructor)
  Param(std::span<const std::uint8_t> blob)            // NOLINT(google-explicit-constructor)
      : blob_(blob), binary_(true) {}

  const char* data() const {
    if (binary_) return reinterpret_cast<const char*>(blob_.data());
    return text_ ? text_->c_str() : nullptr;
  }
  int length() const { return binary_ ? static_cast<int>(blob_.size()) : text_ ? static_cast<int>(text_->size()) : 0; }
  bool binary() const { return binary_; }

 private:
  std::optional<std::string> text_;
  std::span<const std::uint8_t> blob_;
  bool binary_ = false;
};

// A result in binary format. Accessors check the column's type and throw kCorrupt for one they cannot read.
class Result {
 public:
  explicit Result(PGresult* r) : r_(r, &PQclear) {}
  int rows() const { return PQntuples(r_.get()); }
  bool isNull(int row, int col) const {
    check(row, col);
    return PQgetisnull(r_.get(), row, col) != 0;
  }
  // Every accessor checks that the row and column exist (kCorrupt otherwise: a query that found nothing).
  std::int64_t i64(int row, int col) const;
  double f64(int row, int col) const;
  bool boolean(int row, int col) const { return i64(row, col) != 0; }
  std::string text(int row, int col) const;
  std::span<const std::uint8_t> blob(int row, int col) const;

 private:
  void check(int row, int col) const;
  std::unique_ptr<PGresult, void (*)(PGresult*)> r_;
};

// What a failure of `code` means for the caller, in words without SQL or addresses.
std::string meaning(StorageError::Code code);

class Conn {
 public:
  // Connects (libpq's connect_timeout bounds the wait; TCP keepalives notice a dead peer), then runs `setup`
  // (session settings, LISTEN), again after every reconnect. kUnavailable when the server cannot be reached,
  // kInvalidArgument for a URL libpq cannot parse; messages carry the redacted URL only.
  explicit Conn(const std::string& url, std::string setup = "");
  Conn(Conn&&) = default;
  Conn& operator=(Conn&&) = default;

  // Statements without parameters (several may be separated by ';').
  void exec(const std::string& sql) const;
  Result query(const char* sql, const std::vector<Param>& params = {}) const;
  // Readers' connections: a statement outside a transaction that fails because the connection was lost (a
  // server restart, a terminated backend: its end may show only when a statement is sent) is sent once more on
  // the re-established connection. Only for reads: a lost write's outcome is unknown.
  void retryReadsWhenLost() { retry_reads_ = true; }
  // COPY ... FROM STDIN with `data` in COPY's text format.
  void copyIn(const std::string& copy_sql, const std::string& data) const;
  // A lost connection (server restarted, backend terminated) is re-established, its setup run again; true when
  // the connection is usable. Looks at the socket, so a connection the server closed while idle is noticed here
  // rather than by the next statement.
  bool ensureOpen() const;
  PGconn* get() const { return c_.get(); }

 private:
  [[noreturn]] void fail(const PGresult* r, const char* sql) const;
  std::unique_ptr<PGconn, void (*)(PGconn*)> c_{nullptr, &PQfinish};
  std::string redacted_;
  std::string setup_;
  bool retry_reads_ = false;
  // Set when the server said FATAL while the connection was idle (it is ending the session: a terminated backend,
  // a shutdown), which libpq passes on as a notice, before the connection's status shows it.
  std::unique_ptr<std::atomic<bool>> ending_ = std::make_unique<std::atomic<bool>>(false);
};

// BEGIN ... COMMIT on `conn`, rolled back on destruction unless committed.
class Transaction {
 public:
  explicit Transaction(const Conn& conn);
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  ~Transaction();
  void commit();

 private:
  const Conn& conn_;
  bool done_ = false;
};

// Connections for readers, pooled: each caller gets one of its own for the lease.
class Pool {
 public:
  explicit Pool(std::string url) : url_(std::move(url)) {}
  ~Pool();
  class Lease {
   public:
    Lease(const Pool& pool, std::unique_ptr<Conn> conn) : pool_(pool), conn_(std::move(conn)) {}
    Lease(Lease&&) = default;
    ~Lease() {
      if (conn_) pool_.release(std::move(conn_));
    }
    const Conn& operator*() const { return *conn_; }
    const Conn* operator->() const { return conn_.get(); }

   private:
    const Pool& pool_;
    std::unique_ptr<Conn> conn_;
  };
  Lease acquire() const;

 private:
  static constexpr std::size_t kKept = 8;
  void release(std::unique_ptr<Conn> conn) const;
  const std::string url_;
  mutable std::mutex mutex_;
  mutable std::vector<std::unique_ptr<Conn>> idle_;
};

}  // namespace sglc::storage::pg
