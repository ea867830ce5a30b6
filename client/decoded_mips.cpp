#include "client/decoded_mips.h"

#include <algorithm>
#include <cassert>
#include <cstring>
#include <functional>
#include <string_view>

#include "common/codec/net_codec.h"
#include "common/voxel/chunk.h"

namespace terrane {

namespace {
std::size_t hash_bytes(const void* data, std::size_t size) {
  return std::hash<std::string_view>{}(std::string_view(static_cast<const char*>(data), size));
}
// Box's operator== compares voxel by voxel; a voxel is two plain bytes.
bool same_voxels(const Box& a, const Box& b) {
  return a.size() == b.size() && std::memcmp(a.voxels().data(), b.voxels().data(), a.voxels().size_bytes()) == 0;
}
}  // namespace

std::size_t DecodedMips::key_of(std::span<const std::uint8_t> bytes, int level) {
  const std::size_t n = std::min(bytes.size(), kKeyBytes);
  return hash_bytes(bytes.data(), n) ^ (static_cast<std::size_t>(level) * 0x9E3779B97F4A7C15ull);
}

std::size_t DecodedMips::key_of(const Box& voxels) {
  const std::span<const Voxel> v = voxels.voxels();
  // The side too: boxes of other sides never compare equal, but their
  // voxels' bytes may.
  return hash_bytes(v.data(), v.size_bytes()) ^ (static_cast<std::size_t>(voxels.size().x) * 0xC2B2AE3D27D4EB4Full);
}

MipVoxels MipVoxels::of_unit(int side, std::span<const std::uint8_t> bytes) {
  MipVoxels m;
  m.side_ = side;
  m.unit_.assign(bytes.begin(), bytes.end());
  return m;
}

MipVoxels MipVoxels::of_box(const Box& voxels) {
  MipVoxels m;
  m.side_ = voxels.size().x;
  m.box_ = voxels;
  return m;
}

const Box& MipVoxels::read(Box& scratch) const {
  if (!encoded()) return box_;
  scratch.resize({side_, side_, side_});
  // The bytes decoded when their record arrived: a failure here is a bug.
  [[maybe_unused]] const Status st = net_codec_decode(side_, unit_, scratch.voxels());
  assert(st.ok());
  return scratch;
}

std::size_t MipVoxels::heap_bytes() const {
  return sizeof(MipVoxels) + unit_.capacity() + box_.voxel_count() * sizeof(Voxel);
}

template <class T, class Same, class Make>
std::shared_ptr<const T> DecodedMips::intern_in(Table<T>& t, std::size_t key, Same&& same, Make&& make) {
  if (4 * (t.used + 1) > 3 * t.slots.size()) rebuild(t);
  const std::size_t mask = t.slots.size() - 1;
  constexpr std::size_t kNone = ~std::size_t{0};
  // Items of one key may differ (a unit's
  // key is of its first bytes): all of them are looked at, up to
  // kMaxPerKey live ones, and a dead one's slot is taken only once none
  // is equal.
  std::size_t i = home_slot(key, mask);
  std::size_t dead = kNone, first_live = kNone;
  std::size_t live = 0;
  for (; t.slots[i].used; i = (i + 1) & mask) {
    if (t.slots[i].key != key) continue;
    std::shared_ptr<const T> known = t.slots[i].item.lock();
    if (!known) {
      if (dead == kNone) dead = i;
      continue;
    }
    if (same(*known)) {
      ++stats_.hits;
      return known;
    }
    if (first_live == kNone) first_live = i;
    if (++live == kMaxPerKey) break;
  }
  ++stats_.misses;
  std::shared_ptr<const T> item = make();
  // A dead item's slot, else the first free one; with kMaxPerKey live
  // items of this key, the first of them is forgotten (it lives on in the
  // replicas holding it; only its sharing ends).
  const std::size_t at = dead != kNone ? dead : live == kMaxPerKey ? first_live : i;
  if (!t.slots[at].used) ++t.used;
  t.slots[at] = typename Table<T>::Slot{key, item, true};
  return item;
}

template <class T>
void DecodedMips::rebuild(Table<T>& t) {
  std::vector<typename Table<T>::Slot> old = std::move(t.slots);
  std::size_t live = 0;
  for (const auto& s : old) live += s.used && !s.item.expired() ? 1 : 0;
  std::size_t n = 1024;
  while (n < 4 * (live + 1)) n *= 2;
  t.slots.assign(n, typename Table<T>::Slot{});
  t.used = 0;
  for (auto& s : old) {
    if (!s.used || s.item.expired()) continue;
    std::size_t i = home_slot(s.key, n - 1);
    while (t.slots[i].used) i = (i + 1) & (n - 1);
    t.slots[i] = std::move(s);
    ++t.used;
  }
}

std::shared_ptr<const Box> DecodedMips::intern(std::size_t key, const Box& voxels) {
  std::lock_guard lock(m_);
  return intern_in(
      boxes_, key, [&](const Box& known) { return same_voxels(known, voxels); },
      [&] { return std::make_shared<const Box>(voxels); });
}

std::shared_ptr<const MipVoxels> DecodedMips::intern_unit(std::size_t key, int side,
                                                          std::span<const std::uint8_t> bytes) {
  std::lock_guard lock(m_);
  ++stats_.units_kept;
  return intern_in(
      mips_, key,
      [&](const MipVoxels& known) {
        return known.encoded() && known.side() == side && std::ranges::equal(known.unit(), bytes);
      },
      [&] { return std::make_shared<const MipVoxels>(MipVoxels::of_unit(side, bytes)); });
}

KnownPayload DecodedMips::known_unit(int level, std::span<const std::uint8_t> rest) {
  if (rest.size() < kKeyBytes || level < 1 || level >= kMipLevels) return {};
  const std::size_t key = key_of(rest, level);
  const int side = kChunkSize >> level;
  std::lock_guard lock(m_);
  const Table<MipVoxels>& t = mips_;
  if (t.slots.empty()) return {};
  const std::size_t mask = t.slots.size() - 1;
  std::size_t live = 0;
  for (std::size_t i = home_slot(key, mask); t.slots[i].used && live < kMaxPerKey; i = (i + 1) & mask) {
    if (t.slots[i].key != key) continue;
    std::shared_ptr<const MipVoxels> known = t.slots[i].item.lock();
    if (!known) continue;
    ++live;
    if (!known->encoded() || known->side() != side) continue;
    const std::span<const std::uint8_t> unit = known->unit();
    if (unit.size() < kKeyBytes || unit.size() > rest.size() || !std::ranges::equal(unit, rest.first(unit.size())))
      continue;
    ++stats_.hits;
    ++stats_.known_units;
    return {unit.size(), std::move(known)};
  }
  return {};
}

std::shared_ptr<const MipVoxels> DecodedMips::intern_mip_box(std::size_t key, const Box& voxels) {
  std::lock_guard lock(m_);
  return intern_in(
      mips_, key,
      [&](const MipVoxels& known) { return known.box() != nullptr && same_voxels(*known.box(), voxels); },
      [&] { return std::make_shared<const MipVoxels>(MipVoxels::of_box(voxels)); });
}

DecodedMips::Stats DecodedMips::stats() const {
  std::lock_guard lock(m_);
  Stats s = stats_;
  s.bytes = boxes_.slots.capacity() * sizeof(Table<Box>::Slot) + mips_.slots.capacity() * sizeof(Table<MipVoxels>::Slot);
  for (const auto& slot : boxes_.slots)
    if (std::shared_ptr<const Box> box = slot.item.lock()) {
      ++s.entries;
      s.bytes += sizeof(Box) + box->voxel_count() * sizeof(Voxel);
    }
  for (const auto& slot : mips_.slots)
    if (std::shared_ptr<const MipVoxels> mip = slot.item.lock()) {
      ++s.entries;
      s.bytes += mip->heap_bytes();
    }
  return s;
}

}  // namespace terrane
