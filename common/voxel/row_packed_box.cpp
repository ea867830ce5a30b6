#include "common/voxel/row_packed_box.h"

#include <algorithm>
#include <bit>
#include <cstring>

namespace terrane::row_packed_detail {
namespace {

constexpr int kMaxRow = 32;

constexpr auto make_uniform_rows() {
  std::array<std::array<Voxel, kMaxRow>, kMaterialCount> rows{};
  for (int m = 0; m < kMaterialCount; ++m)
    for (auto& v : rows[m]) v = solid(static_cast<Material>(m));
  return rows;
}

// A uniform box's layer map: every layer uniform with material m (the byte
// 0x80 | m, twice per word).
template <int N>
constexpr auto make_uniform_headers() {
  std::array<std::array<std::uint16_t, N / 2>, kMaterialCount> headers{};
  for (int m = 0; m < kMaterialCount; ++m)
    for (auto& h : headers[m]) h = static_cast<std::uint16_t>((0x80 | m) * 0x0101);
  return headers;
}

constexpr auto kHeaders4 = make_uniform_headers<4>();
constexpr auto kHeaders8 = make_uniform_headers<8>();
constexpr auto kHeaders16 = make_uniform_headers<16>();
constexpr auto kHeaders32 = make_uniform_headers<32>();

#if defined(__x86_64__) || defined(__i386__)
bool detect_ssse3() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("ssse3");
}
#endif

int bitmap_bytes(int n) { return (n + 7) / 8; }

// Bytes of a record's occupancy section starting at p.
int occupancy_bytes(const std::uint8_t* p, int n) {
  int set = 0;
  for (int i = 0; i < bitmap_bytes(n); ++i) set += std::popcount(static_cast<unsigned>(p[i]));
  return bitmap_bytes(n) + set;
}

// An index or run record's parts, found once for every reader of it.
struct RecordParts {
  const std::uint8_t* pal;   // P - 1, then P materials
  const std::uint8_t* body;  // the indices, or the run count then the runs
  const std::uint8_t* end;   // the occupancy section, if the tag has one
  bool runs;
  int bits;    // index records: bits per voxel
  int groups;  // index records: index bytes
};

RecordParts parts_of(const std::uint8_t* rec, const std::uint8_t* table, int n) {
  RecordParts p{};
  p.pal = record_palette(rec, table);
  p.body = (rec[0] & kPaletteMask) == kInlinePalette ? rec + 3 + p.pal[0] : rec + 1;
  p.runs = (rec[0] & kKindMask) == kKindRuns;
  p.bits = index_bits(p.pal[0] + 1);
  p.groups = (n * p.bits + 7) / 8;
  p.end = p.runs ? p.body + run_count(p.body) : p.body + p.groups;
  return p;
}

// The palette index of voxel x of an index record.
int index_at(const RecordParts& p, int x) {
  return p.bits == 1 ? (p.body[x / 8] >> (x % 8)) & 1
                     : (p.body[x % p.groups] >> (p.bits * (x / p.groups))) & ((1 << p.bits) - 1);
}

}  // namespace

constinit const std::array<std::array<Voxel, 32>, kMaterialCount> kUniformRows = make_uniform_rows();

const std::uint16_t* uniform_headers(int size, Material material) {
  const int m = material & 63;
  switch (size) {
    case 4: return kHeaders4[m].data();
    case 8: return kHeaders8[m].data();
    case 16: return kHeaders16[m].data();
    default: return kHeaders32[m].data();
  }
}

PaletteTable::PaletteTable(const std::uint8_t* table) {
  if (table == nullptr || table[0] == 0) return;
  for (int id = 0; id < table[0]; ++id) {
    const std::uint8_t* pal = table + table[1 + id];
    add(reinterpret_cast<const Material*>(pal + 1), pal[0] + 1);
  }
}

int PaletteTable::add(const Material* materials, int p) {
  // After this palette: 1 (count) + count_ + 1 offsets + used_ + 1 + p bytes.
  if (!fits(p)) return -1;
  offsets_[static_cast<std::size_t>(count_)] = static_cast<std::uint8_t>(used_);
  pool_[static_cast<std::size_t>(used_)] = static_cast<std::uint8_t>(p - 1);
  std::memcpy(pool_.data() + used_ + 1, materials, static_cast<std::size_t>(p));
  std::uint64_t set = 0;
  for (int i = 0; i < p; ++i) set |= std::uint64_t{1} << (materials[i] & 63);
  masks_[static_cast<std::size_t>(count_)] = set;
  used_ += 1 + p;
  return count_++;
}

