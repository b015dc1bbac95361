// A small open-addressing hash map from packed integer cell coordinates to an int32 value.
// The hot loops (clustering, voxel statistics, plane lookup) use it instead of std::unordered_map.
#pragma once

#include <cstdint>
#include <vector>

namespace sglc {

// Packs three signed cell coordinates (each within +-2^20) into one key.
inline std::uint64_t packCell(int x, int y, int z) {
  constexpr std::uint64_t kOffset = 1u << 20;
  constexpr std::uint64_t kMask = (1u << 21) - 1;
  return ((static_cast<std::uint64_t>(x + kOffset) & kMask) << 42) |
         ((static_cast<std::uint64_t>(y + kOffset) & kMask) << 21) | (static_cast<std::uint64_t>(z + kOffset) & kMask);
}

class VoxelMap {
 public:
  explicit VoxelMap(std::size_t expected = 64) { reset(expected); }

  void reset(std::size_t expected) {
    std::size_t cap = 16;
    while (cap < expected * 2) cap <<= 1;
    keys_.assign(cap, kEmpty);
    values_.assign(cap, -1);
    size_ = 0;
  }

  // Returns the value slot for key, inserting `fresh` when the key is new.
  std::int32_t& findOrInsert(std::uint64_t key, std::int32_t fresh, bool* inserted = nullptr) {
    if ((size_ + 1) * 2 > keys_.size()) grow();
    std::size_t i = slot(key);
    while (keys_[i] != kEmpty && keys_[i] != key) i = (i + 1) & (keys_.size() - 1);
    if (keys_[i] == kEmpty) {
      keys_[i] = key;
      values_[i] = fresh;
      ++size_;
      if (inserted) *inserted = true;
    } else if (inserted) {
      *inserted = false;
    }
    return values_[i];
  }

  // -1 when absent.
  std::int32_t find(std::uint64_t key) const {
    std::size_t i = slot(key);
    while (keys_[i] != kEmpty) {
      if (keys_[i] == key) return values_[i];
      i = (i + 1) & (keys_.size() - 1);
    }
    return -1;
  }

  std::size_t size() const { return size_; }

 private:
  static constexpr std::uint64_t kEmpty = ~0ull;

  std::size_t slot(std::uint64_t key) const {
    key ^= key >> 29;
    key *= 0xbf58476d1ce4e5b9ull;
    key ^= key >> 32;
    return static_cast<std::size_t>(key) & (keys_.size() - 1);
  }

  void grow() {
    std::vector<std::uint64_t> keys;
    std::vector<std::int32_t> values;
    keys.swap(keys_);
    values.swap(values_);
    keys_.assign(keys.size() * 2, kEmpty);
    values_.assign(keys.size() * 2, -1);
    size_ = 0;
    for (std::size_t i = 0; i < keys.size(); ++i)
      if (keys[i] != kEmpty) findOrInsert(keys[i], values[i]);
  }

  std::vector<std::uint64_t> keys_;
  std::vector<std::int32_t> values_;
  std::size_t size_ = 0;
};

}  // namespace sglc
