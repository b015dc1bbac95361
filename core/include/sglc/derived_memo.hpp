// Something derived from a fingerprint's stored data, kept with the fingerprint once computed and keyed by the
// settings that shape it, so that other settings never get a stale one. A narrow query compares its view with
// every stored scan's (recomputing each view context cost about 50 us per stored scan), and a query looks up
// its planes once per candidate plane of every hypothesis (the lookup is built once per query, not per scan
// loaded).
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>

namespace sglc {

template <class T>
class DerivedMemo {
 public:
  DerivedMemo() = default;
  // A copy starts empty: the copy's stored data may be changed (Fingerprint::finalize clears it too).
  DerivedMemo(const DerivedMemo& /*other*/) noexcept {}
  DerivedMemo& operator=(const DerivedMemo& other) noexcept {
    if (this != &other) clear();
    return *this;
  }
  ~DerivedMemo() = default;

  void clear() const noexcept {
    const std::lock_guard lock(mutex_);
    value_.reset();
  }
  // The value kept for `key`, or null.
  std::shared_ptr<const T> find(std::uint64_t key) const {
    const std::lock_guard lock(mutex_);
    return key_ == key ? value_ : nullptr;
  }
  // Keeps `value` for `key` (replacing one kept for other settings).
  void keep(std::uint64_t key, std::shared_ptr<const T> value) const {
    const std::lock_guard lock(mutex_);
    key_ = key;
    value_ = std::move(value);
  }

 private:
  mutable std::mutex mutex_;
  mutable std::uint64_t key_ = 0;
  mutable std::shared_ptr<const T> value_;
};

}  // namespace sglc
