#include "client/chunk_cache.h"

#include <fmt/format.h>

#include <algorithm>
#include <thread>
#include <atomic>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <cctype>
#include <unistd.h>
#include <map>
#include <tuple>

#include "client/replica.h"
#include "client/view_coverage.h"
#include "common/world/coarse_image.h"
#include "common/world/view.h"

namespace terrane {

namespace fs = std::filesystem;

void ChunkCache::post(std::function<void()> job) {
  asio::thread_pool* pool = nullptr;
  {
    std::lock_guard lock(mutex_);
    if (!loaders_) loaders_ = std::make_unique<asio::thread_pool>(std::max(1u, std::thread::hardware_concurrency()));
    pool = loaders_.get();
  }
  asio::post(*pool, std::move(job));
}

namespace {

constexpr std::uint32_t kRegionSlots = kCoarseRegionChunks * kCoarseRegionChunks * kCoarseRegionChunks;
constexpr char kMagic[8] = {'T', 'R', 'N', 'C', 'A', 'C', 'H', 'E'};

std::uint64_t fnv1a(std::uint64_t h, std::span<const std::uint8_t> bytes) {
  for (const std::uint8_t b : bytes) h = (h ^ b) * 0x100000001b3ull;
  return h;
}
constexpr std::uint64_t kFnvBasis = 0xcbf29ce484222325ull;

template <class T>
void put(std::vector<std::uint8_t>& out, T v) {
  const std::size_t at = out.size();
  out.resize(at + sizeof(T));
  std::memcpy(out.data() + at, &v, sizeof(T));  // little-endian hosts only (as the wire)
}
template <class T>
T get(std::span<const std::uint8_t> bytes, std::size_t at) {
  T v;
  std::memcpy(&v, bytes.data() + at, sizeof(T));
  return v;
}

DecodeError damaged(std::size_t at, const char* what) { return DecodeError{DecodeErrorCode::kInvalidValue, at, what}; }

}  // namespace

std::string ChunkCache::normal_dir(const std::string& dir) {
  std::string d = fs::path(dir).lexically_normal().string();
  while (d.size() > 1 && d.back() == '/') d.pop_back();
  return d;
}

FileResult<std::shared_ptr<ChunkCache>> ChunkCache::open(const std::string& dir, std::uint64_t max_bytes) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return FileError{"chunk cache " + dir + ": cannot create: " + ec.message(), {}};
  if (!fs::is_directory(dir, ec)) return FileError{"chunk cache " + dir + ": not a directory", {}};
  // One spelling of each file's path (a trailing slash would make another).
  std::shared_ptr<ChunkCache> cache(new ChunkCache(normal_dir(dir), max_bytes));
  cache->scan();
  return cache;
}

namespace {

// DIR/<16 hex digits>/<int>_<int>_<int>.region: a file of the cache's own.
bool cache_file_name(const fs::path& world_dir, const fs::path& file) {
  const std::string w = world_dir.filename().string();
  if (w.size() != 16 || !std::all_of(w.begin(), w.end(), [](char c) { return std::isxdigit(static_cast<unsigned char>(c)); }))
    return false;
  if (file.extension() != ".region") return false;
  int x, y, z;
  char tail;
  return std::sscanf(file.stem().c_str(), "%d_%d_%d%c", &x, &y, &z, &tail) == 3;
}

}  // namespace

void ChunkCache::scan() {
  // Files by age: the oldest are evicted first. Anything else in the
  // directory (other files, a saver's temporary) is left alone.
  std::error_code ec;
  std::vector<std::pair<fs::file_time_type, std::pair<std::string, std::uint64_t>>> found;
  for (auto w = fs::directory_iterator(dir_, ec); !ec && w != fs::directory_iterator(); w.increment(ec)) {
    std::error_code wec;
    if (!w->is_directory(wec)) continue;
    for (auto it = fs::directory_iterator(w->path(), wec); !wec && it != fs::directory_iterator(); it.increment(wec)) {
      std::error_code fec;
      if (!it->is_regular_file(fec) || !cache_file_name(w->path(), it->path())) continue;
      const auto size = it->file_size(fec);
      if (fec) continue;
      found.push_back({it->last_write_time(fec), {it->path().string(), size}});
    }
  }
  std::sort(found.begin(), found.end());
  for (const auto& [when, file] : found) touch(file.first, file.second);
}

void ChunkCache::touch(const std::string& path, std::uint64_t size) {
  File& f = files_[path];
  counters_.bytes = counters_.bytes - f.size + size;
  f.size = size;
  f.used = ++use_clock_;
}

void ChunkCache::forget(const std::string& path) {
  auto it = files_.find(path);
  if (it != files_.end()) {
    counters_.bytes -= it->second.size;
    files_.erase(it);
  }
  std::error_code ec;
  fs::remove(path, ec);
}

void ChunkCache::evict() {
  while (counters_.bytes > max_bytes_ && !files_.empty()) {
    auto oldest = std::min_element(files_.begin(), files_.end(),
                                   [](const auto& a, const auto& b) { return a.second.used < b.second.used; });
    forget(std::string(oldest->first));
    ++counters_.regions_evicted;
  }
}

