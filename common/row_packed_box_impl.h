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
  copy.raw_count_ = raw_count_;
  copy.byte_count_ = byte_count_;
  if (owns_headers_) {
    copy.owned_headers_ = std::make_unique<std::uint16_t[]>(kRows);
    std::memcpy(copy.owned_headers_.get(), headers_, sizeof(std::uint16_t) * kRows);
    copy.headers_ = copy.owned_headers_.get();
    copy.owns_headers_ = true;
  } else {
    copy.headers_ = headers_;
  }
  if (raw_count_ > 0) {
    copy.raw_ = std::make_unique<Voxel[]>(std::size_t{raw_count_} * N);
    std::memcpy(copy.raw_.get(), raw_.get(), sizeof(Voxel) * raw_count_ * N);
  }
  if (byte_count_ > 0) {
    copy.bytes_ = std::make_unique<std::uint8_t[]>(std::size_t{byte_count_} * N);
    std::memcpy(copy.bytes_.get(), bytes_.get(), std::size_t{byte_count_} * N);
  }
  return copy;
}

template <int N>
void RowPackedBox<N>::read_row_into(int y, int z, Voxel* out) const {
  const std::uint16_t h = headers_[y * N + z];
  if (!(h & kAllocated)) {
    std::memcpy(out, row_packed_detail::uniform_row(static_cast<Material>(h & 63)), sizeof(Voxel) * N);
    return;
  }
  const std::size_t at = static_cast<std::size_t>(h & kOffsetMask) * N;
  if (h & kByteRow) {
    widen(bytes_.get() + at, out);
  } else {
    std::memcpy(out, raw_.get() + at, sizeof(Voxel) * N);
  }
}

template <int N>
typename RowPackedBox<N>::Classified RowPackedBox<N>::classify(const Voxel* row) {
  bool uniform = true;
  bool all_default = true;
  const Voxel first = row[0];
  for (int i = 0; i < N; ++i) {
    uniform &= row[i] == first;
    all_default &= has_default_occupancy(row[i]);
  }
  if (uniform && all_default) return {RowClass::kUniform, first.material};
  return {all_default ? RowClass::kByte : RowClass::kRaw, kAir};
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
  raw_.reset();
  bytes_.reset();
  raw_count_ = byte_count_ = 0;
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

  // Stage 1: materialise and modify the touched rows, then classify them.
  thread_local std::vector<Voxel> content;
  thread_local std::vector<Classified> classes;
  content.resize(static_cast<std::size_t>(count) * N);
  classes.resize(static_cast<std::size_t>(count));
  for (int y = y0; y < y1; ++y) {
    for (int z = z0; z < z1; ++z) {
      Voxel* row = content.data() + static_cast<std::size_t>((y - y0) * nz + (z - z0)) * N;
      read_row_into(y, z, row);
      fn(y, z, row);
      for (int i = 0; i < N; ++i) row[i] = make_voxel(row[i].material, row[i].occupancy);
    }
  }

  if (unpacked_) {
    // Every row is raw: write in place, never repack.
    for (int y = y0; y < y1; ++y)
      for (int z = z0; z < z1; ++z)
        std::memcpy(raw_.get() + static_cast<std::size_t>(headers_[y * N + z] & kOffsetMask) * N,
                    content.data() + static_cast<std::size_t>((y - y0) * nz + (z - z0)) * N,
                    sizeof(Voxel) * N);
    return;
  }

  bool same_classes = true;
  bool uniform_changed = false;
  for (int i = 0; i < count; ++i) {
    classes[i] = classify(content.data() + static_cast<std::size_t>(i) * N);
    const int r = (y0 + i / nz) * N + z0 + i % nz;
    const std::uint16_t h = headers_[r];
    if (classes[i].cls != class_of(h)) {
      same_classes = false;
    } else if (classes[i].cls == RowClass::kUniform && (h & 63) != classes[i].material) {
      uniform_changed = true;
    }
  }

  if (!same_classes) {
    // Stage 2: one reallocation for the whole write.
    rebuild_rect(y0, y1, z0, z1, content.data(), classes.data());
    if (++repacks_ > kRepackBudget) unpack_all();
    return;
  }

  // Stage 3 (in place): same row classes, so no storage moves.
  std::uint16_t* headers = uniform_changed ? mutable_headers() : nullptr;
  for (int i = 0; i < count; ++i) {
    const int r = (y0 + i / nz) * N + z0 + i % nz;
    const Voxel* src = content.data() + static_cast<std::size_t>(i) * N;
    const std::uint16_t h = headers_[r];
    const std::size_t at = static_cast<std::size_t>(h & kOffsetMask) * N;
    switch (classes[i].cls) {
      case RowClass::kUniform:
        if (headers != nullptr) headers[r] = classes[i].material;
        break;
      case RowClass::kRaw:
        std::memcpy(raw_.get() + at, src, sizeof(Voxel) * N);
        break;
      case RowClass::kByte:
        for (int k = 0; k < N; ++k) bytes_[at + k] = src[k].material;
        break;
    }
  }
  if (uniform_changed && raw_count_ == 0 && byte_count_ == 0) {
    const std::uint16_t first = headers_[0];
    if (std::all_of(headers_, headers_ + kRows, [&](std::uint16_t h) { return h == first; }))
      become_uniform(static_cast<Material>(first & 63));
  }
}

