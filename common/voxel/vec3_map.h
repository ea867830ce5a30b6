// Vec3iMap<V>: a hash map from chunk (or unit) positions to V, stored flat:
// open addressing with linear probing in one array, so a lookup reads one
// or two neighbouring slots instead of following a node pointer. The
// server keeps one per client for what it holds (tens of thousands of
// chunks each, looked up on every grant, move, change and hash) and the
// world's interest and residency per chunk; with node maps those lookups
// were the server's largest cost at 1,000 clients.
//
// The interface is the part of std::unordered_map these maps use, with one
// difference: inserting a key that is not there yet may move every element
// (references and iterators are then invalid). Erasing never moves one, so
// erase(it) while iterating is safe. Erased slots become tombstones, dropped
// when the table is rebuilt (at 3/4 full, counting tombstones). Iterators
// point at their map: they do not follow it through a move or swap. Values
// must move without throwing (a rebuild moves them all); the map is not
// copyable.
// Thread-safety: none.
#pragma once

#include <cstddef>
#include <cstdint>
#include <iterator>
#include <memory>
#include <new>
#include <stdexcept>
#include <tuple>
#include <type_traits>
#include <utility>

#include "common/voxel/vec3.h"

namespace terrane {

template <class V>
class Vec3iMap {
  static_assert(std::is_nothrow_move_constructible_v<V>, "a rebuild moves every value and must not fail halfway");

 public:
  using value_type = std::pair<const Vec3i, V>;
  using element = value_type;

  template <bool Const>
  class Iter {
   public:
    using Map = std::conditional_t<Const, const Vec3iMap, Vec3iMap>;
    using Ref = std::conditional_t<Const, const element&, element&>;
    using Ptr = std::conditional_t<Const, const element*, element*>;
    using iterator_category = std::forward_iterator_tag;
    using difference_type = std::ptrdiff_t;
    using value_type = element;
    using pointer = Ptr;
    using reference = Ref;
    Iter() = default;
    Iter(Map* m, std::size_t i) : m_(m), i_(i) {}
    // An iterator converts to a const_iterator, implicitly as std's do.
    template <bool C = Const, std::enable_if_t<C, int> = 0>
    Iter(const Iter<false>& o) : m_(o.m_), i_(o.i_) {}  // NOLINT: implicit
    Ref operator*() const { return *m_->slot(i_); }
    Ptr operator->() const { return m_->slot(i_); }
    Iter& operator++() {
      i_ = m_->next_full(i_ + 1);
      return *this;
    }
    Iter operator++(int) {
      Iter old = *this;
      ++*this;
      return old;
    }
    friend bool operator==(const Iter& a, const Iter& b) { return a.i_ == b.i_; }

   private:
    friend class Vec3iMap;
    template <bool>
    friend class Iter;
    Map* m_ = nullptr;
    std::size_t i_ = 0;
  };
  using iterator = Iter<false>;
  using const_iterator = Iter<true>;

  Vec3iMap() = default;
  ~Vec3iMap() { destroy_all(); }
  Vec3iMap(Vec3iMap&& o) noexcept { swap(o); }
  Vec3iMap& operator=(Vec3iMap&& o) noexcept {
    Vec3iMap tmp(std::move(o));
    swap(tmp);
    return *this;
  }
  Vec3iMap(const Vec3iMap&) = delete;
  Vec3iMap& operator=(const Vec3iMap&) = delete;

  std::size_t size() const { return size_; }
  // The table's own memory (what the values own besides is theirs).
  std::size_t table_bytes() const { return capacity() * (sizeof(Slot) + 1); }
  bool empty() const { return size_ == 0; }

  iterator begin() { return iterator(this, next_full(0)); }
  iterator end() { return iterator(this, capacity()); }
  const_iterator begin() const { return const_iterator(this, next_full(0)); }
  const_iterator end() const { return const_iterator(this, capacity()); }

  // A scan in parts: the table has slot_count() slots, and
  // for_each_in_slots(from, to, f) calls f(key, value) for the elements in
  // slots [from, to) (to clipped to slot_count()). Parts that cover 0 to
  // slot_count() visit every element present throughout, once each, as long
  // as no insert rebuilt the table meanwhile (slot_count() changed); after a
  // rebuild some are missed or seen twice. f must not insert or erase.
  std::size_t slot_count() const { return capacity(); }
  template <class F>
  void for_each_in_slots(std::size_t from, std::size_t to, F&& f) const {
    to = to < capacity() ? to : capacity();
    for (std::size_t i = from; i < to; ++i)
      if (state_[i] == kFull) f(slot(i)->first, std::as_const(slot(i)->second));
  }

  iterator find(Vec3i k) { return iterator(this, find_index(k)); }
  const_iterator find(Vec3i k) const { return const_iterator(this, find_index(k)); }
  std::size_t count(Vec3i k) const { return find_index(k) != capacity() ? 1 : 0; }

  V& at(Vec3i k) {
    const std::size_t i = find_index(k);
    if (i == capacity()) throw std::out_of_range("Vec3iMap::at");
    return slot(i)->second;
  }
  const V& at(Vec3i k) const {
    const std::size_t i = find_index(k);
    if (i == capacity()) throw std::out_of_range("Vec3iMap::at");
    return slot(i)->second;
  }
  V& operator[](Vec3i k) { return try_emplace(k).first->second; }