bool PaletteTable::serves(std::uint64_t materials, int p, bool runs) const {
  for (int id = 0; id < count_; ++id) {
    if ((masks_[static_cast<std::size_t>(id)] & materials) != materials) continue;
    if (keeps_record_size(p, runs, !runs, std::popcount(masks_[static_cast<std::size_t>(id)]))) return true;
  }
  return false;
}

void PaletteTable::write(std::uint8_t* out) const {
  out[0] = static_cast<std::uint8_t>(count_);
  const int base = 1 + count_;
  for (int id = 0; id < count_; ++id) out[1 + id] = static_cast<std::uint8_t>(base + offsets_[static_cast<std::size_t>(id)]);
  std::memcpy(out + base, pool_.data(), static_cast<std::size_t>(used_));
}

RowSummary summarize_row(const Voxel* row, int n) {
  RowSummary s;
  std::uint64_t seen = 0;
  const Voxel first = row[0];
  bool same = true;
  for (int x = 0; x < n; ++x) {
    seen |= std::uint64_t{1} << (row[x].material & 63);
    s.occupancy |= !has_default_occupancy(row[x]);
    same &= row[x] == first;
    s.runs += x == 0 || row[x].material != row[x - 1].material;
  }
  s.uniform = same && !s.occupancy;
  s.mask = seen;
  while (seen != 0 && s.p < 17) {
    s.materials[s.p++] = static_cast<Material>(std::countr_zero(seen));
    seen &= seen - 1;
  }
  if (seen != 0) s.p = 17;
  return s;
}

int encode_row(const Voxel* row, int n, const PaletteTable& table, std::uint8_t* out) {
  return encode_row(row, n, summarize_row(row, n), table, out);
}

int encode_row(const Voxel* row, int n, const RowSummary& s, const PaletteTable& table, std::uint8_t* out) {
  if (s.uniform) return 0;
  const int raw = 2 * n;
  if (s.p > kMaxPalette) {
    std::memcpy(out, row, sizeof(Voxel) * static_cast<std::size_t>(n));
    return raw;
  }
  const int runs = s.runs;  // the same whatever the palette
  int occupied = 0;
  for (int x = 0; x < n; ++x) occupied += !has_default_occupancy(row[x]);
  const int occ_size = s.occupancy ? bitmap_bytes(n) + occupied : 0;
  // Sizes of the index and run records with a palette of `size` materials
  // behind a head of `head` bytes (tag, and an inline palette).
  auto index_size = [&](int head, int size) { return head + (n * index_bits(size) + 7) / 8 + occ_size; };
  auto run_size = [&](int head, int size) { return size <= kMaxRunPalette ? head + runs + occ_size : raw + 1; };
  // The row's own palette inline, then every table palette holding its
  // materials (its own among them, if the table has it).
  int id = -1;
  int best = std::min(index_size(2 + s.p, s.p), run_size(2 + s.p, s.p));
  for (int t = 0; t < table.size(); ++t) {
    if ((table.mask(t) & s.mask) != s.mask) continue;
    const int size = table.palette(t)[0] + 1;
    const int cost = std::min(index_size(1, size), run_size(1, size));
    if (cost < best) {
      best = cost;
      id = t;
    }
  }
  if (best >= raw) {
    std::memcpy(out, row, sizeof(Voxel) * static_cast<std::size_t>(n));
    return raw;
  }
  const std::uint8_t* palette = id >= 0 ? table.palette(id) : nullptr;
  const int p_size = id >= 0 ? palette[0] + 1 : s.p;
  const int head = id >= 0 ? 1 : 2 + s.p;
  const bool use_runs = run_size(head, p_size) < index_size(head, p_size);
  const int bits = index_bits(p_size);
  const int groups = (n * bits + 7) / 8;
  const Material* materials = id >= 0 ? palette + 1 : s.materials;
  std::uint8_t slot[kMaterialCount] = {};
  for (int j = 0; j < p_size; ++j) slot[materials[j] & 63] = static_cast<std::uint8_t>(j);
  std::uint8_t index[kMaxRow];
  for (int x = 0; x < n; ++x) index[x] = slot[row[x].material & 63];
  out[0] = static_cast<std::uint8_t>((use_runs ? kKindRuns : kKindIndex) | (s.occupancy ? kTagOccupancy : 0) |
                                     (id >= 0 ? id : kInlinePalette));
  std::uint8_t* p = out + 1;
  if (id < 0) {
    *p++ = static_cast<std::uint8_t>(s.p - 1);
    std::memcpy(p, s.materials, static_cast<std::size_t>(s.p));
    p += s.p;
  }
  if (use_runs) {
    // The first run starts at 0: its byte's low bits hold the run count - 1.
    *p++ = static_cast<std::uint8_t>(index[0] << 5 | (runs - 1));
    for (int x = 1; x < n; ++x)
      if (index[x] != index[x - 1]) *p++ = static_cast<std::uint8_t>(index[x] << 5 | x);
  } else {
    for (int i = 0; i < groups; ++i) p[i] = 0;
    for (int x = 0; x < n; ++x) {
      // 1 bit: plain bit order; 2 and 4 bits: voxel x in byte x % G at bit b·(x / G).
      const int byte = bits == 1 ? x / 8 : x % groups;
      const int shift = bits == 1 ? x % 8 : bits * (x / groups);
      p[byte] = static_cast<std::uint8_t>(p[byte] | (index[x] << shift));
    }
    p += groups;
  }
  if (s.occupancy) {
    for (int i = 0; i < bitmap_bytes(n); ++i) p[i] = 0;
    std::uint8_t* occ = p + bitmap_bytes(n);
    for (int x = 0; x < n; ++x) {
      if (has_default_occupancy(row[x])) continue;
      p[x / 8] = static_cast<std::uint8_t>(p[x / 8] | (1 << (x % 8)));
      *occ++ = row[x].occupancy;
    }
    p = occ;
  }
  return static_cast<int>(p - out);
}