std::string ChunkCache::path_of(std::uint64_t world_id, Vec3i region) const {
  return fmt::format("{}/{:016x}/{}_{}_{}.region", dir_, world_id, region.x, region.y, region.z);
}

std::vector<std::uint8_t> ChunkCache::file_bytes(std::uint64_t world_id, Vec3i region,
                                                 std::span<const std::uint8_t> records, std::size_t count) {
  std::vector<std::uint8_t> out;
  out.reserve(kHeaderBytes + records.size());
  out.resize(sizeof kMagic);
  std::memcpy(out.data(), kMagic, sizeof kMagic);
  put<std::uint32_t>(out, kFormatVersion);
  put<std::uint32_t>(out, static_cast<std::uint32_t>(count));
  put<std::uint64_t>(out, world_id);
  put<std::int32_t>(out, region.x);
  put<std::int32_t>(out, region.y);
  put<std::int32_t>(out, region.z);
  put<std::uint32_t>(out, static_cast<std::uint32_t>(records.size()));
  const std::uint64_t sum = fnv1a(fnv1a(kFnvBasis, out), records);
  put<std::uint64_t>(out, sum);
  out.insert(out.end(), records.begin(), records.end());
  return out;
}

Status ChunkCache::check_file(std::span<const std::uint8_t> bytes, std::uint64_t world_id, Vec3i region,
                              const std::function<void(const StreamRecord&)>& fn) {
  if (bytes.size() < kHeaderBytes) return damaged(bytes.size(), "chunk cache: shorter than its header");
  if (std::memcmp(bytes.data(), kMagic, 8) != 0) return damaged(0, "chunk cache: not a region file (magic)");
  if (get<std::uint32_t>(bytes, 8) != kFormatVersion)
    return damaged(8, "chunk cache: format version not 1");
  const std::uint32_t count = get<std::uint32_t>(bytes, 12);
  if (get<std::uint64_t>(bytes, 16) != world_id) return damaged(16, "chunk cache: another world's");
  if (!(Vec3i{get<std::int32_t>(bytes, 24), get<std::int32_t>(bytes, 28), get<std::int32_t>(bytes, 32)} == region))
    return damaged(24, "chunk cache: another region's");
  const std::uint32_t payload = get<std::uint32_t>(bytes, 36);
  if (payload != bytes.size() - kHeaderBytes) return damaged(36, "chunk cache: payload size does not match the file's");
  if (count == 0 || count > kRegionSlots) return damaged(12, "chunk cache: record count not 1..512");
  const std::uint64_t sum = fnv1a(fnv1a(kFnvBasis, bytes.first(40)), bytes.subspan(kHeaderBytes));
  if (get<std::uint64_t>(bytes, 40) != sum) return damaged(40, "chunk cache: checksum does not match");
  StreamDecodeScratch scratch;
  std::size_t seen = 0;
  const Vec3i base = region * kCoarseRegionChunks;
  auto st = decode_stream_batch(bytes.subspan(kHeaderBytes), scratch, [&](const StreamRecord& r) -> Status {
    if (!gives_form(r.kind) || !claimable(r.form())) return damaged(kHeaderBytes, "chunk cache: a record not Full, Mip or Empty");
    const Vec3i o = r.chunk_pos - base;
    if (o.x < 0 || o.y < 0 || o.z < 0 || o.x >= kCoarseRegionChunks || o.y >= kCoarseRegionChunks ||
        o.z >= kCoarseRegionChunks)
      return damaged(kHeaderBytes, "chunk cache: a record outside its region");
    ++seen;
    if (fn) fn(r);
    return Ok{};
  });
  if (!st) {
    DecodeError e = st.error();
    e.offset += kHeaderBytes;
    return e;
  }
  if (seen != count) return damaged(12, "chunk cache: record count does not match the records");
  return Ok{};
}

std::optional<std::size_t> ChunkCache::load(std::uint64_t world_id, Vec3i region,
                                            const std::function<void(const StreamRecord&)>& fn) {
  const std::string path = path_of(world_id, region);
  {
    std::lock_guard lock(mutex_);
    if (!files_.count(path)) {
      ++counters_.regions_missing;
      return 0;
    }
  }
  // Read and decoded without the lock (a save renames a whole file in).
  std::vector<std::uint8_t> bytes;
  std::ifstream in(path, std::ios::binary);
  if (in) {
    in.seekg(0, std::ios::end);
    const auto size = static_cast<std::uint64_t>(in.tellg());
    in.seekg(0);
    if (size <= kHeaderBytes + kMaxPayloadBytes) {
      bytes.resize(static_cast<std::size_t>(size));
      in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
      if (!in) bytes.clear();
    }
  }
  std::size_t n = 0;
  const bool whole = !bytes.empty() && check_file(bytes, world_id, region, [&](const StreamRecord& r) {
                       fn(r);
                       ++n;
                     }).ok();
  if (whole) {
    // Its use, for the order of eviction in a later process too.
    std::error_code ec;
    fs::last_write_time(path, fs::file_time_type::clock::now(), ec);
  }
  std::lock_guard lock(mutex_);
  if (!whole) {
    forget(path);
    ++counters_.regions_damaged;
    return std::nullopt;
  }
  touch(path, bytes.size());
  ++counters_.regions_loaded;
  counters_.chunks_loaded += n;
  return n;
}

