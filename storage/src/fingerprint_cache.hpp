// A thread-safe least-recently-used cache of decoded fingerprints, bounded in bytes.
#pragma once

#include <algorithm>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>

#include "sglc/fingerprint.hpp"
#include "sglc/storage/map_store.hpp"
#include "view_context_cache.hpp"

namespace sglc::storage {

// Approximate heap footprint of a decoded fingerprint.
std::size_t memoryBytes(const Fingerprint& fp);

class FingerprintCache {
 public:
  // The view contexts get an eighth of the budget on top, at least 4 MB (about 3,500 scans'; 27,000 at the
  // default 256 MB); nothing when the budget is 0.
  explicit FingerprintCache(std::size_t capacity_bytes)
      : views(capacity_bytes == 0 ? 0 : std::max<std::size_t>(capacity_bytes / 8, std::size_t{4} << 20)),
        capacity_(capacity_bytes) {}

  // Stored scans' view contexts, kept when their fingerprints are evicted; erase() forgets both.
  ViewContextCache views;

  std::shared_ptr<const Fingerprint> get(std::int64_t id) {
    std::lock_guard lock(mutex_);
    auto it = map_.find(id);
    if (it == map_.end()) {
      ++misses_;
      return nullptr;
    }
    ++hits_;
    lru_.splice(lru_.begin(), lru_, it->second);
    return it->second->value;
  }

  void put(std::int64_t id, std::shared_ptr<const Fingerprint> fp) {
    const std::size_t bytes = memoryBytes(*fp);
    std::lock_guard lock(mutex_);
    if (bytes > capacity_) return;
    if (auto it = map_.find(id); it != map_.end()) {
      used_ -= it->second->bytes;
      lru_.erase(it->second);
      map_.erase(it);
    }
    lru_.push_front({id, std::move(fp), bytes});
    map_[id] = lru_.begin();
    used_ += bytes;
    while (used_ > capacity_) {
      used_ -= lru_.back().bytes;
      map_.erase(lru_.back().id);
      lru_.pop_back();
    }
  }

  void erase(std::int64_t id) {
    views.erase(id);
    std::lock_guard lock(mutex_);
    if (auto it = map_.find(id); it != map_.end()) {
      used_ -= it->second->bytes;
      lru_.erase(it->second);
      map_.erase(it);
    }
  }

  // Its figures in a store's statistics.
  void report(Stats& s) const {
    std::lock_guard lock(mutex_);
    s.cache_mb = static_cast<double>(used_ + views.usedBytes()) / (1024.0 * 1024.0);  // view contexts included
    s.cache_hits = hits_;
    s.cache_misses = misses_;
  }

 private:
  struct Item {
    std::int64_t id;
    std::shared_ptr<const Fingerprint> value;
    std::size_t bytes;
  };
  mutable std::mutex mutex_;
  std::size_t capacity_;
  std::size_t used_ = 0;
  std::int64_t hits_ = 0, misses_ = 0;
  std::list<Item> lru_;
  std::unordered_map<std::int64_t, std::list<Item>::iterator> map_;
};

inline std::size_t memoryBytes(const Fingerprint& fp) {
  return sizeof(Fingerprint) + fp.nodes.size() * sizeof(Node) + fp.instance_offsets.size() * 4 +
         fp.instance_points.size() * sizeof(Vec3f) + fp.background.size() * sizeof(BevCell) +
         fp.planes.size() * (sizeof(Plane) + 24) + fp.descriptor.size() * 4 +
         static_cast<std::size_t>(fp.node_descriptors.size()) * 4;
}

}  // namespace sglc::storage
