#include "postgres.hpp"

#include <endian.h>
#include <poll.h>

#include <array>
#include <cstdio>
#include <cstring>

#include "sglc/names.hpp"

namespace sglc::storage::pg {
namespace {

using Code = StorageError::Code;

// Type OIDs of PostgreSQL's built-in types (fixed in its catalogue).
constexpr Oid kBool = 16, kBytea = 17, kName = 19, kInt8 = 20, kInt2 = 21, kInt4 = 23, kText = 25, kFloat4 = 700,
              kFloat8 = 701, kVarchar = 1043;

template <typename T>
T bigEndian(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  if constexpr (sizeof(T) == 8) return static_cast<T>(be64toh(static_cast<std::uint64_t>(v)));
  if constexpr (sizeof(T) == 4) return static_cast<T>(be32toh(static_cast<std::uint32_t>(v)));
  if constexpr (sizeof(T) == 2) return static_cast<T>(be16toh(static_cast<std::uint16_t>(v)));
  return v;
}

// SQLSTATE (PostgreSQL's error code) to our codes.
Code classify(const char* sqlstate) {
  const std::string s = sqlstate ? sqlstate : "";
  if (s == "23505") return Code::kAlreadyExists;             // unique_violation
  if (s == "23503") return Code::kNotFound;                  // foreign_key_violation: a row it refers to is gone
  if (s == "53100") return Code::kFull;                      // disk_full
  if (s == "25006" || s == "42501") return Code::kReadOnly;  // read-only transaction, insufficient privilege
  if (s == "55P03" || s == "40001" || s == "40P01" || s == "57014") return Code::kBusy;  // lock/statement timeout
  // The connection is gone: lost, or ended by the server (57P01 terminated, 57P05 idle session, 25P03 a
  // transaction idle past idle_in_transaction_session_timeout: a stalled writer). A retry reconnects.
  if (s.rfind("08", 0) == 0 || s.rfind("57P", 0) == 0 || s == "25P03" || s.empty()) return Code::kUnavailable;
  if (s == "XX001" || s == "XX002" || s == "42P01" || s == "42703") return Code::kCorrupt;  // damage, missing table
  if (s == "22021") return Code::kInvalidArgument;  // a name that is not valid UTF-8 (text columns hold UTF-8)
  return Code::kIo;
}

// Notices are not shown; a FATAL one (the server ending an idle session) marks the connection as ending.
void onNotice(void* ending, const PGresult* notice) {
  const char* severity = PQresultErrorField(notice, PG_DIAG_SEVERITY_NONLOCALIZED);
  if (severity && (std::strcmp(severity, "FATAL") == 0 || std::strcmp(severity, "PANIC") == 0))
    static_cast<std::atomic<bool>*>(ending)->store(true);
}

// The server's side of the keepalives: a client whose machine vanished (no FIN, no RST) is noticed within about
// 25 s, so that the locks its session holds (the write lock mid-transaction, a map's pose graph) are freed
// rather than held for the server's default of over two hours. No effect over a Unix socket.
constexpr const char* kServerSide =
    "SET tcp_keepalives_idle = 10; SET tcp_keepalives_interval = 5; SET tcp_keepalives_count = 3; "
    "SET tcp_user_timeout = 30000";

}  // namespace

bool isUrl(const std::string& path) { return path.rfind("postgresql://", 0) == 0 || path.rfind("postgres://", 0) == 0; }

std::string redacted(const std::string& url) {
  // scheme://[user[:password]@]host...: the password is between the first ':' after the scheme and the '@'.
  const auto scheme = url.find("://");
  if (scheme == std::string::npos) return url;
  const auto at = url.find('@', scheme + 3);
  const auto slash = url.find('/', scheme + 3);
  std::string out = url;
  if (at != std::string::npos && (slash == std::string::npos || at < slash)) {
    const auto colon = url.find(':', scheme + 3);
    if (colon != std::string::npos && colon < at) out = url.substr(0, colon + 1) + "***" + url.substr(at);
  }
  // Among the query parameters, any whose name decodes to "password" (libpq decodes %xx in names too).
  const auto query = out.find('?');
  if (query == std::string::npos) return out;
  std::string result = out.substr(0, query + 1);
  for (std::size_t start = query + 1; start <= out.size();) {
    const auto end = std::min(out.find('&', start), out.size());
    const std::string param = out.substr(start, end - start);
    const auto eq = param.find('=');
    result += eq != std::string::npos && percentDecoded(param.substr(0, eq)) == "password"
                  ? param.substr(0, eq + 1) + "***"
                  : param;
    if (end == out.size()) break;
    result += '&';
    start = end + 1;
  }
  return result;
}

Param::Param(double v) {
  std::array<char, 32> buf{};
  std::snprintf(buf.data(), buf.size(), "%.17g", v);  // round-trips every finite double
  text_ = buf.data();
}

void Result::check(int row, int col) const {
  if (row < 0 || row >= PQntuples(r_.get()) || col < 0 || col >= PQnfields(r_.get()))
    throw StorageError(Code::kCorrupt, meaning(Code::kCorrupt),
                       "row " + std::to_string(row) + " column " + std::to_string(col) + " is not in the result");
}

std::int64_t Result::i64(int row, int col) const {
  check(row, col);
  const char* p = PQgetvalue(r_.get(), row, col);
  switch (PQftype(r_.get(), col)) {
    case kInt8:
      return bigEndian<std::int64_t>(p);
    case kInt4:
      return bigEndian<std::int32_t>(p);
    case kInt2:
      return bigEndian<std::int16_t>(p);
    case kBool:
      return *p != 0;
    default:
      throw StorageError(Code::kCorrupt, meaning(Code::kCorrupt),
                         "column " + std::to_string(col) + " is not an integer");
  }
}

double Result::f64(int row, int col) const {
  check(row, col);
  const char* p = PQgetvalue(r_.get(), row, col);
  switch (PQftype(r_.get(), col)) {
    case kFloat8: {
      const auto bits = bigEndian<std::uint64_t>(p);
      double v;
      std::memcpy(&v, &bits, sizeof v);
      return v;
    }
    case kFloat4: {
      const auto bits = bigEndian<std::uint32_t>(p);
      float v;
      std::memcpy(&v, &bits, sizeof v);
      return v;
    }
    default:
      return static_cast<double>(i64(row, col));
  }
}

std::string Result::text(int row, int col) const {
  check(row, col);
  const auto type = PQftype(r_.get(), col);
  if (type != kText && type != kVarchar && type != kName)
    throw StorageError(Code::kCorrupt, meaning(Code::kCorrupt), "column " + std::to_string(col) + " is not text");
  return {PQgetvalue(r_.get(), row, col), static_cast<std::size_t>(PQgetlength(r_.get(), row, col))};
}

std::span<const std::uint8_t> Result::blob(int row, int col) const {
  check(row, col);
  if (PQftype(r_.get(), col) != kBytea)
    throw StorageError(Code::kCorrupt, meaning(Code::kCorrupt), "column " + std::to_string(col) + " is not bytea");
  return {reinterpret_cast<const std::uint8_t*>(PQgetvalue(r_.get(), row, col)),
          static_cast<std::size_t>(PQgetlength(r_.get(), row, col))};
}

std::string meaning(Code code) {
  switch (code) {
    case Code::kFull:
      return "the map database's disk is full (or the database reached its size limit)";
    case Code::kReadOnly:
      return "the map database cannot be written (read-only server, or no permission)";
    case Code::kCorrupt:
      return "the map database is damaged or not an SGLC map";
    case Code::kBusy:
      return "the map database is busy (a lock was not granted in time)";
    case Code::kAlreadyExists:
      return "the record already exists";
    case Code::kNotFound:
      return "a record it refers to no longer exists";
    case Code::kUnavailable:
      return "the map database (PostgreSQL) cannot be reached";
    case Code::kInvalidArgument:
      return "a name is not valid UTF-8 (a PostgreSQL map stores names as UTF-8 text)";
    default:
      return "the map database had an error";
  }
}

Conn::Conn(const std::string& url, std::string setup) : redacted_(redacted(url)), setup_(std::move(setup)) {
  char* parse_error = nullptr;
  PQconninfoOption* parsed = PQconninfoParse(url.c_str(), &parse_error);
  if (!parsed) {
    PQfreemem(parse_error);  // it may quote the password: not passed on
    throw StorageError(Code::kInvalidArgument, "the PostgreSQL URL is not valid",
                       "libpq cannot parse the URL " + redacted_);
  }
  PQconninfoFree(parsed);
  // Our defaults first: the URL's own settings (expanded from dbname) override them. Keepalives and the TCP
  // user timeout bound how long a call waits on a server that vanished from the network.
  const std::array<const char*, 9> keys = {"connect_timeout",
                                           "application_name",
                                           "keepalives",
                                           "keepalives_idle",
                                           "keepalives_interval",
                                           "keepalives_count",
                                           "tcp_user_timeout",
                                           "dbname",
                                           nullptr};
  const std::array<const char*, 9> values = {"10", "sglc", "1", "10", "5", "3", "30000", url.c_str(), nullptr};
  c_.reset(PQconnectdbParams(keys.data(), values.data(), 1));
  if (!c_ || PQstatus(c_.get()) != CONNECTION_OK) {
    // Where the database is (user, host, port, name) is for the operator's log, not for every caller.
    std::string detail = "cannot connect to PostgreSQL at " + redacted_ + ": ";
    detail += c_ ? PQerrorMessage(c_.get()) : "out of memory";
    while (!detail.empty() && detail.back() == '\n') detail.pop_back();
    throw StorageError(Code::kUnavailable, meaning(Code::kUnavailable), detail);
  }
  PQsetNoticeReceiver(c_.get(), &onNotice, ending_.get());
  exec(kServerSide);
  if (!setup_.empty()) exec(setup_);
}

void Conn::fail(const PGresult* r, const char* sql) const {
  const char* state = r ? PQresultErrorField(r, PG_DIAG_SQLSTATE) : nullptr;
  const auto code = r && PQstatus(c_.get()) == CONNECTION_OK ? classify(state) : Code::kUnavailable;
  std::string detail = std::string(sql).substr(0, 120) + ": ";
  detail += r && PQresultErrorMessage(r)[0] ? PQresultErrorMessage(r) : PQerrorMessage(c_.get());
  while (!detail.empty() && detail.back() == '\n') detail.pop_back();
  throw StorageError(code, meaning(code), detail);
}

void Conn::exec(const std::string& sql) const {
  PGresult* r = PQexec(c_.get(), sql.c_str());
  Result owned(r);
  const auto status = r ? PQresultStatus(r) : PGRES_FATAL_ERROR;
  if (status != PGRES_COMMAND_OK && status != PGRES_TUPLES_OK) fail(r, sql.c_str());
}

Result Conn::query(const char* sql, const std::vector<Param>& params) const {
  std::vector<const char*> values;
  std::vector<int> lengths, formats;
  for (const auto& p : params) {
    values.push_back(p.data());
    lengths.push_back(p.length());
    formats.push_back(p.binary() ? 1 : 0);
  }
  const bool outside = PQtransactionStatus(c_.get()) == PQTRANS_IDLE;
  for (int attempt = 0;; ++attempt) {
    PGresult* r = PQexecParams(c_.get(), sql, static_cast<int>(params.size()), nullptr, values.data(), lengths.data(),
                               formats.data(), 1);
    const auto status = r ? PQresultStatus(r) : PGRES_FATAL_ERROR;
    if (status == PGRES_COMMAND_OK || status == PGRES_TUPLES_OK) return Result(r);
    Result owned(r);
    const bool lost = PQstatus(c_.get()) == CONNECTION_BAD;
    if (!(retry_reads_ && outside && lost && attempt == 0 && ensureOpen())) fail(r, sql);
  }
}

void Conn::copyIn(const std::string& copy_sql, const std::string& data) const {
  {
    PGresult* r = PQexec(c_.get(), copy_sql.c_str());
    Result owned(r);
    if (!r || PQresultStatus(r) != PGRES_COPY_IN) fail(r, copy_sql.c_str());
  }
  if (PQputCopyData(c_.get(), data.data(), static_cast<int>(data.size())) != 1 || PQputCopyEnd(c_.get(), nullptr) != 1)
    fail(nullptr, copy_sql.c_str());
  while (PGresult* r = PQgetResult(c_.get())) {
    Result owned(r);
    if (PQresultStatus(r) != PGRES_COMMAND_OK) fail(r, copy_sql.c_str());
  }
}

bool Conn::ensureOpen() const {
  // An idle connection the server ended has a readable socket (its FATAL goodbye, then EOF, perhaps a moment
  // later): reading it updates the status or marks the connection as ending, so the connection is re-established
  // here rather than failing the next statement.
  pollfd pfd{PQsocket(c_.get()), POLLIN, 0};
  for (int reads = 0; reads < 4 && PQstatus(c_.get()) == CONNECTION_OK && !*ending_ &&
                      PQtransactionStatus(c_.get()) == PQTRANS_IDLE && ::poll(&pfd, 1, 0) > 0;
       ++reads)
    PQconsumeInput(c_.get());
  if (PQstatus(c_.get()) == CONNECTION_OK && !*ending_) return true;
  PQreset(c_.get());
  *ending_ = false;
  if (PQstatus(c_.get()) != CONNECTION_OK) return false;
  exec(kServerSide);
  if (!setup_.empty()) exec(setup_);
  return true;
}

Transaction::Transaction(const Conn& conn) : conn_(conn) {
  try {
    conn_.exec("BEGIN");
  } catch (const StorageError& e) {
    // A connection whose end showed only now (a restart): nothing has run yet, so begin on a new one.
    if (e.code() != StorageError::Code::kUnavailable || !conn_.ensureOpen()) throw;
    conn_.exec("BEGIN");
  }
}

Transaction::~Transaction() {
  if (done_) return;
  try {
    conn_.exec("ROLLBACK");
  } catch (const StorageError&) {
    // The connection is gone: the server rolls the transaction back itself.
  }
}

void Transaction::commit() {
  conn_.exec("COMMIT");
  done_ = true;
}

Pool::~Pool() = default;

Pool::Lease Pool::acquire() const {
  {
    std::lock_guard lock(mutex_);
    while (!idle_.empty()) {
      auto conn = std::move(idle_.back());
      idle_.pop_back();
      if (conn->ensureOpen()) return {*this, std::move(conn)};
      idle_.clear();  // one closed by the server: the others most likely too (a restart), so start afresh
    }
  }
  auto conn = std::make_unique<Conn>(url_);
  conn->retryReadsWhenLost();
  return {*this, std::move(conn)};
}

void Pool::release(std::unique_ptr<Conn> conn) const {
  if (PQstatus(conn->get()) != CONNECTION_OK || PQtransactionStatus(conn->get()) != PQTRANS_IDLE) return;
  std::lock_guard lock(mutex_);
  if (idle_.size() < kKept) idle_.push_back(std::move(conn));
}

}  // namespace sglc::storage::pg
