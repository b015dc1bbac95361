// The server's bounds on memory in flight and on open streams.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "call.hpp"
#include "memory_budget.hpp"
#include "rpc_error.hpp"
#include "stream_registry.hpp"

namespace sglc::server {
namespace {

using std::chrono::system_clock;
const auto kNever = system_clock::time_point::max();
const auto kNotCancelled = [] { return false; };

TEST(MemoryBudget, CallsBeyondTheBudgetWaitUntilMemoryIsReturned) {
  MemoryBudget budget(100);
  auto a = budget.acquire(60, kNever, kNotCancelled);
  std::atomic<bool> got{false};
  std::thread waiter([&] {
    auto b = budget.acquire(60, kNever, kNotCancelled);
    got = true;
    EXPECT_LE(budget.inUse(), 100u);
  });
  // The waiter cannot get its 60 while 60 of 100 are taken; it gets them once they are returned.
  for (int i = 0; i < 50 && budget.inUse() != 60; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  EXPECT_FALSE(got);
  a.release();
  waiter.join();
  EXPECT_TRUE(got);
  EXPECT_EQ(budget.inUse(), 0u);
  EXPECT_LE(budget.peak(), 100u);
}

TEST(MemoryBudget, AScanLargerThanTheBudgetIsAdmittedAlone) {
  MemoryBudget budget(100);
  {
    auto big = budget.acquire(500, kNever, kNotCancelled);
    EXPECT_EQ(budget.inUse(), 500u);
  }
  EXPECT_EQ(budget.inUse(), 0u);
  MemoryBudget::Lease growing = budget.acquire(80, kNever, kNotCancelled);
  budget.grow(growing, 80, kNever, kNotCancelled);  // alone in flight: may grow past the budget
  EXPECT_EQ(growing.bytes(), 160u);
  // But nobody else gets in while it is over (a short maximum wait ends the attempt) ...
  EXPECT_THROW(budget.acquire(1, kNever, kNotCancelled, std::chrono::milliseconds(20)), RpcError);
  // ... until it returns what it reserved beyond its real size (a chunked upload, once complete).
  budget.shrink(growing, 60);
  EXPECT_EQ(growing.bytes(), 60u);
  EXPECT_EQ(budget.inUse(), 60u);
  EXPECT_EQ(budget.acquire(40, kNever, kNotCancelled, std::chrono::milliseconds(20)).bytes(), 40u);
}

TEST(MemoryBudget, WaitingEndsWithTheCallsDeadlineCancellationOrTheMaximumWait) {
  MemoryBudget budget(100);
  auto held = budget.acquire(100, kNever, kNotCancelled);
  auto code = [&](system_clock::time_point deadline, std::function<bool()> cancelled, std::chrono::milliseconds wait) {
    try {
      budget.acquire(10, deadline, cancelled, wait);
      return grpc::StatusCode::OK;
    } catch (const RpcError& e) {
      EXPECT_FALSE(std::string(e.what()).empty());
      return e.code();
    }
  };
  EXPECT_EQ(code(system_clock::now() + std::chrono::milliseconds(30), kNotCancelled, std::chrono::seconds(30)),
            grpc::StatusCode::DEADLINE_EXCEEDED);
  EXPECT_EQ(code(
                kNever, [] { return true; }, std::chrono::seconds(30)),
            grpc::StatusCode::CANCELLED);
  EXPECT_EQ(code(kNever, kNotCancelled, std::chrono::milliseconds(30)), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(budget.inUse(), 100u);  // failed waits took nothing
  held.release();
  EXPECT_EQ(code(kNever, kNotCancelled, std::chrono::milliseconds(30)), grpc::StatusCode::OK);
}

struct FakeStream : RegisteredStream {
  std::optional<std::chrono::steady_clock::time_point> since;
  std::atomic<int> closed{0};
  grpc::Status status;
  std::optional<std::chrono::steady_clock::time_point> idleSince() override { return since; }
  void close(const grpc::Status& s) override {
    status = s;
    ++closed;
  }
};

TEST(StreamRegistry, LimitsPerClientAndInTotal) {
  StreamRegistry registry({.max_per_client = 2, .max_total = 3, .idle_timeout = std::chrono::hours(1)}, nullptr);
  std::vector<FakeStream*> streams;
  for (int i = 0; i < 6; ++i) streams.push_back(new FakeStream);
  auto refused = [&](StreamRegistry::Kind kind, const std::string& client, FakeStream* s) {
    try {
      registry.admit(kind, client, s);
      return std::string();
    } catch (const RpcError& e) {
      EXPECT_EQ(e.code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
      return std::string(e.what());
    }
  };
  const auto a1 = registry.admit(StreamRegistry::Kind::kIngest, "a", streams[0]);
  registry.admit(StreamRegistry::Kind::kIngest, "a", streams[1]);
  EXPECT_NE(refused(StreamRegistry::Kind::kIngest, "a", streams[2]).find("streams"), std::string::npos);
  EXPECT_EQ(refused(StreamRegistry::Kind::kWatch, "a", streams[2]), "");   // another kind has its own count
  EXPECT_EQ(refused(StreamRegistry::Kind::kIngest, "b", streams[3]), "");  // another client is not affected
  EXPECT_NE(refused(StreamRegistry::Kind::kIngest, "c", streams[4]).find("server"), std::string::npos);  // total
  registry.leave(a1);
  EXPECT_EQ(refused(StreamRegistry::Kind::kIngest, "a", streams[5]), "");
  EXPECT_EQ(registry.open(StreamRegistry::Kind::kIngest), 3);
  registry.closeAll(grpc::Status(grpc::StatusCode::UNAVAILABLE, "bye"));
  for (int i : {1, 2, 3, 5}) EXPECT_EQ(streams[static_cast<std::size_t>(i)]->closed, 1) << i;
  EXPECT_EQ(streams[0]->closed, 0);  // it had left
  EXPECT_EQ(streams[1]->status.error_code(), grpc::StatusCode::UNAVAILABLE);
  try {
    registry.admit(StreamRegistry::Kind::kIngest, "z", streams[4]);
    ADD_FAILURE() << "admitted after closeAll";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::UNAVAILABLE);
  }
  for (auto* s : streams) s->unref();
}

TEST(StreamRegistry, IdleIngestStreamsAreClosedWatchersAndBusyStreamsAreNot) {
  std::atomic<int> housekeeping{0};
  StreamRegistry registry({.max_per_client = 10, .max_total = 10, .idle_timeout = std::chrono::milliseconds(100)},
                          [&] { ++housekeeping; });
  auto* idle = new FakeStream;
  auto* busy = new FakeStream;
  auto* watcher = new FakeStream;
  idle->since = std::chrono::steady_clock::now();
  watcher->since = std::chrono::steady_clock::now();
  registry.admit(StreamRegistry::Kind::kIngest, "a", idle);
  registry.admit(StreamRegistry::Kind::kIngest, "a", busy);
  registry.admit(StreamRegistry::Kind::kWatch, "a", watcher);
  for (int i = 0; i < 1000 && (idle->closed == 0 || housekeeping < 2); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_GE(idle->closed, 1);
  EXPECT_EQ(idle->status.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_NE(idle->status.error_message().find("idle"), std::string::npos);
  EXPECT_EQ(busy->closed, 0);
  EXPECT_EQ(watcher->closed, 0);
  registry.closeAll(grpc::Status::OK);
  for (auto* s : {idle, busy, watcher}) s->unref();
}

// Messages built from client text are bounded and one line, whatever the handler put in them.
TEST(StatusOf, MessagesAreCutAndControlCharactersEscaped) {
  std::string detail;
  const auto of = [&](const std::string& text) {
    return statusOf(std::make_exception_ptr(RpcError(grpc::StatusCode::NOT_FOUND, text)), &detail);
  };
  const grpc::Status cut = of("no robot '" + std::string(100000, 'x') + "'");
  EXPECT_EQ(cut.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_LE(cut.error_message().size(), kMaxStatusMessageBytes + 32);
  EXPECT_NE(cut.error_message().find("(100011 bytes)"), std::string::npos) << cut.error_message();
  EXPECT_EQ(of("a\nb\tc").error_message(), "a\\x0ab\\x09c");
  // A cut never splits a UTF-8 character: 2-byte characters up to the limit leave whole characters only.
  std::string accents;
  for (int i = 0; i < 600; ++i) accents += "\xc3\xa9";
  const std::string m = of(accents).error_message();
  const std::string kept = m.substr(0, m.find("..."));
  EXPECT_EQ(kept.size() % 2, 0u);
  EXPECT_EQ(static_cast<unsigned char>(kept[0]), 0xc3);
}

}  // namespace
}  // namespace sglc::server
