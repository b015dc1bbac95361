// A fingerprint's view context (view_context.hpp), kept with the fingerprint once computed: a narrow query
// compares its view with every stored scan's, and recomputing each of those on every query cost about 50 us per
// stored scan. Keyed by the settings that shape the context, so that other settings never get a stale one.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>

namespace sglc {

struct ViewContext;

class ViewContextMemo {
 public:
  ViewContextMemo() = default;
  // A copy starts empty: the copy's stored data may be changed (Fingerprint::finalize clears it too).
  ViewContextMemo(const ViewContextMemo& /*other*/) noexcept {}
  ViewContextMemo& operator=(const ViewContextMemo& other) noexcept {
    if (this != &other) clear();
    return *this;
  }
  ~ViewContextMemo() = default;

  void clear() const noexcept {
    const std::lock_guard lock(mutex_);
    value_.reset();
  }
  // The context kept for `key`, or null.
  std::shared_ptr<const ViewContext> find(std::uint64_t key) const {
    const std::lock_guard lock(mutex_);
    return key_ == key ? value_ : nullptr;
  }
  // Keeps `value` for `key` (replacing one kept for other settings).
  void keep(std::uint64_t key, std::shared_ptr<const ViewContext> value) const {
    const std::lock_guard lock(mutex_);
    key_ = key;
    value_ = std::move(value);
  }

 private:
  mutable std::mutex mutex_;
  mutable std::uint64_t key_ = 0;
  mutable std::shared_ptr<const ViewContext> value_;
};

}  // namespace sglc
