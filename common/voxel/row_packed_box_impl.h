// Template definitions for RowPackedBox<N>; included by row_packed_box.h only.
#pragma once

#include <algorithm>
#include <cstring>
#include <vector>

namespace terrane {

template <int N>
RowPackedBox<N>::RowPackedBox(Material fill)
    : headers_(row_packed_detail::uniform_headers(N, fill)) {}

template <int N>
RowPackedBox<N> RowPackedBox<N>::clone() const {
  RowPackedBox copy(kAir);
  copy.unpacked_ = unpacked_;
  copy.repacks_ = repacks_;
  copy.data_units_ = data_units_;
  if (owns_headers_) {
    copy.owned_headers_ = std::make_unique<std::uint16_t[]>(kRows);
    std::memcpy(copy.owned_headers_.get(), headers_, sizeof(std::uint16_t) * kRows);
    copy.headers_ = copy.owned_headers_.get();
    copy.owns_headers_ = true;
  } else {
    copy.headers_ = headers_;
  }
  if (data_units_ > 0) {
    copy.data_ = std::make_unique<Voxel[]>(data_units_);
    std::memcpy(copy.data_.get(), data_.get(), sizeof(Voxel) * data_units_);
  }
  return copy;
}

template <int N>
void RowPackedBox<N>::read_row_into(int y, int z, Voxel* out) const {
  Row scratch;
  std::memcpy(out, read_row(y, z, scratch), sizeof(Voxel) * N);
}

template <int N>
std::uint16_t* RowPackedBox<N>::mutable_headers() {
  if (!owns_headers_) {
    owned_headers_ = std::make_unique<std::uint16_t[]>(kRows);
    std::memcpy(owned_headers_.get(), headers_, sizeof(std::uint16_t) * kRows);
    headers_ = owned_headers_.get();
    owns_headers_ = true;
  }
  return owned_headers_.get();
}

template <int N>
void RowPackedBox<N>::become_uniform(Material m) {
  owned_headers_.reset();
  data_.reset();
  data_units_ = 0;
  owns_headers_ = false;
  unpacked_ = false;
  headers_ = row_packed_detail::uniform_headers(N, m);
}

template <int N>
void RowPackedBox<N>::fill(Material m) {
  become_uniform(m);
  repacks_ = 0;
}

template <int N>
template <class RowFn>
void RowPackedBox<N>::modify_rows(int y0, int y1, int z0, int z1, RowFn&& fn) {
  const int ny = y1 - y0;
  const int nz = z1 - z0;
  if (ny <= 0 || nz <= 0) return;
  const int count = ny * nz;
  auto row_of = [&](int i) { return (y0 + i / nz) * N + z0 + i % nz; };

  // Stage 1: materialise and modify the touched rows.
  thread_local std::vector<Voxel> content;
  content.resize(static_cast<std::size_t>(count) * N);
  for (int y = y0; y < y1; ++y) {
    for (int z = z0; z < z1; ++z) {
      Voxel* row = content.data() + static_cast<std::size_t>((y - y0) * nz + (z - z0)) * N;
      read_row_into(y, z, row);
      fn(y, z, row);
      for (int i = 0; i < N; ++i) row[i] = make_voxel(row[i].material, row[i].occupancy);
    }
  }

  if (unpacked_) {
    // Every row is a raw record of its own: write in place, never repack.
    for (int i = 0; i < count; ++i)
      std::memcpy(data_.get() + (headers_[row_of(i)] & kOffsetMask),
                  content.data() + static_cast<std::size_t>(i) * N, sizeof(Voxel) * N);
    return;
  }

  // Stage 2: encode the rows and see whether storage has to move.
  thread_local std::vector<std::uint8_t> records;
  thread_local std::vector<std::uint16_t> sizes;
  thread_local std::vector<Material> materials;
  records.resize(static_cast<std::size_t>(count) * 2 * N);
  sizes.resize(static_cast<std::size_t>(count));
  materials.resize(static_cast<std::size_t>(count));
  bool in_place = true;
  bool headers_change = false;
  bool records_change = false;
  for (int i = 0; i < count; ++i) {
    const Voxel* row = content.data() + static_cast<std::size_t>(i) * N;
    std::uint8_t* rec = records.data() + static_cast<std::size_t>(i) * 2 * N;
    sizes[i] = static_cast<std::uint16_t>(row_packed_detail::encode_row(row, N, rec));
    materials[i] = row[0].material;
    const std::uint16_t h = headers_[row_of(i)];
    if (sizes[i] == 0) {
      if (h & kAllocated) in_place = false;
      else if ((h & 63) != materials[i]) headers_change = true;
    } else if (!(h & kAllocated) || row_packed_detail::record_bytes(record(h), N) != sizes[i]) {
      in_place = false;
    } else if (std::memcmp(record(h), rec, static_cast<std::size_t>(sizes[i])) != 0) {
      records_change = true;
    }
  }
  if (in_place && records_change) {
    // A changed record may be overwritten only if no other row shares it.
    thread_local std::vector<std::uint8_t> refs;
    refs.assign(data_units_, 0);
    for (int r = 0; r < kRows; ++r)
      if (headers_[r] & kAllocated) refs[headers_[r] & kOffsetMask] += refs[headers_[r] & kOffsetMask] < 2;
    for (int i = 0; i < count && in_place; ++i) {
      const std::uint16_t h = headers_[row_of(i)];
      if (sizes[i] > 0 && refs[h & kOffsetMask] > 1) in_place = false;
    }
  }

  if (!in_place) {
    // Stage 3a: one reallocation for the whole write.
    rebuild_rect(y0, y1, z0, z1, records.data(), sizes.data(), materials.data());
    if (++repacks_ > kRepackBudget) unpack_all();
    return;
  }

  // Stage 3b: same record sizes, nothing shared: write in place.
  std::uint16_t* headers = headers_change ? mutable_headers() : nullptr;
  for (int i = 0; i < count; ++i) {
    const int r = row_of(i);
    if (sizes[i] == 0) {
      if (headers != nullptr) headers[r] = materials[i];
    } else {
      std::memcpy(data_.get() + (headers_[r] & kOffsetMask), records.data() + static_cast<std::size_t>(i) * 2 * N,
                  std::size_t{sizes[i]});
    }
  }
  if (headers_change && data_units_ == 0) {
    const std::uint16_t first = headers_[0];
    if (std::all_of(headers_, headers_ + kRows, [&](std::uint16_t h) { return h == first; }))
      become_uniform(static_cast<Material>(first & 63));
  }
}

template <int N>
void RowPackedBox<N>::rebuild_rect(int y0, int y1, int z0, int z1, const std::uint8_t* records, const std::uint16_t* sizes,
                                   const Material* materials) {
  const int nz = z1 - z0;
  // New records go to a scratch buffer first (at most one raw record per
  // row), deduplicated through an open-addressing table of offsets + 1.
  constexpr std::size_t kTableSize = 2 * kRows;  // power of two, load <= 1/2
  thread_local std::vector<std::uint8_t> buf;
  thread_local std::vector<std::uint16_t> table;
  buf.resize(std::size_t{kRows} * 2 * N);
  table.assign(kTableSize, 0);
  auto headers = std::make_unique<std::uint16_t[]>(kRows);
  std::size_t used = 0;  // bytes in buf, always even
  bool all_uniform_same = true;
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const int r = y * N + z;
      const bool touched = y >= y0 && y < y1 && z >= z0 && z < z1;
      const int i = touched ? (y - y0) * nz + (z - z0) : -1;
      const std::uint8_t* src = nullptr;
      int size = 0;
      if (touched) {
        size = sizes[i];
        if (size == 0) headers[r] = materials[i];
        src = records + static_cast<std::size_t>(i) * 2 * N;
      } else if (const std::uint16_t h = headers_[r]; !(h & kAllocated)) {
        headers[r] = h;
      } else {
        src = record(h);
        size = row_packed_detail::record_bytes(src, N);
      }
      if (size > 0) {
        std::uint32_t hash = 2166136261u;  // FNV-1a
        for (int k = 0; k < size; ++k) hash = (hash ^ src[k]) * 16777619u;
        for (std::size_t slot = hash & (kTableSize - 1);; slot = (slot + 1) & (kTableSize - 1)) {
          const std::uint16_t e = table[slot];
          if (e == 0) {
            std::memcpy(buf.data() + used, src, static_cast<std::size_t>(size));
            headers[r] = static_cast<std::uint16_t>(kAllocated | (used / 2));
            table[slot] = static_cast<std::uint16_t>(used / 2 + 1);
            used += static_cast<std::size_t>(size);
            break;
          }
          const std::uint8_t* cand = buf.data() + std::size_t{e - 1u} * 2;
          if (row_packed_detail::record_bytes(cand, N) == size &&
              std::memcmp(cand, src, static_cast<std::size_t>(size)) == 0) {
            headers[r] = static_cast<std::uint16_t>(kAllocated | (e - 1u));
            break;
          }
        }
      }
      all_uniform_same &= headers[r] == headers[0];
    }
  }
  if (all_uniform_same && !(headers[0] & kAllocated)) {
    become_uniform(static_cast<Material>(headers[0] & 63));
    return;
  }
  owned_headers_ = std::move(headers);
  headers_ = owned_headers_.get();
  owns_headers_ = true;
  if (used == 0) {
    data_.reset();
    data_units_ = 0;
    return;
  }
  data_units_ = static_cast<std::uint32_t>(used / 2) + kPadUnits;
  data_ = std::make_unique<Voxel[]>(data_units_);  // value-initialised: padding is zero
  std::memcpy(data_.get(), buf.data(), used);
}