  template <class... Args>
  std::pair<iterator, bool> try_emplace(Vec3i k, Args&&... args) {
    std::size_t free_slot = capacity();  // where the probe ended
    if (capacity() != 0) {
      std::size_t i = home(k), tomb = capacity();
      for (;; i = (i + 1) & mask_) {
        if (state_[i] == kEmpty) break;
        if (state_[i] == kTomb) {
          if (tomb == capacity()) tomb = i;
        } else if (slot(i)->first == k) {
          return {iterator(this, i), false};
        }
      }
      if (tomb != capacity()) return {iterator(this, construct(tomb, k, std::forward<Args>(args)...)), true};
      free_slot = i;
    }
    if ((used_ + 1) * 4 > capacity() * 3) {
      rebuild(size_ + 1);
      free_slot = home(k);
      while (state_[free_slot] == kFull) free_slot = (free_slot + 1) & mask_;  // a rebuilt table has no tombstones
    }
    ++used_;
    return {iterator(this, construct(free_slot, k, std::forward<Args>(args)...)), true};
  }
  template <class... Args>
  std::pair<iterator, bool> emplace(Vec3i k, Args&&... args) {
    return try_emplace(k, std::forward<Args>(args)...);
  }
  template <class M>
  std::pair<iterator, bool> insert_or_assign(Vec3i k, M&& v) {
    auto r = try_emplace(k, std::forward<M>(v));
    if (!r.second) r.first->second = std::forward<M>(v);
    return r;
  }

  std::size_t erase(Vec3i k) {
    const std::size_t i = find_index(k);
    if (i == capacity()) return 0;
    destroy(i);
    return 1;
  }
  iterator erase(const_iterator it) {
    destroy(it.i_);
    return iterator(this, next_full(it.i_ + 1));
  }
  iterator erase(iterator it) { return erase(const_iterator(it)); }

  void clear() {
    destroy_all();
    for (std::size_t i = 0; i < capacity(); ++i) state_[i] = kEmpty;
    used_ = 0;
  }
  void swap(Vec3iMap& o) noexcept {
    std::swap(slots_, o.slots_);
    std::swap(state_, o.state_);
    std::swap(mask_, o.mask_);
    std::swap(size_, o.size_);
    std::swap(used_, o.used_);
  }

 private:
  static constexpr std::uint8_t kEmpty = 0, kFull = 1, kTomb = 2;
  struct Slot {
    alignas(value_type) unsigned char bytes[sizeof(value_type)];
  };

  std::size_t capacity() const { return slots_ ? mask_ + 1 : 0; }
  std::size_t home(Vec3i k) const { return Vec3iHash{}(k) & mask_; }
  value_type* slot(std::size_t i) const { return std::launder(reinterpret_cast<value_type*>(slots_[i].bytes)); }
  std::size_t next_full(std::size_t i) const {
    while (i < capacity() && state_[i] != kFull) ++i;
    return i;
  }
  std::size_t find_index(Vec3i k) const {
    if (capacity() == 0) return 0;
    for (std::size_t i = home(k);; i = (i + 1) & mask_) {
      if (state_[i] == kEmpty) return capacity();
      if (state_[i] == kFull && slot(i)->first == k) return i;
    }
  }
  template <class... Args>
  std::size_t construct(std::size_t i, Vec3i k, Args&&... args) {
    new (slots_[i].bytes) value_type(std::piecewise_construct, std::forward_as_tuple(k),
                                     std::forward_as_tuple(std::forward<Args>(args)...));
    state_[i] = kFull;
    ++size_;
    return i;
  }
  void destroy(std::size_t i) {
    slot(i)->~value_type();
    state_[i] = kTomb;
    --size_;
  }
  void destroy_all() {
    for (std::size_t i = 0; i < capacity(); ++i)
      if (state_[i] == kFull) slot(i)->~value_type();
    size_ = 0;
  }
  // A table for n elements at most half full, without tombstones.
  void rebuild(std::size_t n) {
    std::size_t cap = 16;
    while (cap < n * 2) cap *= 2;
    auto slots = std::make_unique_for_overwrite<Slot[]>(cap);
    auto state = std::make_unique<std::uint8_t[]>(cap);  // zeroed: kEmpty
    const std::size_t mask = cap - 1;
    for (std::size_t i = 0; i < capacity(); ++i) {
      if (state_[i] != kFull) continue;
      value_type* v = slot(i);
      std::size_t j = Vec3iHash{}(v->first) & mask;
      while (state[j] == kFull) j = (j + 1) & mask;
      new (slots[j].bytes) value_type(std::piecewise_construct, std::forward_as_tuple(v->first),
                                      std::forward_as_tuple(std::move(v->second)));
      state[j] = kFull;
      v->~value_type();
    }
    slots_ = std::move(slots);
    state_ = std::move(state);
    mask_ = mask;
    used_ = size_;
  }

  std::unique_ptr<Slot[]> slots_;
  std::unique_ptr<std::uint8_t[]> state_;
  std::size_t mask_ = 0;
  std::size_t size_ = 0;
  std::size_t used_ = 0;  // full slots and tombstones
};

}  // namespace terrane
