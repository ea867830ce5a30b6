// Template definitions for RowPackedBox<N>; included by row_packed_box.h only.
#pragma once

#include <algorithm>
#include <bit>
#include <cstring>
#include <vector>

namespace terrane {

template <int N>
RowPackedBox<N>::RowPackedBox(Material fill) : headers_(row_packed_detail::uniform_headers(N, fill)) {}

template <int N>
RowPackedBox<N> RowPackedBox<N>::clone() const {
  RowPackedBox copy(kAir);
  copy.shift_ = shift_;
  // A copy starts its own budget: a chunk cloned and edited every tick
  // would otherwise spend one budget over its whole life and unpack.
  copy.repacks_ = 0;
  copy.data_bytes_ = data_bytes_;
  if (owns_headers_) {
    copy.owned_headers_ = std::make_unique<std::uint16_t[]>(header_words());
    std::memcpy(copy.owned_headers_.get(), headers_, sizeof(std::uint16_t) * header_words());
    copy.headers_ = copy.owned_headers_.get();
    copy.owns_headers_ = true;
  } else {
    copy.headers_ = headers_;
  }
  if (data_bytes_ > 0) {
    copy.data_ = std::make_unique<std::uint8_t[]>(data_bytes_);
    std::memcpy(copy.data_.get(), data_.get(), data_bytes_);
  }
  return copy;
}

template <int N>
void RowPackedBox<N>::read_row_into(int y, int z, Voxel* out) const {
  Row scratch;
  std::memcpy(out, read_row(y, z, scratch), sizeof(Voxel) * N);
}

template <int N>
std::size_t RowPackedBox<N>::header_words() const {
  const auto* map = reinterpret_cast<const std::uint8_t*>(headers_);
  std::size_t units = 0;
  for (int y = 0; y < N; ++y)
    if (!(map[y] & 0x80)) units += (map[y] & kWideLayer) ? 2 : 1;
  return N / 2 + units * kUnitWords;
}

template <int N>
void RowPackedBox<N>::adopt_headers(const std::uint16_t* all, const std::int32_t* narrow_base,
                                    const std::uint8_t* narrow_bytes) {
  std::uint8_t map[N];
  int units = 0;
  for (int y = 0; y < N; ++y) {
    const std::uint16_t first = all[y * N];
    const bool alike = !(first & kAllocated) && std::all_of(all + y * N, all + (y + 1) * N,
                                                             [&](std::uint16_t h) { return h == first; });
    if (alike) {
      map[y] = static_cast<std::uint8_t>(0x80 | (first & 63));
    } else if (narrow_base != nullptr && narrow_base[2 * y] >= 0) {
      map[y] = static_cast<std::uint8_t>(units);
      units += 1;
    } else {
      map[y] = static_cast<std::uint8_t>(kWideLayer | units);
      units += 2;
    }
  }
  auto owned = std::make_unique<std::uint16_t[]>(std::size_t{N / 2} + std::size_t(units) * kUnitWords);
  std::memcpy(owned.get(), map, N);
  for (int y = 0; y < N; ++y) {
    if (map[y] & 0x80) continue;
    std::uint16_t* slot = owned.get() + N / 2 + (map[y] & 63) * kUnitWords;
    if (map[y] & kWideLayer) {
      std::memcpy(slot, all + y * N, sizeof(std::uint16_t) * N);
    } else {
      slot[0] = static_cast<std::uint16_t>(narrow_base[2 * y]);
      slot[1] = static_cast<std::uint16_t>(narrow_base[2 * y + 1]);
      std::memcpy(slot + 2, narrow_bytes + y * N, N);
    }
  }
  owned_headers_ = std::move(owned);
  headers_ = owned_headers_.get();
  owns_headers_ = true;
}

template <int N>
void RowPackedBox<N>::become_uniform(Material m) {
  owned_headers_.reset();
  data_.reset();
  data_bytes_ = 0;
  owns_headers_ = false;
  shift_ = 0;
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

  if (unpacked()) {
    // Every row is a raw record of its own: write in place, never repack.
    for (int i = 0; i < count; ++i)
      std::memcpy(data_.get() + (static_cast<std::uint32_t>(header(row_of(i)) & kOffsetMask) << shift_),
                  content.data() + static_cast<std::size_t>(i) * N, sizeof(Voxel) * N);
    return;
  }

  if (count == kRows) {
    // The whole box: choose its palette table afresh.
    compact_from(content.data());
    return;
  }
  row_packed_detail::PaletteTable table(this->table());

  // Stage 2: encode the rows against the box's table and see whether storage
  // has to move.
  thread_local std::vector<std::uint8_t> records;
  thread_local std::vector<std::uint16_t> sizes;
  records.resize(static_cast<std::size_t>(count) * 2 * N);
  sizes.resize(static_cast<std::size_t>(count));
  bool in_place = true;
  bool headers_change = false;
  bool records_change = false;
  for (int i = 0; i < count; ++i) {
    const Voxel* row = content.data() + static_cast<std::size_t>(i) * N;
    std::uint8_t* rec = records.data() + static_cast<std::size_t>(i) * 2 * N;
    sizes[i] = static_cast<std::uint16_t>(row_packed_detail::encode_row(row, N, table, rec));
    const std::uint16_t h = header(row_of(i));
    if (sizes[i] == 0) {
      if (h & kAllocated) in_place = false;
      else if ((h & 63) != row[0].material) headers_change = true;
    } else if (!(h & kAllocated) || row_packed_detail::record_bytes(record(h), this->table(), N) < sizes[i] ||
               (rec[0] >= row_packed_detail::kKindIndex &&
                (rec[0] & row_packed_detail::kPaletteMask) == row_packed_detail::kInlinePalette &&
                table.fits(rec[1] + 1))) {  // an inline palette's first byte is P - 1
      // A record that grows, or whose palette could join the table, is rebuilt.
      in_place = false;
    } else if (std::memcmp(record(h), rec, static_cast<std::size_t>(sizes[i])) != 0) {
      records_change = true;
    }
  }
  if (in_place && records_change) {
    // A changed record may be overwritten only if no other row shares it.
    thread_local std::vector<std::uint8_t> refs;
    refs.assign(data_bytes_, 0);
    for (int r = 0; r < kRows; ++r)
      if (const std::uint16_t h = header(r); h & kAllocated) refs[h & kOffsetMask] += refs[h & kOffsetMask] < 2;
    for (int i = 0; i < count && in_place; ++i) {
      const std::uint16_t h = header(row_of(i));
      if (sizes[i] > 0 && refs[h & kOffsetMask] > 1) in_place = false;
    }
  }

  if (!in_place) {
    // Stage 3a: one reallocation for the whole write.
    rebuild_rect(y0, y1, z0, z1, content.data(), table, true);
    if (++repacks_ > kRepackBudget) unpack_all();
    return;
  }
  if (headers_change) {
    // Uniform rows changed material: the headers are laid out again, with
    // the records (a narrow layer's reach is checked there); records did not
    // grow, so this is not counted as a repack.
    rebuild_rect(y0, y1, z0, z1, content.data(), table, true);
    return;
  }

  // Stage 3b: no record grows, nothing shared: write in place (a shorter
  // record leaves its tail unused until the next rebuild).
  for (int i = 0; i < count; ++i)
    if (sizes[i] > 0)
      std::memcpy(data_.get() + (header(row_of(i)) & kOffsetMask), records.data() + static_cast<std::size_t>(i) * 2 * N,
                  std::size_t{sizes[i]});
}

template <int N>
void RowPackedBox<N>::rebuild_rect(int y0, int y1, int z0, int z1, const Voxel* content,
                                   row_packed_detail::PaletteTable& table, bool grow_table,
                                   const row_packed_detail::RowSummary* known) {
  const int nz = z1 - z0;
  const std::uint8_t* old_table = this->table();
  // Touched rows are summarised once; they may add their palettes to the
  // table while it has room.
  thread_local std::vector<row_packed_detail::RowSummary> made;
  if (known == nullptr) {
    made.resize(static_cast<std::size_t>((y1 - y0) * nz));
    for (int i = 0; i < (y1 - y0) * nz; ++i)
      made[static_cast<std::size_t>(i)] = row_packed_detail::summarize_row(content + std::size_t(i) * N, N);
  }
  const row_packed_detail::RowSummary* summaries = known != nullptr ? known : made.data();
  for (int i = 0; i < (y1 - y0) * nz; ++i) {
    const row_packed_detail::RowSummary& s = summaries[i];
    if (grow_table && !s.uniform && s.p <= row_packed_detail::kMaxPalette &&
        !table.serves(s.mask, s.p, row_packed_detail::takes_runs(s, N)))
      table.add(s.materials, s.p);
  }
  const std::size_t table_bytes = static_cast<std::size_t>(table.bytes());
  // New records go to a scratch buffer after the table (at most one raw
  // record per row), deduplicated through an open-addressing table of
  // offsets + 1.
  constexpr std::size_t kTableSize = 2 * kRows;  // power of two, load <= 1/2
  thread_local std::vector<std::uint8_t> buf;
  thread_local std::vector<std::uint16_t> slots;
  // (At most one record or copy per row.)
  buf.resize(table_bytes + std::size_t{kRows} * 2 * N);
  slots.assign(kTableSize, 0);
  table.write(buf.data());
  auto headers = std::make_unique<std::uint16_t[]>(kRows);
  std::size_t used = table_bytes;
  bool all_uniform_same = true;
  std::uint8_t encoded[2 * N];
  // Narrow layers (see the header comment): a record stored more than
  // kReuseReach bytes before the layer's own records is copied rather than
  // shared, so that the layer's records stay within one byte of its base.
  // (64: the least memory over the real regions and the default world
  // against 16, 32 and 96, and than no copies at all; 2026-11-29.)
  constexpr std::size_t kReuseReach = 64;
  std::int32_t narrow_base[2 * N];
  std::uint8_t narrow_bytes[kRows];
  for (int y = 0; y < N; ++y) {
    const std::size_t layer_start = used;
    for (int z = 0; z < N; ++z) {
      const int r = y * N + z;
      const bool touched = y >= y0 && y < y1 && z >= z0 && z < z1;
      const std::uint8_t* src = nullptr;
      int size = 0;
      if (touched) {
        const std::size_t i = static_cast<std::size_t>((y - y0) * nz + (z - z0));
        const Voxel* row = content + i * N;
        size = row_packed_detail::encode_row(row, N, summaries[i], table, encoded);
        if (size == 0) headers[r] = row[0].material;
        src = encoded;
      } else if (const std::uint16_t h = header(r); !(h & kAllocated)) {
        headers[r] = h;
      } else {
        src = record(h);
        size = row_packed_detail::record_bytes(src, old_table, N);
      }
      if (size > 0) {
        std::uint32_t hash = 2166136261u;  // FNV-1a
        for (int k = 0; k < size; ++k) hash = (hash ^ src[k]) * 16777619u;
        for (std::size_t slot = hash & (kTableSize - 1);; slot = (slot + 1) & (kTableSize - 1)) {
          const std::uint16_t e = slots[slot];
          const std::uint8_t* cand = e == 0 ? nullptr : buf.data() + std::size_t{e - 1u};
          const bool same = cand != nullptr && row_packed_detail::record_bytes(cand, buf.data(), N) == size &&
                            std::memcmp(cand, src, static_cast<std::size_t>(size)) == 0;
          if (e != 0 && !same) continue;  // another record's slot
          if (same && std::size_t{e - 1u} + kReuseReach >= layer_start) {
            headers[r] = static_cast<std::uint16_t>(kAllocated | (e - 1u));
            break;
          }
          // A new record: at a free slot, or a copy of one too far back for
          // this layer, which later rows share.
          std::memcpy(buf.data() + used, src, static_cast<std::size_t>(size));
          if (used > kOffsetMask) {
            // Beyond 15-bit byte offsets: this box is better unpacked.
            unpack_from(y0, y1, z0, z1, content);
            return;
          }
          headers[r] = static_cast<std::uint16_t>(kAllocated | used);
          slots[slot] = static_cast<std::uint16_t>(used + 1);
          used += static_cast<std::size_t>(size);
          break;
        }
      }
      all_uniform_same &= headers[r] == headers[0];
    }
    // The layer is narrow if, in each half, its records start within 191
    // bytes of the first.
    narrow_base[2 * y] = narrow_base[2 * y + 1] = -1;
    const std::uint16_t* layer = headers.get() + y * N;
    std::size_t lo[2] = {~std::size_t{0}, ~std::size_t{0}}, hi[2] = {0, 0};
    for (int z = 0; z < N; ++z) {
      if (!(layer[z] & kAllocated)) continue;
      const std::size_t at = layer[z] & kOffsetMask;
      const int half = z / (N / 2);
      lo[half] = std::min(lo[half], at);
      hi[half] = std::max(hi[half], at);
    }
    // (A half without records has no base: 0.)
    for (int half = 0; half < 2; ++half)
      if (hi[half] < lo[half]) lo[half] = hi[half] = 0;
    if (hi[0] - lo[0] >= kNarrowUniform || hi[1] - lo[1] >= kNarrowUniform) continue;
    narrow_base[2 * y] = static_cast<std::int32_t>(lo[0]);
    narrow_base[2 * y + 1] = static_cast<std::int32_t>(lo[1]);
    for (int z = 0; z < N; ++z) {
      narrow_bytes[y * N + z] = static_cast<std::uint8_t>(
          (layer[z] & kAllocated) ? (layer[z] & kOffsetMask) - lo[z / (N / 2)] : kNarrowUniform + (layer[z] & 63));
    }
  }
  if (all_uniform_same && !(headers[0] & kAllocated)) {
    become_uniform(static_cast<Material>(headers[0] & 63));
    return;
  }
  adopt_headers(headers.get(), narrow_base, narrow_bytes);
  shift_ = 0;
  if (used == table_bytes) {
    data_.reset();
    data_bytes_ = 0;
    return;
  }
  data_bytes_ = static_cast<std::uint32_t>(used) + kPadBytes;
  data_ = std::make_unique<std::uint8_t[]>(data_bytes_);  // value-initialised: padding is zero
  std::memcpy(data_.get(), buf.data(), used);
}

template <int N>
void RowPackedBox<N>::unpack_from(int y0, int y1, int z0, int z1, const Voxel* content) {
  const int nz = z1 - z0;
  auto headers = std::make_unique<std::uint16_t[]>(kRows);
  const std::uint32_t bytes = std::uint32_t{kRows} * N * sizeof(Voxel) + kPadBytes;
  auto data = std::make_unique<std::uint8_t[]>(bytes);
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const int r = y * N + z;
      Voxel* dst = reinterpret_cast<Voxel*>(data.get()) + std::size_t(r) * N;
      if (y >= y0 && y < y1 && z >= z0 && z < z1)
        std::memcpy(dst, content + static_cast<std::size_t>((y - y0) * nz + (z - z0)) * N, sizeof(Voxel) * N);
      else
        read_row_into(y, z, dst);
      headers[r] = static_cast<std::uint16_t>(kAllocated | (r * N));  // in 2-byte units: shift_ = 1
    }
  }
  adopt_headers(headers.get());
  data_ = std::move(data);
  data_bytes_ = bytes;
  shift_ = 1;
}

