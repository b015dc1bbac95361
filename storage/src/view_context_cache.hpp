// Stored scans' view contexts (sglc/view_context.hpp), kept apart from their fingerprints: about 1 KB a scan
// against tens of KB for a fingerprint. A narrow query compares its view with up to view_search.max_scans stored
// scans; when the map is larger than the fingerprint cache holds, reading each fingerprint back and recomputing
// its context cost 1.8 s per query on a 10,000-scan map (a 256 MB cache). With the contexts kept here, ranking
// needs neither. Least recently used entries go first; thread-safe. Scan ids are never reused, and deletions
// erase a scan's entries too.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <utility>
#include <vector>

#include "sglc/view_context.hpp"

namespace sglc::storage {

class ViewContextCache {
 public:
  explicit ViewContextCache(std::size_t capacity_bytes) : capacity_(capacity_bytes) {}

  // The context of scan `id` for `config`: kept, else computed from *load() as viewContextOf would (kept from
  // then on); nullptr when load finds no such scan. Throws what load or viewContext throw.
  std::shared_ptr<const ViewContext> get(std::int64_t id, const ViewSearchConfig& config,
                                         const std::function<std::shared_ptr<const Fingerprint>()>& load) {
    const Key key{id, settingsKey(config)};
    std::uint64_t erasures = 0;
    {
      std::lock_guard lock(mutex_);
      if (auto it = map_.find(key); it != map_.end()) {
        lru_.splice(lru_.begin(), lru_, it->second);
        return it->second->value;
      }
      erasures = erasures_;
    }
    const auto fp = load();
    if (!fp) return nullptr;
    // Computed here rather than through the fingerprint's memo (viewContextOf): a cached fingerprint must not
    // grow past the bytes its cache counted when it took it.
    auto made = std::make_shared<const ViewContext>(
        viewContext(fp->background, fp->background_cell, config, fp->labeller_structure));
    put(key, made, erasures);
    return made;
  }

  // Forgets scan id's contexts (for every setting seen).
  void erase(std::int64_t id) {
    std::lock_guard lock(mutex_);
    ++erasures_;
    for (const auto settings : settings_seen_) {
      const auto it = map_.find({id, settings});
      if (it == map_.end()) continue;
      used_ -= it->second->bytes;
      lru_.erase(it->second);
      map_.erase(it);
    }
  }

  std::size_t usedBytes() const {
    std::lock_guard lock(mutex_);
    return used_;
  }

 private:
  struct Key {
    std::int64_t id;
    std::uint64_t settings;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      return std::hash<std::uint64_t>()(static_cast<std::uint64_t>(k.id) * 0x9E3779B97F4A7C15ULL ^ k.settings);
    }
  };
  struct Item {
    Key key;
    std::shared_ptr<const ViewContext> value;
    std::size_t bytes;
  };

  // The settings that shape a context (a scan's own cell size and label source are fixed with its id): the
  // config fields viewContextOf keys its memo by; a field added there must be added here.
  static std::uint64_t settingsKey(const ViewSearchConfig& config) {
    std::uint64_t key = 1469598103934665603ULL;  // FNV-1a
    const auto mix = [&key](const auto& value) {
      const auto* bytes = reinterpret_cast<const unsigned char*>(&value);
      for (std::size_t i = 0; i < sizeof value; ++i) key = (key ^ bytes[i]) * 1099511628211ULL;
    };
    mix(config.rings);
    mix(config.max_range_m);
    return key;
  }

  // Keeps value unless a scan was erased since the caller looked (`erasures` then): the scan it was computed
  // from may be the one deleted, and a deleted scan's context must not come back.
  void put(const Key& key, std::shared_ptr<const ViewContext> value, std::uint64_t erasures) {
    const std::size_t bytes = sizeof(ViewContext) + sizeof(Item) + 64 +
                              (value->building.size() + value->vegetation.size()) * sizeof(ViewContext::Row);
    std::lock_guard lock(mutex_);
    if (bytes > capacity_ || map_.count(key) || erasures != erasures_) return;
    if (std::find(settings_seen_.begin(), settings_seen_.end(), key.settings) == settings_seen_.end())
      settings_seen_.push_back(key.settings);
    lru_.push_front({key, std::move(value), bytes});
    map_[key] = lru_.begin();
    used_ += bytes;
    while (used_ > capacity_) {
      used_ -= lru_.back().bytes;
      map_.erase(lru_.back().key);
      lru_.pop_back();
    }
  }

  mutable std::mutex mutex_;
  std::size_t capacity_;
  std::size_t used_ = 0;
  std::uint64_t erasures_ = 0;  // erase() calls so far
  std::list<Item> lru_;
  std::unordered_map<Key, std::list<Item>::iterator, KeyHash> map_;
  std::vector<std::uint64_t> settings_seen_;  // in practice one: a store's engine has one configuration
};

}  // namespace sglc::storage
