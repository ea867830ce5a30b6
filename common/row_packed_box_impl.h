// Template definitions for RowPackedBox<N>; included by row_packed_box.h only.
#pragma once

#include <algorithm>
#include <bit>
#include <cstring>
#include <vector>

namespace terrane {

template <int N>
RowPackedBox<N>::RowPackedBox(Material fill)
    : headers_(row_packed_detail::uniform_headers(N, fill)) {}

template <int N>
RowPackedBox<N> RowPackedBox<N>::clone() const {
  RowPackedBox copy(kAir);
  copy.entry_shift_ = entry_shift_;
  copy.repacks_ = repacks_;
  copy.data_units_ = data_units_;
  copy.raw_base_ = raw_base_;
  if (owned_headers_) {
    copy.owned_headers_ = std::make_unique<std::uint16_t[]>(kRows);
    std::memcpy(copy.owned_headers_.get(), headers_, sizeof(std::uint16_t) * kRows);
    copy.headers_ = copy.owned_headers_.get();
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
int RowPackedBox<N>::stored_encoding(std::uint16_t h, std::uint8_t* out) const {
  if (!(h & kAllocated)) return 0;
  if (!(h & kPaletteRow)) {
    std::memcpy(out, raw_record(h), sizeof(Voxel) * N);
    return 2 * N;
  }
  const std::uint8_t* rec = bytes() + (h & kOffsetMask);
  const std::uint8_t* entry = entry_of(rec);
  const int eb = row_packed_detail::entry_bytes(entry[0]);
  const int g = row_packed_detail::index_bytes(entry[0], N);
  std::memcpy(out, entry, static_cast<std::size_t>(eb));
  std::memcpy(out + eb, indices_of(rec, entry), static_cast<std::size_t>(g));
  return eb + g;
}

template <int N>
std::uint16_t* RowPackedBox<N>::mutable_headers() {
  if (!owned_headers_) {
    owned_headers_ = std::make_unique<std::uint16_t[]>(kRows);
    std::memcpy(owned_headers_.get(), headers_, sizeof(std::uint16_t) * kRows);
    headers_ = owned_headers_.get();
  }
  return owned_headers_.get();
}

template <int N>
void RowPackedBox<N>::become_uniform(Material m) {
  owned_headers_.reset();
  data_.reset();
  data_units_ = 0;
  raw_base_ = 0;
  entry_shift_ = kPackedShift;
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
      std::memcpy(raw_record_mut(headers_[row_of(i)]), content.data() + static_cast<std::size_t>(i) * N,
                  sizeof(Voxel) * N);
    return;
  }

  // Stage 2: encode the rows and see whether storage has to move. A palette
  // row stays in place only with its current table entry and index width.
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
    } else if (!(h & kAllocated)) {
      in_place = false;
    } else if (rec[0] < row_packed_detail::kPaletteTag) {
      if (h & kPaletteRow) in_place = false;
      else if (std::memcmp(raw_record(h), rec, sizeof(Voxel) * N) != 0) records_change = true;
    } else if (!(h & kPaletteRow)) {
      in_place = false;
    } else {
      const std::uint8_t* stored = bytes() + (h & kOffsetMask);
      const std::uint8_t* entry = entry_of(stored);
      if constexpr (kInlinePalettes) {
        const int eb = row_packed_detail::entry_bytes(rec[0]);
        if (entry[0] != rec[0] || std::memcmp(entry, rec, static_cast<std::size_t>(eb)) != 0) {
          in_place = false;
        } else if (std::memcmp(indices_of(stored, entry), rec + eb,
                               static_cast<std::size_t>(row_packed_detail::index_bytes(rec[0], N))) != 0) {
          records_change = true;
        }
      } else {
        // Any row whose voxels are all in the stored entry's (possibly
        // merged) palette keeps the entry.
        std::uint8_t idx[2 * N];
        if (!row_packed_detail::encode_with_entry(row, N, entry, idx)) {
          in_place = false;
        } else if (std::memcmp(indices_of(stored, entry), idx,
                               static_cast<std::size_t>(row_packed_detail::index_bytes(entry[0], N))) != 0) {
          records_change = true;
        }
      }
    }
  }
  if (in_place && records_change) {
    // A changed record may be overwritten only if no other row shares it.
    thread_local std::vector<std::uint8_t> refs;
    refs.assign(std::size_t{kAllocated}, 0);
    for (int r = 0; r < kRows; ++r)
      if (headers_[r] & kAllocated) refs[headers_[r] & 0x7FFF] += refs[headers_[r] & 0x7FFF] < 2;
    for (int i = 0; i < count && in_place; ++i) {
      const std::uint16_t h = headers_[row_of(i)];
      if (sizes[i] > 0 && refs[h & 0x7FFF] > 1) in_place = false;
    }
  }