int record_bytes(const std::uint8_t* rec, const std::uint8_t* table, int n) {
  if (rec[0] < kKindIndex) return 2 * n;
  const RecordParts p = parts_of(rec, table, n);
  const std::uint8_t* end = p.end + ((rec[0] & kTagOccupancy) ? occupancy_bytes(p.end, n) : 0);
  return static_cast<int>(end - rec);
}

namespace {
// Whether the palette at pal (P - 1, then P materials) within avail bytes
// holds 1..16 materials below 64 in ascending order.
bool checked_palette(const std::uint8_t* pal, std::size_t avail) {
  if (avail < 1) return false;
  const int p = pal[0] + 1;
  if (p > kMaxPalette || avail < std::size_t(1 + p)) return false;
  for (int i = 1; i <= p; ++i)
    if (pal[i] >= kMaterialCount || (i > 1 && pal[i] <= pal[i - 1])) return false;
  return true;
}
}  // namespace

int checked_table_bytes(const std::uint8_t* data, std::size_t d) {
  if (d < 1) return -1;
  const int t = data[0];
  if (t > kMaxTablePalettes || d < std::size_t(1 + t)) return -1;
  std::size_t end = 1 + static_cast<std::size_t>(t);
  for (int id = 0; id < t; ++id) {
    const std::size_t limit = std::min(d, std::size_t{kMaxTableBytes});
    if (end >= limit || data[1 + id] != end || !checked_palette(data + end, limit - end)) return -1;
    end += 1 + std::size_t{data[end]} + 1;
  }
  // As PaletteTable adopts it: every palette fits at its turn.
  if (PaletteTable(data).size() != t) return -1;
  return static_cast<int>(end);
}