template <int N>
void RowPackedBox<N>::unpack_all() {
  unpack_from(0, 0, 0, 0, nullptr);
}

template <int N>
void RowPackedBox<N>::compact_from(const Voxel* content) {
  // The rows' material sets by the bytes their own palette would save
  // inline (1 + P per row using it), and whether their rows take run or
  // index records with it (occupancy sections cost the same in both).
  struct Candidate {
    int saving = 0;
    int p = 0;
    std::uint64_t mask = 0;
    bool runs = false, index = false;
  };
  std::vector<Candidate> candidates;
  thread_local std::vector<row_packed_detail::RowSummary> summaries;
  summaries.resize(kRows);
  for (int r = 0; r < kRows; ++r) {
    const row_packed_detail::RowSummary& s = summaries[static_cast<std::size_t>(r)] =
        row_packed_detail::summarize_row(content + std::size_t(r) * N, N);
    if (s.uniform || s.p > row_packed_detail::kMaxPalette) continue;
    auto it = std::find_if(candidates.begin(), candidates.end(), [&](const Candidate& c) { return c.mask == s.mask; });
    if (it == candidates.end()) {
      candidates.push_back({0, s.p, s.mask});
      it = candidates.end() - 1;
    }
    it->saving += 1 + s.p;
    const bool runs = row_packed_detail::takes_runs(s, N);
    (runs ? it->runs : it->index) = true;
  }
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const Candidate& a, const Candidate& b) { return a.saving > b.saving; });
  // The table's palettes. A palette of `size` materials serves a set's rows
  // at no extra cost if it holds the set and its rows' records keep their
  // size: at most 8 materials for run records, the same index width for
  // index records.
  struct Chosen {
    std::uint64_t mask = 0;
    bool runs = false, index = false;  // of the sets it serves
  };
  using row_packed_detail::keeps_record_size;
  // Each set, most used first, takes the cheapest of: a palette already
  // serving it (0 bytes), growing a palette by its missing materials (one
  // byte each, while the sets that palette serves keep their records'
  // sizes), a palette of its own (2 + P bytes, while the table has room),
  // or its palette inline in each of its rows.
  std::vector<Chosen> chosen;
  int table_bytes = 1;
  for (const Candidate& c : candidates) {
    auto serves = [&](const Chosen& t) {
      return (t.mask & c.mask) == c.mask && keeps_record_size(c.p, c.runs, c.index, std::popcount(t.mask));
    };
    if (std::any_of(chosen.begin(), chosen.end(), serves)) continue;
    int grow_cost = c.saving;
    std::size_t grow = chosen.size();
    for (std::size_t i = 0; i < chosen.size(); ++i) {
      const Chosen& t = chosen[i];
      const int before = std::popcount(t.mask), after = std::popcount(t.mask | c.mask);
      // The palette's own sets keep their sizes if it keeps its index width
      // (index records) and at most 8 materials (run records).
      if (!keeps_record_size(c.p, c.runs, c.index, after) || !keeps_record_size(before, t.runs, t.index, after) ||
          table_bytes + after - before > row_packed_detail::kMaxTableBytes)
        continue;
      if (after - before < grow_cost) {
        grow_cost = after - before;
        grow = i;
      }
    }
    const int own_cost = 2 + c.p;
    const bool own_fits = static_cast<int>(chosen.size()) < row_packed_detail::kMaxTablePalettes &&
                          table_bytes + own_cost <= row_packed_detail::kMaxTableBytes;
    if (own_fits && own_cost <= c.saving && own_cost <= grow_cost) {
      chosen.push_back({c.mask, c.runs, c.index});
      table_bytes += own_cost;
    } else if (grow < chosen.size()) {
      Chosen& t = chosen[grow];
      t.mask |= c.mask;
      t.runs |= c.runs;
      t.index |= c.index;
      table_bytes += grow_cost;
    }
  }
  row_packed_detail::PaletteTable table;
  for (const Chosen& t : chosen) {
    Material materials[row_packed_detail::kMaxPalette];
    int p = 0;
    for (std::uint64_t rest = t.mask; rest != 0; rest &= rest - 1) materials[p++] = static_cast<Material>(std::countr_zero(rest));
    table.add(materials, p);
  }
  shift_ = 0;
  repacks_ = 0;
  rebuild_rect(0, N, 0, N, content, table, false, summaries.data());
}