  if (!in_place) {
    // Stage 3a: one reallocation for the whole write.
    rebuild_rect(y0, y1, z0, z1, records.data(), sizes.data(), materials.data());
    if (++repacks_ > kRepackBudget) unpack_all();
    return;
  }

  // Stage 3b: same entries and record sizes, nothing shared: write in place.
  std::uint16_t* headers = headers_change ? mutable_headers() : nullptr;
  for (int i = 0; i < count; ++i) {
    const int r = row_of(i);
    const std::uint8_t* rec = records.data() + static_cast<std::size_t>(i) * 2 * N;
    const std::uint16_t h = headers_[r];
    if (sizes[i] == 0) {
      if (headers != nullptr) headers[r] = materials[i];
    } else if (!(h & kPaletteRow)) {
      std::memcpy(raw_record_mut(h), rec, sizeof(Voxel) * N);
    } else {
      auto* stored = reinterpret_cast<std::uint8_t*>(data_.get()) + (h & kOffsetMask);
      if constexpr (kInlinePalettes) {
        const int eb = row_packed_detail::entry_bytes(rec[0]);
        std::memcpy(stored + eb, rec + eb, static_cast<std::size_t>(row_packed_detail::index_bytes(rec[0], N)));
      } else {
        row_packed_detail::encode_with_entry(content.data() + static_cast<std::size_t>(i) * N, N, entry_of(stored),
                                             stored + 1);
      }
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
  using namespace row_packed_detail;
  const int nz = z1 - z0;
  // Palette entries are interned into the new table and records are
  // deduplicated, each through an open-addressing table (load <= 1/2).
  constexpr std::size_t kRecordSlots = 2 * kRows;
  constexpr std::size_t kEntrySlots = 512;  // 2 · 256 entry ids
  thread_local std::vector<std::uint8_t> table;
  thread_local std::vector<std::uint8_t> pal;
  thread_local std::vector<Voxel> raw;
  thread_local std::vector<std::uint16_t> record_slots;
  thread_local std::vector<std::uint16_t> entry_slots;  // palette index + 1
  struct Palette {
    std::uint8_t original[1 + 2 * kMaxPalette];  // as encoded by the rows that use it
    std::uint8_t info;                           // width and occupancy bits of the info byte
    int p;
    Voxel voxels[kMaxPalette];                   // after merging (when target is itself)
    std::uint64_t materials;                     // bit per material in voxels
    int target;                                  // the palette it was merged into
    int id;                                      // table entry id of a chosen palette, or -1
  };
  thread_local std::vector<Palette> palettes;
  thread_local std::vector<int> order;
  thread_local std::vector<int> chosen;
  auto headers = std::make_unique<std::uint16_t[]>(kRows);
  bool any_palette = false;

  // One packing attempt with table entries in units of 1 << shift bytes;
  // false when the table would need more than 256 ids (retried with 8-byte
  // units; beyond that rows whose palette does not fit are stored raw).
  auto pack = [&](int shift, bool last) {
    const std::size_t unit = std::size_t{1} << shift;
    const std::size_t max_table = kInlinePalettes ? 0 : 256 * unit;
    // Record offsets must fit 14 bits after the table is put before them.
    const std::size_t max_palette = std::size_t{kOffsetMask} + 1 - max_table;
    table.clear();
    pal.clear();
    raw.clear();
    record_slots.assign(kRecordSlots, 0);
    entry_slots.assign(kEntrySlots, 0);
    any_palette = false;
    std::uint8_t own[2 * N];
    std::uint8_t rec[2 * N];
    Voxel decoded[N];
    // The encoding of row r (as encode_row) and its size.
    auto encoding = [&](int r) -> std::pair<const std::uint8_t*, int> {
      const int y = r / N, z = r % N;
      if (y >= y0 && y < y1 && z >= z0 && z < z1) {
        const int i = (y - y0) * nz + (z - z0);
        return {records + static_cast<std::size_t>(i) * 2 * N, sizes[i]};
      }
      return {own, stored_encoding(headers_[r], own)};
    };
    // Table boxes: the rows' distinct palettes, merged within an index width
    // where that saves bytes (a palette absorbs another when their union
    // still fits the width), then laid out in the table.
    auto find_palette = [&](const std::uint8_t* src) {
      const int eb = entry_bytes(src[0]);
      std::uint32_t hash = 2166136261u;  // FNV-1a
      for (int k = 0; k < eb; ++k) hash = (hash ^ src[k]) * 16777619u;
      std::size_t slot = hash & (kEntrySlots - 1);
      for (;; slot = (slot + 1) & (kEntrySlots - 1)) {
        const std::uint16_t e = entry_slots[slot];
        if (e == 0) break;
        const Palette& c = palettes[e - 1u];
        if (c.original[0] == src[0] && std::memcmp(c.original, src, static_cast<std::size_t>(eb)) == 0) break;
      }
      return slot;
    };
    if constexpr (!kInlinePalettes) {
      palettes.clear();
      for (int r = 0; r < kRows; ++r) {
        const auto [src, size] = encoding(r);
        if (size == 0 || src[0] < kPaletteTag) continue;
        const std::size_t slot = find_palette(src);
        if (entry_slots[slot] != 0) continue;
        if (palettes.size() + 1 >= kEntrySlots / 2) continue;  // stored raw below
        Palette pal_entry{};
        std::memcpy(pal_entry.original, src, static_cast<std::size_t>(entry_bytes(src[0])));
        pal_entry.info = static_cast<std::uint8_t>(src[0] & 0xF0);
        pal_entry.p = (src[0] & 15) + 1;
        const bool occ = (src[0] & kTagOccupancy) != 0;
        for (int j = 0; j < pal_entry.p; ++j) {
          pal_entry.voxels[j] = Voxel{src[1 + j], occ ? src[1 + pal_entry.p + j] : default_occupancy(src[1 + j])};
          pal_entry.materials |= std::uint64_t{1} << (src[1 + j] & 63);
        }
        pal_entry.target = static_cast<int>(palettes.size());
        palettes.push_back(pal_entry);
        entry_slots[slot] = static_cast<std::uint16_t>(palettes.size());
      }
      order.resize(palettes.size());
      for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
      std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return palettes[a].p > palettes[b].p; });
      chosen.clear();
      // Only default-occupancy palettes merge: their material sets are bit
      // masks, so trying every pair stays cheap.
      for (const int k : order) {
        Palette& e = palettes[k];
        const int code = e.info >> 6;
        const int max_p = code == 1 ? 2 : code == 2 ? 4 : (e.info & kTagThreeBits) ? 8 : 16;
        int best = -1;
        int best_added = e.p;  // merging must add fewer voxels than e has
        if (!(e.info & kTagOccupancy)) {
          for (const int c : chosen) {
            const Palette& t = palettes[c];
            if (t.info != e.info) continue;
            const int added = std::popcount(e.materials & ~t.materials);
            if (added < best_added && t.p + added <= max_p) {
              best = c;
              best_added = added;
            }
          }
        }
        if (best < 0) {
          chosen.push_back(k);
          continue;
        }
        Palette& t = palettes[best];
        for (int j = 0; j < e.p; ++j)
          if (!(t.materials >> (e.voxels[j].material & 63) & 1)) t.voxels[t.p++] = e.voxels[j];
        t.materials |= e.materials;
        e.target = best;
      }
      // Layout: each chosen palette gets an id (or -1: its rows go raw).
      for (const int c : chosen) {
        Palette& t = palettes[c];
        const bool occ = (t.info & kTagOccupancy) != 0;
        const std::size_t eb = 1 + static_cast<std::size_t>(t.p) * (occ ? 2 : 1);
        const std::size_t at = table.size();
        const std::size_t padded = (eb + unit - 1) & ~(unit - 1);
        if (at + padded > max_table) {
          if (!last) return false;
          t.id = -1;
          continue;
        }
        table.resize(at + padded, 0);
        std::uint8_t* out = table.data() + at;
        out[0] = static_cast<std::uint8_t>(t.info | (t.p - 1));
        for (int j = 0; j < t.p; ++j) {
          out[1 + j] = t.voxels[j].material;
          if (occ) out[1 + t.p + j] = t.voxels[j].occupancy;
        }
        t.id = static_cast<int>(at >> shift);
      }
    }
    for (int y = 0; y < N; ++y) {
      for (int z = 0; z < N; ++z) {
        const int r = y * N + z;
        const bool touched = y >= y0 && y < y1 && z >= z0 && z < z1;
        const std::uint8_t* src = nullptr;
        int size = 0;
        if (touched) {
          const int i = (y - y0) * nz + (z - z0);
          size = sizes[i];
          headers[r] = materials[i];
          src = records + static_cast<std::size_t>(i) * 2 * N;
        } else {
          headers[r] = headers_[r];
          size = stored_encoding(headers_[r], own);
          src = own;
        }
        if (size == 0) continue;
        if (src[0] >= kPaletteTag) {
          const unsigned info = src[0];
          const int eb = entry_bytes(info);
          const int g = index_bytes(info, N);
          std::size_t rb = static_cast<std::size_t>(size);
          bool fits = true;
          if constexpr (kInlinePalettes) {
            std::memcpy(rec, src, rb);
          } else {
            const std::uint16_t e = entry_slots[find_palette(src)];
            const int target = e == 0 ? -1 : palettes[e - 1u].target;
            const int id = target < 0 ? -1 : palettes[static_cast<std::size_t>(target)].id;
            fits = id >= 0;
            if (fits) {
              rec[0] = static_cast<std::uint8_t>(id);
              if (target == e - 1) {
                // Merging only appends to a palette: its own indices stay valid.
                std::memcpy(rec + 1, src + eb, static_cast<std::size_t>(g));
              } else {
                decode_palette_scalar(src, src + eb, decoded, N);
                encode_with_entry(decoded, N, table.data() + (std::size_t{rec[0]} << shift), rec + 1);
              }
              rb = 1 + static_cast<std::size_t>(g);
            }
          }
          if (fits && pal.size() + rb <= max_palette) {
            std::uint32_t hash = 2166136261u;
            for (std::size_t k = 0; k < rb; ++k) hash = (hash ^ rec[k]) * 16777619u;
            for (std::size_t slot = hash & (kRecordSlots - 1);; slot = (slot + 1) & (kRecordSlots - 1)) {
              const std::uint16_t e = record_slots[slot];
              if (e == 0) {
                const std::size_t at = pal.size();
                pal.insert(pal.end(), rec, rec + rb);
                record_slots[slot] = static_cast<std::uint16_t>(kAllocated | at);
                headers[r] = static_cast<std::uint16_t>(kAllocated | kPaletteRow | at);
                break;
              }
              if (!(e & kAllocated)) continue;  // a raw record
              // Same first byte (entry id or info): same length.
              const std::uint8_t* cand = pal.data() + (e & 0x7FFF);
              if (cand[0] == rec[0] && std::memcmp(cand, rec, rb) == 0) {
                headers[r] = static_cast<std::uint16_t>(kAllocated | kPaletteRow | (e & 0x7FFF));
                break;
              }
            }
            any_palette = true;
            continue;
          }
          // Table or palette area full: store the row raw.
          decode_palette_scalar(src, src + eb, decoded, N);
          src = reinterpret_cast<const std::uint8_t*>(decoded);
        }
        std::uint32_t hash = 2166136261u ^ 0x5Au;
        for (int k = 0; k < 2 * N; ++k) hash = (hash ^ src[k]) * 16777619u;
        for (std::size_t slot = hash & (kRecordSlots - 1);; slot = (slot + 1) & (kRecordSlots - 1)) {
          const std::uint16_t e = record_slots[slot];
          if (e == 0) {
            const std::size_t index = raw.size() / N;
            raw.resize(raw.size() + N);
            std::memcpy(raw.data() + index * N, src, sizeof(Voxel) * N);
            record_slots[slot] = static_cast<std::uint16_t>(index + 1);
            headers[r] = static_cast<std::uint16_t>(kAllocated | index);
            break;
          }
          if (e & kAllocated) continue;  // a palette record
          if (std::memcmp(raw.data() + std::size_t{e - 1u} * N, src, sizeof(Voxel) * N) == 0) {
            headers[r] = static_cast<std::uint16_t>(kAllocated | (e - 1u));
            break;
          }
        }
      }
    }
    return true;
  };
  // The stored encodings are read from this box while packing, so its
  // entry shift changes only afterwards.
  std::uint8_t shift = kPackedShift;
  if (!pack(shift, false)) pack(++shift, true);

