#include "client/decoded_mips.h"

#include <algorithm>
#include <cstring>
#include <functional>
#include <string_view>

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
  return hash_bytes(bytes.data(), bytes.size()) ^ (static_cast<std::size_t>(level) * 0x9E3779B97F4A7C15ull);
}

std::size_t DecodedMips::key_of(const Box& voxels) {
  const std::span<const Voxel> v = voxels.voxels();
  // The side too: boxes of other sides never compare equal, but their
  // voxels' bytes may.
  return hash_bytes(v.data(), v.size_bytes()) ^ (static_cast<std::size_t>(voxels.size().x) * 0xC2B2AE3D27D4EB4Full);
}

std::shared_ptr<const Box> DecodedMips::intern(std::size_t key, const Box& voxels) {
  std::lock_guard lock(m_);
  if (4 * (used_ + 1) > 3 * slots_.size()) rebuild();
  const std::size_t mask = slots_.size() - 1;
  // Keys are hashes already; the multiply spreads keys that differ only
  // in their high bits (the level).
  std::size_t i = (key * 0x9E3779B97F4A7C15ull >> 20) & mask;
  for (; slots_[i].used; i = (i + 1) & mask) {
    if (slots_[i].key != key) continue;
    std::shared_ptr<const Box> known = slots_[i].box.lock();
    if (known && same_voxels(*known, voxels)) {
      ++stats_.hits;
      return known;
    }
    if (!known) break;  // a dead box of this key: its slot takes the new one
  }
  ++stats_.misses;
  auto box = std::make_shared<const Box>(voxels);
  if (!slots_[i].used) ++used_;
  slots_[i] = Slot{key, box, true};
  return box;
}

void DecodedMips::rebuild() {
  std::vector<Slot> old = std::move(slots_);
  std::size_t live = 0;
  for (const Slot& s : old) live += s.used && !s.box.expired() ? 1 : 0;
  std::size_t n = 1024;
  while (n < 4 * (live + 1)) n *= 2;
  slots_.assign(n, Slot{});
  used_ = 0;
  for (Slot& s : old) {
    if (!s.used || s.box.expired()) continue;
    std::size_t i = (s.key * 0x9E3779B97F4A7C15ull >> 20) & (n - 1);
    while (slots_[i].used) i = (i + 1) & (n - 1);
    slots_[i] = std::move(s);
    ++used_;
  }
}

DecodedMips::Stats DecodedMips::stats() const {
  std::lock_guard lock(m_);
  Stats s = stats_;
  s.bytes = slots_.capacity() * sizeof(Slot);
  for (const Slot& slot : slots_)
    if (std::shared_ptr<const Box> box = slot.box.lock()) {
      ++s.entries;
      s.bytes += sizeof(Box) + box->voxel_count() * sizeof(Voxel);
    }
  return s;
}

}  // namespace terrane