template <int N>
void RowPackedBox<N>::compact() {
  std::vector<Voxel> content(std::size_t{kRows} * N);
  for (int r = 0; r < kRows; ++r) read_row_into(r / N, r % N, content.data() + std::size_t(r) * N);
  compact_from(content.data());
}

template <int N>
void RowPackedBox<N>::write_image(std::vector<std::uint8_t>& out) const {
  // The slots' narrow bytes are written as the words hold them in memory,
  // which is the image's byte order on little-endian hosts only.
  static_assert(std::endian::native == std::endian::little, "chunk images assume a little-endian host");
  if (!owns_headers_) {
    out.push_back(0);
    out.push_back(static_cast<std::uint8_t>(uniform_material()));
    return;
  }
  out.push_back(1);
  const auto* map = reinterpret_cast<const std::uint8_t*>(headers_);
  out.insert(out.end(), map, map + N);
  const std::size_t words = header_words();
  for (std::size_t i = N / 2; i < words; ++i) append_le16(out, headers_[i]);
  const std::uint32_t d = data_bytes_ > 0 ? data_bytes_ - kPadBytes : 0;
  append_le16(out, static_cast<std::uint16_t>(d));
  if (d > 0) out.insert(out.end(), data_.get(), data_.get() + d);
}

template <int N>
Result<RowPackedBox<N>> RowPackedBox<N>::read_image(std::span<const std::uint8_t> in, std::size_t& pos) {
  using row_packed_detail::checked_record_bytes;
  using row_packed_detail::checked_table_bytes;
  constexpr auto kTruncated = DecodeErrorCode::kTruncated;
  constexpr auto kInvalid = DecodeErrorCode::kInvalidValue;
  if (pos >= in.size()) return DecodeError{kTruncated, pos, "row-packed image: form"};
  const std::uint8_t form = in[pos];
  if (form == 0) {
    if (pos + 2 > in.size()) return DecodeError{kTruncated, pos + 1, "row-packed image: uniform material"};
    if (in[pos + 1] >= kMaterialCount) return DecodeError{kInvalid, pos + 1, "row-packed image: material above 63"};
    const auto m = static_cast<Material>(in[pos + 1]);
    pos += 2;
    return RowPackedBox(m);
  }
  if (form != 1) return DecodeError{kInvalid, pos, "row-packed image: form not 0 or 1"};
  std::size_t at = pos + 1;
  if (in.size() - at < std::size_t{N}) return DecodeError{kTruncated, at, "row-packed image: layer map"};
  const std::uint8_t* map = in.data() + at;
  int units = 0;
  bool one_material = true;
  for (int y = 0; y < N; ++y) {
    const std::uint8_t b = map[y];
    if (b & 0x80) {
      if (b & 0x40) return DecodeError{kInvalid, at + y, "row-packed image: uniform layer byte above 0xBF"};
      one_material &= b == map[0];
      continue;
    }
    one_material = false;
    if ((b & 63) != units) return DecodeError{kInvalid, at + y, "row-packed image: layer slots out of order"};
    units += (b & kWideLayer) ? 2 : 1;
  }
  if (one_material) return DecodeError{kInvalid, at, "row-packed image: a packed box of one material"};
  at += N;
  const std::size_t slot_words = static_cast<std::size_t>(units) * kUnitWords;
  if (in.size() - at < 2 * slot_words) return DecodeError{kTruncated, at, "row-packed image: layer slots"};
  auto owned = std::make_unique<std::uint16_t[]>(N / 2 + slot_words);
  std::memcpy(owned.get(), map, N);
  for (std::size_t i = 0; i < slot_words; ++i) owned[N / 2 + i] = load_le16(in.data() + at + 2 * i);
  at += 2 * slot_words;
  if (in.size() - at < 2) return DecodeError{kTruncated, at, "row-packed image: data length"};
  const std::size_t d = load_le16(in.data() + at);
  if (d > std::size_t{kOffsetMask} + 2 * N) return DecodeError{DecodeErrorCode::kOverLimit, at, "row-packed image: data length"};
  at += 2;
  if (in.size() - at < d) return DecodeError{kTruncated, at, "row-packed image: data"};
  const std::uint8_t* data = in.data() + at;
  int table_bytes = 0;
  if (d > 0 && (table_bytes = checked_table_bytes(data, d)) < 0)
    return DecodeError{kInvalid, at, "row-packed image: palette table"};

  RowPackedBox box(kAir);
  box.owned_headers_ = std::move(owned);
  box.headers_ = box.owned_headers_.get();
  box.owns_headers_ = true;
  if (d > 0) {
    box.data_bytes_ = static_cast<std::uint32_t>(d) + kPadBytes;
    box.data_ = std::make_unique<std::uint8_t[]>(box.data_bytes_);  // value-initialised: padding is zero
    std::memcpy(box.data_.get(), data, d);
  }
  // Every row's header, and each record its rows start (once, however many
  // rows share it). Records may not overlap: a write in place (modify_rows)
  // rewrites one record's bytes, which must be no other record's. Bit i of
  // starts: a record starts at byte i; of covered: byte i is a record's.
  const std::size_t words = (d + 63) / 64;
  thread_local std::vector<std::uint64_t> starts, covered;
  starts.assign(words, 0);
  covered.assign(words, 0);
  const auto bit = [](const std::vector<std::uint64_t>& v, std::size_t i) { return (v[i / 64] >> (i % 64)) & 1; };
  bool any_record = false;
  for (int y = 0; y < N; ++y) {
    if (map[y] & 0x80) continue;
    const std::uint16_t* slot = box.headers_ + N / 2 + (map[y] & 63) * kUnitWords;
    const bool wide = map[y] & kWideLayer;
    const std::size_t slot_at = pos + 1 + N + 2 * static_cast<std::size_t>((map[y] & 63) * kUnitWords);
    const std::uint16_t first = box.header(y, 0);
    bool alike = true;
    for (int z = 0; z < N; ++z) {
      // Where row z's header is in the image: its word, or its narrow byte.
      const std::size_t header_at = wide ? slot_at + 2 * z : slot_at + 4 + z;
      if (wide) {
        if (!(slot[z] & kAllocated) && slot[z] >= kMaterialCount)
          return DecodeError{kInvalid, header_at, "row-packed image: uniform row above material 63"};
      } else {
        const unsigned b = reinterpret_cast<const std::uint8_t*>(slot + 2)[z];
        if (b < kNarrowUniform && slot[z / (N / 2)] + b > kOffsetMask)
          return DecodeError{kInvalid, header_at, "row-packed image: narrow layer offset beyond 15 bits"};
      }
      const std::uint16_t h = box.header(y, z);
      alike &= h == first;
      if (!(h & kAllocated)) continue;
      any_record = true;
      const std::size_t off = h & kOffsetMask;
      if (off < static_cast<std::size_t>(table_bytes) || off >= d)
        return DecodeError{kInvalid, header_at, "row-packed image: row record outside the data"};
      if (bit(starts, off)) continue;
      // (No record is longer than a raw one: the writer takes the smallest.)
      const int bytes = checked_record_bytes(data + off, d - off, data, N);
      if (bytes < 0 || bytes > 2 * N) return DecodeError{kInvalid, at + off, "row-packed image: row record"};
      starts[off / 64] |= std::uint64_t{1} << (off % 64);
      // Its bytes [off, off + bytes), at most 64: in one word or two.
      for (std::size_t from = off, end = off + static_cast<std::size_t>(bytes); from < end;) {
        const std::size_t w = from / 64, lo = from % 64, n = std::min<std::size_t>(end - from, 64 - lo);
        const std::uint64_t mask = (n == 64 ? ~std::uint64_t{0} : ((std::uint64_t{1} << n) - 1)) << lo;
        if (covered[w] & mask) return DecodeError{kInvalid, at + off, "row-packed image: a record inside another"};
        covered[w] |= mask;
        from += n;
      }
    }
    if (alike && !(first & kAllocated))
      return DecodeError{kInvalid, slot_at, "row-packed image: a layer slot whose rows are alike"};
  }
  if (d > 0 && !any_record) return DecodeError{kInvalid, at, "row-packed image: data without records"};
  pos = at + d;
  return box;
}