  const std::uint16_t first = headers[0];
  if (!(first & kAllocated) && std::all_of(headers.get(), headers.get() + kRows, [&](std::uint16_t h) { return h == first; })) {
    become_uniform(static_cast<Material>(first & 63));
    return;
  }
  // Palette records follow the table: shift their offsets past it.
  const std::size_t table_bytes = table.size();
  for (int r = 0; r < kRows; ++r)
    if ((headers[r] & (kAllocated | kPaletteRow)) == (kAllocated | kPaletteRow))
      headers[r] = static_cast<std::uint16_t>(headers[r] + table_bytes);
  owned_headers_ = std::move(headers);
  headers_ = owned_headers_.get();
  entry_shift_ = shift;
  const std::size_t packed_units = (table_bytes + pal.size() + 1) / 2;
  const std::size_t units = packed_units + raw.size() + (any_palette ? kPadUnits : 0);
  raw_base_ = static_cast<std::uint16_t>(packed_units);
  data_units_ = static_cast<std::uint32_t>(units);
  if (units == 0) {
    data_.reset();
    return;
  }
  data_ = std::make_unique<Voxel[]>(units);  // value-initialised: padding is zero
  auto* out = reinterpret_cast<std::uint8_t*>(data_.get());
  if (table_bytes > 0) std::memcpy(out, table.data(), table_bytes);
  if (!pal.empty()) std::memcpy(out + table_bytes, pal.data(), pal.size());
  if (!raw.empty()) std::memcpy(data_.get() + packed_units, raw.data(), sizeof(Voxel) * raw.size());
}

