#include "client/decoded_chunks.h"

#include <algorithm>
#include <functional>

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
  e.bytes.assign(payload.begin(), payload.end());
  e.chunk = std::move(chunk);
  if (fresh) {
    lru_.push_front(key);
    e.lru = lru_.begin();
  } else {
    lru_.splice(lru_.begin(), lru_, e.lru);
  }
  while (entries_.size() > capacity_) {
    entries_.erase(lru_.back());
    lru_.pop_back();
  }
}

DecodedChunks::Stats DecodedChunks::stats() const {
  std::lock_guard lock(m_);
  Stats s = stats_;
  s.entries = entries_.size();
  for (const auto& [key, e] : entries_) s.bytes += sizeof(Entry) + e.bytes.capacity() + e.chunk->memory().total();
  return s;
}

}  // namespace terrane
