// Open-addressing hash set of packed voxel keys, private to the mapping sources (the octree's
// batched insert and the hashed grid): far cheaper per insert than a node-allocating std set.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace inekf_semantic_mapping {
namespace mapping {

// Open-addressing hash set of packed keys (48 bits, stored +1 so that 0 marks an empty slot).
class FlatKeySet {
 public:
  void reserve(std::size_t expected) {
    std::size_t capacity = 1024;
    while (capacity < 2 * expected) capacity *= 2;
    if (capacity > slots_.size()) rehash(capacity);
  }
  // True when the key was not in the set yet.
  bool insert(std::uint64_t packed) {
    if (2 * (size_ + 1) > slots_.size()) rehash(std::max<std::size_t>(1024, 2 * slots_.size()));
    const std::uint64_t stored = packed + 1;
    std::size_t i = slotOf(stored);
    while (slots_[i] != 0) {
      if (slots_[i] == stored) return false;
      i = (i + 1) & mask_;
    }
    slots_[i] = stored;
    ++size_;
    return true;
  }
  void insertAll(const FlatKeySet& other) {
    other.forEach([this](std::uint64_t packed) { insert(packed); });
  }
  template <typename F>
  void forEach(F&& f) const {
    for (std::uint64_t stored : slots_) {
      if (stored != 0) f(stored - 1);
    }
  }
  std::size_t size() const { return size_; }

 private:
  std::size_t slotOf(std::uint64_t stored) const {
    return static_cast<std::size_t>((stored * 0x9E3779B97F4A7C15ULL) >> shift_);
  }
  void rehash(std::size_t capacity) {
    std::vector<std::uint64_t> old;
    old.swap(slots_);
    slots_.assign(capacity, 0);
    mask_ = capacity - 1;
    shift_ = 64;
    for (std::size_t c = capacity; c > 1; c >>= 1) --shift_;
    size_ = 0;
    for (std::uint64_t stored : old) {
      if (stored != 0) insert(stored - 1);
    }
  }
  std::vector<std::uint64_t> slots_;
  std::size_t mask_ = 0;
  int shift_ = 64;
  std::size_t size_ = 0;
};

}  // namespace mapping
}  // namespace inekf_semantic_mapping