template <int N>
void RowPackedBox<N>::unpack_all() {
  auto headers = std::make_unique<std::uint16_t[]>(kRows);
  const std::uint32_t units = std::uint32_t{kRows} * N;
  auto data = std::make_unique<Voxel[]>(units);
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const int r = y * N + z;
      read_row_into(y, z, data.get() + std::size_t(r) * N);
      headers[r] = static_cast<std::uint16_t>(kAllocated | r);
    }
  }
  owned_headers_ = std::move(headers);
  headers_ = owned_headers_.get();
  data_ = std::move(data);
  data_units_ = units;
  raw_base_ = 0;
  entry_shift_ = 0;
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
  entry_shift_ = kPackedShift;
  repacks_ = 0;
  rebuild_rect(0, N, 0, N, records.data(), sizes.data(), materials.data());
}

template <int N>
std::size_t RowPackedBox<N>::heap_bytes() const {
  return (owned_headers_ ? sizeof(std::uint16_t) * kRows : 0) + sizeof(Voxel) * std::size_t{data_units_};
}

template <int N>
RowPackedStats RowPackedBox<N>::stats() const {
  RowPackedStats s;
  s.data_bytes = sizeof(Voxel) * std::size_t{data_units_};
  std::vector<bool> seen(std::size_t{kAllocated}, false);
  for (int r = 0; r < kRows; ++r) {
    const std::uint16_t h = headers_[r];
    if (!(h & kAllocated)) {
      ++s.uniform_rows;
      continue;
    }
    if (!(h & kPaletteRow)) {
      ++s.raw_rows;
    } else {
      const std::uint8_t* rec = bytes() + (h & kOffsetMask);
      const std::uint8_t info = entry_of(rec)[0];
      ++s.palette_rows;
      if (info & row_packed_detail::kTagOccupancy) ++s.raw_rows;
      else ++s.byte_rows;
    }
    s.shared_rows += seen[h & 0x7FFF];
    seen[h & 0x7FFF] = true;
  }
  return s;
}

}  // namespace terrane