bool ChunkCache::save(std::uint64_t world_id, Vec3i region, std::span<const std::uint8_t> records, std::size_t count) {
  const std::string path = path_of(world_id, region);
  if (count == 0) {
    std::lock_guard lock(mutex_);
    if (files_.count(path)) forget(path);
    return true;
  }
  const std::vector<std::uint8_t> bytes = file_bytes(world_id, region, records, count);
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  if (ec) return false;
  // Written aside and renamed: a reader never sees half a file, and a
  // process killed part-way leaves the file before (or none).
  static std::atomic<std::uint64_t> serial{0};
  const std::string temp = fmt::format("{}.{}-{}.tmp", path, ::getpid(), serial.fetch_add(1));
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) {
      fs::remove(temp, ec);
      return false;
    }
  }
  std::lock_guard lock(mutex_);
  fs::rename(temp, path, ec);
  if (ec) {
    fs::remove(temp, ec);
    return false;
  }
  touch(path, bytes.size());
  ++counters_.regions_saved;
  counters_.chunks_saved += count;
  evict();
  return true;
}

std::size_t load_view(ChunkCache& cache, std::uint64_t world_id, const StreamedView& view, const WorldBounds& bounds,
                      Replica& replica) {
  // The regions the view's box meets (chunks_in_view would list and sort
  // every chunk in view first: 40,000 at view 1,024).
  const Vec3i centre = view_chunk(view.position);
  const std::int32_t reach = view.view_distance / kChunkSize + 1;
  const Vec3i lo = coarse_region_of(centre - Vec3i{reach, reach, reach});
  const Vec3i hi = coarse_region_of(centre + Vec3i{reach, reach, reach});
  std::size_t n = 0;
  std::vector<Vec3i> taken;
  for (std::int32_t y = lo.y; y <= hi.y; ++y)
    for (std::int32_t z = lo.z; z <= hi.z; ++z)
      for (std::int32_t x = lo.x; x <= hi.x; ++x) {
        const Vec3i region{x, y, z};
        constexpr std::int64_t kRegionVoxels = std::int64_t{kCoarseRegionChunks} * kChunkSize;
        if (std::int64_t{bounds.min_y} >= (std::int64_t{y} + 1) * kRegionVoxels ||
            std::int64_t{bounds.max_y} <= std::int64_t{y} * kRegionVoxels)
          continue;  // above or below the world
        taken.clear();
        const auto got = cache.load(world_id, region, [&](const StreamRecord& r) {
          // A chunk out of view now would only be claimed to be released.
          if (!within(view.position, r.chunk_pos, view.view_distance) || !bounds.touches_chunk(r.chunk_pos)) return;
          replica.apply_stream_record(r);
          taken.push_back(r.chunk_pos);
        });
        if (!got) {
          // A damaged file: none of it is kept.
          for (const Vec3i cp : taken) {
            StreamRecord released;
            released.kind = StreamRecordKind::kReleased;
            released.chunk_pos = cp;
            replica.apply_stream_record(released);
          }
          continue;
        }
        n += taken.size();
      }
  return n;
}

std::optional<std::size_t> save_replica(ChunkCache& cache, std::uint64_t world_id, const Replica& replica,
                                        const std::function<bool(Vec3i)>& skip) {
  std::map<std::tuple<int, int, int>, std::vector<Vec3i>> regions;
  replica.for_each_holding([&](Vec3i cp, const Holding& h) {
    if (!claimable(h.form) || (skip && skip(cp))) return;
    const Vec3i r = coarse_region_of(cp);
    regions[{r.y, r.z, r.x}].push_back(cp);
  });
  std::size_t saved = 0;
  bool ok = true;
  std::vector<std::uint8_t> records, payload;
  for (auto& [key, chunks] : regions) {
    std::sort(chunks.begin(), chunks.end(), [](Vec3i a, Vec3i b) { return coarse_index(a) < coarse_index(b); });
    records.clear();
    Vec3i prev{0, 0, 0};
    std::size_t count = 0;
    for (const Vec3i cp : chunks) {
      payload.clear();
      const auto h = replica.exact_payload(cp, payload);
      if (!h) continue;
      put_stream_record_head(record_kind_of(h->form), cp, h->revision, prev, records);
      records.insert(records.end(), payload.begin(), payload.end());
      ++count;
    }
    const Vec3i region{std::get<2>(key), std::get<0>(key), std::get<1>(key)};
    if (!cache.save(world_id, region, records, count)) ok = false;
    saved += count;
  }
  if (!ok) return std::nullopt;
  return saved;
}

ChunkCacheCounters ChunkCache::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace terrane
