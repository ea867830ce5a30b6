#include "client/decoded_chunks.h"

#include <algorithm>
#include <functional>

#include "protocol/messages.h"

namespace terrane {

DecodedChunks::DecodedChunks(std::size_t capacity) : capacity_(std::max<std::size_t>(capacity, 1)) {}

std::size_t DecodedChunks::key_of(std::span<const std::uint8_t> payload) {
  return std::hash<std::string_view>{}(
      std::string_view(reinterpret_cast<const char*>(payload.data()), payload.size()));
}

std::shared_ptr<const Chunk> DecodedChunks::find(std::span<const std::uint8_t> payload) {
  const std::size_t key = key_of(payload);
  std::lock_guard lock(m_);
  auto it = entries_.find(key);
  if (it == entries_.end() || !std::equal(payload.begin(), payload.end(), it->second.bytes.begin(),
                                          it->second.bytes.end())) {
    ++stats_.misses;
    return nullptr;
  }
  ++stats_.hits;
  lru_.splice(lru_.begin(), lru_, it->second.lru);
  return it->second.chunk;
}

void DecodedChunks::add(std::span<const std::uint8_t> payload, std::shared_ptr<const Chunk> chunk) {
  const std::size_t key = key_of(payload);
  std::lock_guard lock(m_);
  auto [it, fresh] = entries_.try_emplace(key);
  Entry& e = it->second;
  if (!fresh) unindex(key, e);
  e.bytes.assign(payload.begin(), payload.end());
  e.chunk = std::move(chunk);
  if (fresh) {
    lru_.push_front(key);
    e.lru = lru_.begin();
  } else {
    lru_.splice(lru_.begin(), lru_, e.lru);
  }
  if (e.bytes.size() >= kPrefixBytes) {
    std::vector<std::size_t>& keys = prefix_[prefix_key(StreamRecordKind::kFull, e.bytes)];
    if (keys.size() >= 4) keys.erase(keys.begin());
    keys.push_back(key);
  }
  while (entries_.size() > capacity_) {
    const auto old = entries_.find(lru_.back());
    unindex(old->first, old->second);
    entries_.erase(old);
    lru_.pop_back();
  }
}

std::size_t DecodedChunks::prefix_key(StreamRecordKind kind, std::span<const std::uint8_t> bytes) {
  return key_of(bytes.first(kPrefixBytes)) ^ (static_cast<std::size_t>(kind) * 0x9E3779B97F4A7C15ull);
}

void DecodedChunks::unindex(std::size_t key, const Entry& e) {
  if (e.bytes.size() < kPrefixBytes) return;
  const auto it = prefix_.find(prefix_key(StreamRecordKind::kFull, e.bytes));
  if (it == prefix_.end()) return;
  std::erase(it->second, key);
  if (it->second.empty()) prefix_.erase(it);
}

KnownPayload DecodedChunks::known(StreamRecordKind kind, std::span<const std::uint8_t> rest) {
  if (kind != StreamRecordKind::kFull) return carries_units(kind) ? mips_.known_unit(payload_level(kind), rest) : KnownPayload{};
  if (rest.size() < kPrefixBytes) return {};
  const auto begins = [&](const std::vector<std::uint8_t>& b) {
    return b.size() <= rest.size() && std::equal(b.begin(), b.end(), rest.begin());
  };
  const std::size_t pk = prefix_key(kind, rest);
  std::lock_guard lock(m_);
  const auto it = prefix_.find(pk);
  if (it == prefix_.end()) return {};
  for (const std::size_t key : it->second) {
    const auto e = entries_.find(key);
    if (e == entries_.end() || !begins(e->second.bytes)) continue;
    ++stats_.known_chunks;
    ++stats_.hits;  // (taken from here, as a find would have)
    lru_.splice(lru_.begin(), lru_, e->second.lru);
    return {e->second.bytes.size(), e->second.chunk};
  }
  return {};
}

std::uint64_t DecodedChunks::hash_of(const std::shared_ptr<const Chunk>& chunk, std::uint64_t revision) {
  {
    std::lock_guard lock(m_);
    const auto it = hashes_.find(chunk.get());
    if (it != hashes_.end() && it->second.revision == revision && it->second.chunk.lock() == chunk) {
      ++stats_.hashes_shared;
      return it->second.hash;
    }
  }
  const std::uint64_t h = chunk_hash(chunk.get(), revision);  // (outside the lock: 32^3 voxels)
  std::lock_guard lock(m_);
  if (hashes_.size() >= kMaxHashes) hashes_.clear();
  hashes_[chunk.get()] = KnownHash{chunk, revision, h};
  ++stats_.hashes_made;
  return h;
}

DecodedChunks::Stats DecodedChunks::stats() const {
  std::lock_guard lock(m_);
  Stats s = stats_;
  s.entries = entries_.size();
  for (const auto& [key, e] : entries_) s.bytes += sizeof(Entry) + e.bytes.capacity() + e.chunk->memory().total();
  return s;
}

}  // namespace terrane