template <int N>
void RowPackedBox<N>::unpack_all() {
  auto headers = std::make_unique<std::uint16_t[]>(kRows);
  const std::uint32_t units = std::uint32_t{kRows} * N + kPadUnits;
  auto data = std::make_unique<Voxel[]>(units);
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const int r = y * N + z;
      read_row_into(y, z, data.get() + std::size_t(r) * N);
      headers[r] = static_cast<std::uint16_t>(kAllocated | (r * N));
    }
  }
  owned_headers_ = std::move(headers);
  headers_ = owned_headers_.get();
  owns_headers_ = true;
  data_ = std::move(data);
  data_units_ = units;
  unpacked_ = true;
}

template <int N>
void RowPackedBox<N>::compact() {
  std::vector<Voxel> content(std::size_t{kRows} * N);
  std::vector<std::uint8_t> records(std::size_t{kRows} * 2 * N);
  std::vector<std::uint16_t> sizes(kRows);
  std::vector<Material> materials(kRows);
  for (int r = 0; r < kRows; ++r) {
    Voxel* row = content.data() + std::size_t(r) * N;
    read_row_into(r / N, r % N, row);
    sizes[r] = static_cast<std::uint16_t>(row_packed_detail::encode_row(row, N, records.data() + std::size_t(r) * 2 * N));
    materials[r] = row[0].material;
  }
  unpacked_ = false;
  repacks_ = 0;
  rebuild_rect(0, N, 0, N, records.data(), sizes.data(), materials.data());
}

template <int N>
std::size_t RowPackedBox<N>::heap_bytes() const {
  return (owns_headers_ ? sizeof(std::uint16_t) * kRows : 0) + sizeof(Voxel) * std::size_t{data_units_};
}

template <int N>
RowPackedStats RowPackedBox<N>::stats() const {
  RowPackedStats s;
  s.data_bytes = sizeof(Voxel) * std::size_t{data_units_};
  std::vector<bool> seen(data_units_, false);
  for (int r = 0; r < kRows; ++r) {
    const std::uint16_t h = headers_[r];
    if (!(h & kAllocated)) {
      ++s.uniform_rows;
      continue;
    }
    const std::uint8_t tag = record(h)[0];
    if (tag < row_packed_detail::kPaletteTag || (tag & row_packed_detail::kTagOccupancy)) {
      ++s.raw_rows;
    } else {
      ++s.byte_rows;
    }
    s.palette_rows += tag >= row_packed_detail::kPaletteTag;
    s.shared_rows += seen[h & kOffsetMask];
    seen[h & kOffsetMask] = true;
  }
  return s;
}

}  // namespace terrane
