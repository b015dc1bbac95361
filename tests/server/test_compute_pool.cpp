// ComputePool: bounded engine threads, first-come-first-served slots, and parallelFor.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <mutex>
#include <numeric>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include "compute_pool.hpp"
#include "rpc_error.hpp"

namespace sglc::server {
namespace {

using namespace std::chrono_literals;
const auto kForever = std::chrono::system_clock::time_point::max();
bool never() { return false; }

void waitUntil(const std::function<bool()>& done) {
  for (int i = 0; i < 5000 && !done(); ++i) std::this_thread::sleep_for(1ms);
  ASSERT_TRUE(done());
}

TEST(ComputePool, ParallelForRunsEveryItemOnce) {
  for (int threads : {1, 2, 4}) {
    ComputePool pool(threads);
    auto slot = pool.acquire(kForever, never);
    for (std::size_t n : {0u, 1u, 7u, 1000u}) {
      std::vector<std::atomic<int>> hits(n);
      pool.parallelFor(n, [&](std::size_t i) { ++hits[i]; });
      for (std::size_t i = 0; i < n; ++i) EXPECT_EQ(hits[i].load(), 1) << "threads " << threads << " item " << i;
    }
  }
}

TEST(ComputePool, IdleHelpersJoinACall) {
  ComputePool pool(3);
  auto slot = pool.acquire(kForever, never);
  std::mutex m;
  std::set<std::thread::id> ids;
  std::atomic<int> inside{0}, most{0};
  pool.parallelFor(24, [&](std::size_t) {
    const int now = ++inside;
    for (int seen = most.load(); now > seen && !most.compare_exchange_weak(seen, now);) {
    }
    std::this_thread::sleep_for(5ms);
    --inside;
    std::lock_guard lock(m);
    ids.insert(std::this_thread::get_id());
  });
  EXPECT_GT(ids.size(), 1u);  // 24 x 5 ms: the two helpers certainly woke up
  EXPECT_LE(most.load(), 3);
  EXPECT_EQ(pool.busy(), 1);  // helpers gave their slots back
}

TEST(ComputePool, FirstExceptionReachesTheCaller) {
  for (int threads : {1, 2}) {
    ComputePool pool(threads);
    auto slot = pool.acquire(kForever, never);
    std::atomic<int> ran{0};
    try {
      pool.parallelFor(100, [&](std::size_t i) {
        ++ran;
        if (i == 3) throw std::runtime_error("item 3");
      });
      FAIL() << "no exception";
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), "item 3");
    }
    // Alone, the caller takes items in order and stops at the failure; with a helper, items may finish
    // before the failure is seen, so only the rethrow and the slot count are certain.
    if (threads == 1) {
      EXPECT_EQ(ran.load(), 4);
    }
    EXPECT_EQ(pool.busy(), 1);
  }
}

TEST(ComputePool, NeverMoreThanItsThreadsAtWork) {
  ComputePool pool(2);
  std::atomic<int> inside{0}, most{0};
  std::vector<std::thread> calls;
  for (int c = 0; c < 8; ++c)
    calls.emplace_back([&] {
      auto slot = pool.acquire(kForever, never);
      pool.parallelFor(6, [&](std::size_t) {
        const int now = ++inside;
        for (int seen = most.load(); now > seen && !most.compare_exchange_weak(seen, now);) {
        }
        std::this_thread::sleep_for(2ms);
        --inside;
      });
    });
  for (auto& t : calls) t.join();
  EXPECT_LE(most.load(), 2);
  EXPECT_EQ(pool.busy(), 0);
  EXPECT_EQ(pool.waiting(), 0);
}

TEST(ComputePool, WaitingCallsAreServedInArrivalOrder) {
  ComputePool pool(1);
  auto first = pool.acquire(kForever, never);
  std::mutex m;
  std::vector<int> order;
  std::vector<std::thread> calls;
  for (int c = 0; c < 5; ++c) {
    calls.emplace_back([&, c] {
      auto slot = pool.acquire(kForever, never);
      std::lock_guard lock(m);
      order.push_back(c);
    });
    waitUntil([&] { return pool.waiting() == c + 1; });  // queued before the next one arrives
  }
  first.release();
  for (auto& t : calls) t.join();
  EXPECT_EQ(order, (std::vector<int>{0, 1, 2, 3, 4}));
}

TEST(ComputePool, DeadlineAndCancellationEndTheWait) {
  ComputePool pool(1);
  auto held = pool.acquire(kForever, never);
  const auto t0 = std::chrono::steady_clock::now();
  try {
    pool.acquire(std::chrono::system_clock::now() + 60ms, never);
    FAIL() << "acquired a slot that is held";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::DEADLINE_EXCEEDED);
    EXPECT_NE(std::string(e.what()).find("server busy"), std::string::npos) << e.what();
  }
  EXPECT_GE(std::chrono::steady_clock::now() - t0, 60ms);
  std::atomic<bool> cancel{false};
  std::thread canceller([&] {
    std::this_thread::sleep_for(30ms);
    cancel = true;
  });
  try {
    pool.acquire(kForever, [&] { return cancel.load(); });
    FAIL() << "acquired a slot that is held";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::CANCELLED);
  }
  canceller.join();
  EXPECT_EQ(pool.waiting(), 0);  // the abandoned waits left the line
  held.release();
  auto next = pool.acquire(std::chrono::system_clock::now() + 1s, never);  // and did not take the slot
  EXPECT_EQ(pool.busy(), 1);
}

}  // namespace
}  // namespace sglc::server
