// ChunkTable<V>: a value per chunk, kept block by block: per 4^3-chunk
// block a 64-bit map of the chunks that have a value and their values
// side by side, in chunk order.
//
// A replica holds a value for every chunk of its view (thousands; most of
// them mips), many to a block. In a flat hash map (Vec3iMap) each cost a
// slot with its key, at a load between 3/8 and 3/4, so a bot's table of
// chunks was a fifth of its memory; here a value costs its own bytes and
// a block's key, map and vector (about 50 bytes) are shared by up to 64
// of them. A lookup is a block lookup and a count of bits; an insert or
// erase moves the values after it in its block (at most 63: blocks of
// 8^3 chunks made a replica's inserts cost more than the rest of them).
//
// Inserting a value may move every value of its block (references to
// them are then invalid); erasing moves those after it. Iteration visits
// block by block, chunks in order within each.
// Thread-safety: none.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/voxel/vec3_map.h"

namespace terrane {

template <class V>
class ChunkTable {
  static constexpr int kSide = 4;  // kSide^3 = 64 chunks: one word of bits

  struct Block {
    std::uint64_t has = 0;
    std::vector<V> values;  // one per set bit, in bit order

    bool test(int i) const { return (has >> i & 1) != 0; }
    // Values before slot i.
    std::size_t rank(int i) const {
      return static_cast<std::size_t>(std::popcount(has & ((std::uint64_t{1} << i) - 1)));
    }
  };

  static Vec3i block_of(Vec3i cp) { return floor_div(cp, kSide); }
  static int slot_of(Vec3i cp) {
    const Vec3i l = floor_mod(cp, kSide);
    return (l.y * kSide + l.z) * kSide + l.x;
  }

 public:
  // The value of chunk cp, or null.
  V* find(Vec3i cp) {
    auto it = blocks_.find(block_of(cp));
    if (it == blocks_.end()) return nullptr;
    const int i = slot_of(cp);
    return it->second.test(i) ? &it->second.values[it->second.rank(i)] : nullptr;
  }
  const V* find(Vec3i cp) const { return const_cast<ChunkTable*>(this)->find(cp); }

  // The value of chunk cp, a value-initialised one inserted if it had none.
  V& operator[](Vec3i cp) {
    Block& r = blocks_[block_of(cp)];
    const int i = slot_of(cp);
    const std::size_t at = r.rank(i);
    if (r.test(i)) return r.values[at];
    r.has |= std::uint64_t{1} << i;
    ++size_;
    // Grown by a quarter, not doubled: a block's values stay within an
    // eighth or so of their own bytes.
    if (r.values.size() == r.values.capacity()) r.values.reserve(r.values.size() + r.values.size() / 4 + 2);
    return *r.values.emplace(r.values.begin() + static_cast<std::ptrdiff_t>(at));
  }

  // Removes chunk cp's value; false if it had none.
  bool erase(Vec3i cp) {
    auto it = blocks_.find(block_of(cp));
    if (it == blocks_.end()) return false;
    Block& r = it->second;
    const int i = slot_of(cp);
    if (!r.test(i)) return false;
    r.values.erase(r.values.begin() + static_cast<std::ptrdiff_t>(r.rank(i)));
    r.has &= ~(std::uint64_t{1} << i);
    --size_;
    if (r.values.empty()) blocks_.erase(it);
    return true;
  }

  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }

  // f(Vec3i chunk_pos, V& value) for every value.
  template <class F>
  void for_each(F&& f) {
    for (auto& [block, r] : blocks_) visit(block, r, f);
  }
  template <class F>
  void for_each(F&& f) const {
    for (const auto& [block, r] : blocks_) visit(block, r, f);
  }

  // Heap bytes: the blocks' table and their values (with the vectors'
  // spare capacity).
  std::size_t heap_bytes() const {
    std::size_t n = blocks_.table_bytes();
    for (const auto& [block, r] : blocks_) n += r.values.capacity() * sizeof(V);
    return n;
  }

 private:
  template <class R, class F>
  static void visit(Vec3i block, R& r, F& f) {
    std::size_t k = 0;
    for (std::uint64_t bits = r.has; bits != 0; bits &= bits - 1) {
      const int i = std::countr_zero(bits);
      const Vec3i l{i % kSide, i / (kSide * kSide), i / kSide % kSide};
      f(block * kSide + l, r.values[k++]);
    }
  }

  Vec3iMap<Block> blocks_;
  std::size_t size_ = 0;
};

}  // namespace terrane