template <int N>
std::size_t RowPackedBox<N>::heap_bytes() const {
  return (owns_headers_ ? sizeof(std::uint16_t) * header_words() : 0) + std::size_t{data_bytes_};
}

template <int N>
RowPackedStats RowPackedBox<N>::stats() const {
  RowPackedStats s;
  s.data_bytes = data_bytes_;
  if (data_ && !unpacked()) s.table_bytes = static_cast<std::size_t>(row_packed_detail::PaletteTable(data_.get()).bytes());
  std::vector<bool> seen(data_bytes_, false);
  for (int r = 0; r < kRows; ++r) {
    const std::uint16_t h = header(r);
    if (!(h & kAllocated)) {
      ++s.uniform_rows;
      continue;
    }
    const std::uint8_t tag = record(h)[0];
    if (tag < row_packed_detail::kKindIndex) {
      ++s.raw_rows;
      ++s.occupancy_rows;
    } else {
      s.run_rows += (tag & row_packed_detail::kKindMask) == row_packed_detail::kKindRuns;
      s.index_rows += (tag & row_packed_detail::kKindMask) == row_packed_detail::kKindIndex;
      s.occupancy_rows += (tag & row_packed_detail::kTagOccupancy) != 0;
    }
    if (!seen[h & kOffsetMask]) {
      const int bytes = row_packed_detail::record_bytes(record(h), table(), N);
      if (tag < row_packed_detail::kKindIndex) s.raw_bytes += static_cast<std::size_t>(bytes);
      else if ((tag & row_packed_detail::kKindMask) == row_packed_detail::kKindRuns) s.run_bytes += static_cast<std::size_t>(bytes);
      else s.index_bytes += static_cast<std::size_t>(bytes);
      if (tag >= row_packed_detail::kKindIndex && (tag & row_packed_detail::kPaletteMask) == row_packed_detail::kInlinePalette)
        s.inline_palette_bytes += 2u + record(h)[1];
    }
    s.shared_rows += seen[h & kOffsetMask];
    seen[h & kOffsetMask] = true;
  }
  const auto* map = reinterpret_cast<const std::uint8_t*>(headers_);
  for (int y = 0; y < N && owns_headers_; ++y) {
    if (map[y] & 0x80) continue;
    s.wide_layers += (map[y] & kWideLayer) != 0;
    s.narrow_layers += (map[y] & kWideLayer) == 0;
  }
  return s;
}

}  // namespace terrane
