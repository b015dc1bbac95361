// The FAISS index of one map, with the per-entry metadata that search filters need.
// Internal FAISS labels are positions in `entries`; deleted entries become tombstones that every search
// excludes (the next open rebuilds without them). Not thread-safe by itself: MapStore locks around it.
#pragma once

#include <faiss/Index.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <unordered_set>
#include <vector>

#include "sglc/storage/map_store.hpp"

namespace sglc::storage {

struct IndexEntry {
  std::int64_t scan_id = 0;
  std::int64_t robot_id = 0;
  std::int64_t session_id = 0;
  std::int64_t seq = 0;
  double stamp = 0;  // NaN when unknown
  bool deleted = false;
};

// What a search may return, resolved to database ids.
struct SearchFilter {
  std::unordered_set<std::int64_t> robots;  // empty: any
  std::unordered_set<std::int64_t> exclude_robots;
  std::unordered_set<std::int64_t> sessions;  // empty: any
  std::unordered_set<std::int64_t> exclude_scans;
  std::int64_t self_robot = -1;
  std::int64_t self_session = -1;
  std::int64_t self_seq = 0;
  std::int64_t exclude_recent = 0;
  double self_stamp = 0;  // NaN: no time exclusion
  double exclude_seconds = 0;
  bool any() const;
  bool accepts(const IndexEntry& e) const;
};

class DescriptorIndex {
 public:
  DescriptorIndex(int dim, const IndexOptions& options);
  ~DescriptorIndex();

  int dim() const { return dim_; }
  std::int64_t live() const { return live_; }
  bool approximate() const { return ivf_; }

  // Replaces the content (used on open). IVF options take effect here when there are enough entries.
  void build(std::vector<IndexEntry> entries, const std::vector<float>& vectors);
  void add(const IndexEntry& entry, const float* vector);
  // Marks entries deleted; returns how many were live.
  std::int64_t remove(const std::unordered_set<std::int64_t>& scan_ids);
  // The scan ids of the live entries `keep` accepts.
  template <typename Pred>
  std::unordered_set<std::int64_t> liveIds(Pred keep) const {
    std::unordered_set<std::int64_t> out;
    for (const auto& e : entries_)
      if (!e.deleted && keep(e)) out.insert(e.scan_id);
    return out;
  }

  // Nearest k live entries accepted by the filter, sorted by (distance, scan id).
  std::vector<SearchHit> search(const float* query, int k, const SearchFilter& filter) const;

  // Snapshot: our header + entries + the FAISS index. load() returns false when the file is absent, of another
  // generation, or unreadable (the caller then rebuilds from the database).
  void save(const std::string& path, std::int64_t generation) const;
  bool load(const std::string& path, std::int64_t generation);
  bool hasTombstones() const { return live_ != static_cast<std::int64_t>(entries_.size()); }

 private:
  std::vector<SearchHit> searchExact(const float* query, int k, const SearchFilter& filter) const;
  void computeNorms();

  int dim_;
  IndexOptions options_;
  bool ivf_ = false;
  std::unique_ptr<faiss::Index> quantizer_;
  std::unique_ptr<faiss::Index> index_;
  std::vector<IndexEntry> entries_;
  std::vector<float> norms_;  // squared norms of the flat index's vectors (exact search only)
  std::int64_t live_ = 0;
};

}  // namespace sglc::storage