int checked_record_bytes(const std::uint8_t* rec, std::size_t avail, const std::uint8_t* table, int n) {
  if (avail < 1) return -1;
  const unsigned tag = rec[0];
  if (tag < kKindIndex) {
    if (avail < std::size_t(2 * n)) return -1;
    for (int x = 0; x < n; ++x)
      if (rec[2 * x] >= kMaterialCount || (rec[2 * x] == kAir && rec[2 * x + 1] != 0)) return -1;
    return 2 * n;
  }
  if ((tag & kKindMask) == kKindMask) return -1;
  const bool runs = (tag & kKindMask) == kKindRuns;
  std::size_t pos = 1;  // the body: after the tag and any inline palette
  if ((tag & kPaletteMask) == kInlinePalette) {
    if (!checked_palette(rec + 1, avail - 1)) return -1;
    pos = 2 + std::size_t{rec[1]} + 1;
  } else if (table == nullptr || (tag & kPaletteMask) >= table[0]) {
    return -1;
  }
  // Every body has a byte (a run count, or index bytes): parts_of may read it.
  if (avail < pos + 1) return -1;
  const RecordParts parts = parts_of(rec, table, n);
  const int p = parts.pal[0] + 1;
  if (runs) {
    const int r = run_count(parts.body);
    if (p > kMaxRunPalette || r > n || avail < pos + std::size_t(r)) return -1;
    int last = 0;
    for (int i = 0; i < r; ++i) {
      if ((parts.body[i] >> 5) >= p) return -1;
      if (i == 0) continue;
      const int start = parts.body[i] & 31;
      if (start <= last || start >= n) return -1;
      last = start;
    }
    pos += static_cast<std::size_t>(r);
  } else {
    if (avail < pos + std::size_t(parts.groups)) return -1;
    // (Indices of b bits are all below P when P is 2^b.)
    if (p != 1 << parts.bits)
      for (int x = 0; x < n; ++x)
        if (index_at(parts, x) >= p) return -1;
    pos += static_cast<std::size_t>(parts.groups);
  }
  if (tag & kTagOccupancy) {
    if (avail < pos + std::size_t(bitmap_bytes(n))) return -1;
    const int bytes = occupancy_bytes(parts.end, n);
    if (avail < pos + std::size_t(bytes)) return -1;
    pos += static_cast<std::size_t>(bytes);
    // Air only at occupancy 0: only a palette holding Air (its first
    // material, palettes being ascending) can break that, and a voxel with
    // an occupancy byte is Air when its index is 0.
    if (parts.pal[1] == kAir) {
      const std::uint8_t* occ = parts.end + bitmap_bytes(n);
      std::uint32_t set = 0;  // (n <= 32: at most 4 bytes of bitmap)
      for (int i = 0; i < bitmap_bytes(n); ++i) set |= std::uint32_t{parts.end[i]} << (8 * i);
      for (; set != 0; set &= set - 1) {
        const int x = std::countr_zero(set);
        if (*occ++ == 0 || x >= n) continue;
        // (Scalar runs: run_index_at's SIMD load may read past the record.)
        const unsigned index = runs ? run_index_at_scalar(parts.body, x) : static_cast<unsigned>(index_at(parts, x));
        if (index == 0) return -1;
      }
    }
  }
  return static_cast<int>(pos);
}

void decode_record_scalar(const std::uint8_t* rec, const std::uint8_t* table, Voxel* out, int n) {
  const RecordParts p = parts_of(rec, table, n);
  if (p.runs) {
    const int runs = run_count(p.body);
    for (int r = 0; r < runs; ++r) {
      const int from = r == 0 ? 0 : p.body[r] & 31;
      const int to = r + 1 < runs ? p.body[r + 1] & 31 : n;
      const Voxel v = solid(p.pal[1 + (p.body[r] >> 5)]);
      for (int x = from; x < to; ++x) out[x] = v;
    }
  } else {
    for (int x = 0; x < n; ++x) out[x] = solid(p.pal[1 + index_at(p, x)]);
  }
  if (rec[0] & kTagOccupancy) {
    const std::uint8_t* occ = p.end + bitmap_bytes(n);
    for (int x = 0; x < n; ++x)
      if ((p.end[x / 8] >> (x % 8)) & 1) out[x].occupancy = *occ++;
  }
}

Voxel record_voxel(const std::uint8_t* rec, const std::uint8_t* table, int n, int x) {
  const RecordParts p = parts_of(rec, table, n);
  Material m;
  if (p.runs) {
    m = p.pal[1 + run_index_at(p.body, x)];
  } else {
    m = p.pal[1 + index_at(p, x)];
  }
  if ((rec[0] & kTagOccupancy) && ((p.end[x / 8] >> (x % 8)) & 1)) {
    int before = 0;
    for (int i = 0; i < x / 8; ++i) before += std::popcount(static_cast<unsigned>(p.end[i]));
    before += std::popcount(static_cast<unsigned>(p.end[x / 8] & ((1u << (x % 8)) - 1)));
    return make_voxel(m, p.end[bitmap_bytes(n) + before]);
  }
  return solid(m);
}

#if defined(__x86_64__) || defined(__i386__)
const bool kHaveSsse3 = detect_ssse3();
#endif

}  // namespace terrane::row_packed_detail

namespace terrane {
template class RowPackedBox<4>;
template class RowPackedBox<8>;
template class RowPackedBox<16>;
template class RowPackedBox<32>;
}  // namespace terrane