template <int N>
void RowPackedBox<N>::rebuild_rect(int y0, int y1, int z0, int z1, const Voxel* content,
                                   const Classified* classes) {
  const int nz = z1 - z0;
  auto touched_index = [&](int y, int z) -> int {
    return (y >= y0 && y < y1 && z >= z0 && z < z1) ? (y - y0) * nz + (z - z0) : -1;
  };
  // Count the new layout first so each array is allocated once, exactly.
  int raw_rows = 0, byte_rows = 0;
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const int i = touched_index(y, z);
      const RowClass c = i >= 0 ? classes[i].cls : class_of(headers_[y * N + z]);
      raw_rows += c == RowClass::kRaw;
      byte_rows += c == RowClass::kByte;
    }
  }
  auto headers = std::make_unique<std::uint16_t[]>(kRows);
  std::unique_ptr<Voxel[]> raw = raw_rows ? std::make_unique<Voxel[]>(std::size_t(raw_rows) * N) : nullptr;
  std::unique_ptr<std::uint8_t[]> bytes =
      byte_rows ? std::make_unique<std::uint8_t[]>(std::size_t(byte_rows) * N) : nullptr;
  std::uint16_t next_raw = 0, next_byte = 0;
  Row scratch;
  bool all_uniform_same = raw_rows == 0 && byte_rows == 0;
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const int r = y * N + z;
      const int i = touched_index(y, z);
      const std::uint16_t old = headers_[r];
      const Voxel* src;
      Classified c;
      if (i >= 0) {
        src = content + static_cast<std::size_t>(i) * N;
        c = classes[i];
      } else {
        src = read_row(y, z, scratch);
        c = {class_of(old), static_cast<Material>(old & 63)};
      }
      switch (c.cls) {
        case RowClass::kUniform:
          headers[r] = c.material;
          break;
        case RowClass::kRaw:
          headers[r] = static_cast<std::uint16_t>(kAllocated | next_raw);
          std::memcpy(raw.get() + std::size_t{next_raw} * N, src, sizeof(Voxel) * N);
          ++next_raw;
          break;
        case RowClass::kByte:
          headers[r] = static_cast<std::uint16_t>(kAllocated | kByteRow | next_byte);
          for (int k = 0; k < N; ++k) bytes[std::size_t{next_byte} * N + k] = src[k].material;
          ++next_byte;
          break;
      }
      all_uniform_same &= headers[r] == headers[0];
    }
  }
  if (all_uniform_same) {
    become_uniform(static_cast<Material>(headers[0] & 63));
    return;
  }
  owned_headers_ = std::move(headers);
  headers_ = owned_headers_.get();
  owns_headers_ = true;
  raw_ = std::move(raw);
  bytes_ = std::move(bytes);
  raw_count_ = next_raw;
  byte_count_ = next_byte;
}

template <int N>
void RowPackedBox<N>::unpack_all() {
  auto headers = std::make_unique<std::uint16_t[]>(kRows);
  auto raw = std::make_unique<Voxel[]>(std::size_t{kRows} * N);
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const int r = y * N + z;
      read_row_into(y, z, raw.get() + std::size_t(r) * N);
      headers[r] = static_cast<std::uint16_t>(kAllocated | r);
    }
  }
  owned_headers_ = std::move(headers);
  headers_ = owned_headers_.get();
  owns_headers_ = true;
  raw_ = std::move(raw);
  bytes_.reset();
  raw_count_ = kRows;
  byte_count_ = 0;
  unpacked_ = true;
}

template <int N>
void RowPackedBox<N>::compact() {
  std::vector<Voxel> content(std::size_t{kRows} * N);
  std::vector<Classified> classes(kRows);
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const int r = y * N + z;
      read_row_into(y, z, content.data() + std::size_t(r) * N);
      classes[r] = classify(content.data() + std::size_t(r) * N);
    }
  }
  unpacked_ = false;
  repacks_ = 0;
  rebuild_rect(0, N, 0, N, content.data(), classes.data());
}

template <int N>
std::size_t RowPackedBox<N>::heap_bytes() const {
  return (owns_headers_ ? sizeof(std::uint16_t) * kRows : 0) + sizeof(Voxel) * std::size_t{raw_count_} * N +
         std::size_t{byte_count_} * N;
}

template <int N>
RowPackedStats RowPackedBox<N>::stats() const {
  RowPackedStats s;
  s.raw_rows = raw_count_;
  s.byte_rows = byte_count_;
  s.uniform_rows = static_cast<std::size_t>(kRows) - raw_count_ - byte_count_;
  return s;
}

}  // namespace terrane
