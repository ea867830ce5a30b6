// RowPackedBox<N>: an N³ box of voxels stored row-packed, the in-memory format
// of the storage article ("Memory format, take two"), used for a chunk's full
// resolution (N = 32; a chunk's mips are kept as network-codec units, see
// chunk.h).
//
// Each of the N² rows along x, addressed by (y, z), has a header, kept per
// layer (one y, its N rows): a layer map of N bytes says for each layer
// either "all its rows uniform with material m" (0x80 | m: the layer stores
// no headers) or where its headers are, in units of N/2 + 2 words after the
// map (unit u at words N/2 + u·(N/2 + 2)):
//
//   0x40 | u   wide layer, one unit and the next: N 2-byte headers
//   u < 0x40   narrow layer, one unit: two 2-byte base offsets B0 (rows
//              z < N/2) and B1 (the others), then N bytes, one per row:
//              b < 192, its record starts at byte B0 or B1 + b of data_;
//              b >= 192, a uniform row of material b - 192
//
// A wide layer's header:
//
//   bit 15 14 ........... 0
//        0  -  . material      uniform row: N voxels of `material`, default occupancy
//        1  offset             allocated row: its record starts at byte
//                              offset << shift_ of data_ (shift_ is 0, or 1
//                              in unpacked mode, where rows are 2N bytes apart)
//
// A layer is narrow when, in each half, every record its rows start lies
// within 191 bytes of the first: in real terrain most layers' records are a
// few bytes each, so a layer's headers take N + 4 bytes instead of 2N, and
// a row is found with the same loads as through a wide header. Unpacked
// boxes are all wide.
//
// data_ starts with the box's palette table, then holds the records:
//
//   palette table:  T | T offsets (1 byte each, from data_) | T palettes
//   palette:        P - 1 | P materials (ascending)           (P = 1..16)
//   (T <= 31 and the whole table within 255 bytes; T = 0 is one byte.)
//
// An allocated row's record says what it is in its first byte:
//
//   raw record (first byte < 0x40, it is voxel 0's material), 2N bytes:
//     m0 occ0 m1 occ1 ...                   read_row returns a pointer to it
//
//   index record (tag 01oiiiii):  tag | [palette] | G index bytes | [occupancies]
//   run record   (tag 10oiiiii):  tag | [palette] | R run bytes | [occupancies]
//     i (bits 4-0): a palette of the table, or 31: the palette follows the tag
//     o (bit 5): the record ends with an occupancy section (else every voxel
//        has its material's default occupancy)
//     index record: b = 1, 2 or 4 bits per voxel for P <= 2, <= 4, <= 16;
//        G = ceil(N·b / 8). 1 bit: voxel x is bit x % 8 of byte x / 8. 2 and 4
//        bits: voxel x's index is the b bits at bit b·(x / G) of byte x % G,
//        which for N = 32 puts voxels 0..15 and 16..31 in the two halves of an
//        SSE register after a few shifts.
//     run record (P <= 8): R runs, each one byte (index << 5 | first x),
//        first x strictly ascending from 0; the first run's byte holds
//        R - 1 in place of its first x (0), so R is not stored apart.
//     occupancy section: ceil(N / 8) bytes of bitmap (bit x % 8 of byte x / 8:
//        voxel x has a non-default occupancy), then one occupancy byte per set
//        bit, in x order.
//
// Records are byte-aligned and unpadded; data_ ends with kPadBytes of padding
// so the SIMD decoder may over-read. Identical records are stored once
// (several headers share an offset). A box whose rows are all uniform with
// one material owns no headers at all: it points at a shared header table
// ("a uniform chunk stores one value").
//
// A record's palette holds every material of its row and may hold others: a
// run record costs the same with any palette of up to 8 materials, an index
// record with any palette of its index width, so rows over different sets
// of materials share one table palette holding them all. Each row takes the
// smallest of its encodings over every palette that can serve it. compact()
// (and any write covering the whole box) chooses the table: the rows'
// material sets, most used first, each take a palette already serving them,
// grow one by their missing materials (while the rows it serves keep their
// records' sizes), get one of their own, or go inline, whichever costs the
// fewest bytes. Partial writes add a palette for a row no table palette
// serves, while the table has room.
//
// Uniform rows read in place from a shared read-only table of pre-filled rows
// per material; raw rows in place; index and run records are decoded into the
// caller's scratch row (SSSE3 for N = 32, a scalar reference otherwise). Every
// path is constant-time except the occupancy section (one step per voxel of
// non-default occupancy) and runs (one step per run), with no allocation.
//
// Writes are two-stage, as in the article: the rows a write touches are
// materialised, modified and encoded first; if no touched row's record grows
// (or is shared, or has an inline palette the table has room for) the new
// records are written in place, otherwise the box is rebuilt once with one allocation. A box that
// keeps being rebuilt by small writes switches to unpacked mode (every row a
// raw record of its own, writes in place, no repacking) until compact() is
// called.
//
// Invariants: headers_ points at a layer map and its slots' headers; a layer
// has a slot only if some row of it is allocated or differs from the first;
// a narrow layer's allocated rows start records within 191 bytes of their
// half's base;
// every allocated header's offset
// starts a valid record inside data_; records name only palettes of the
// table; data_ holds data_bytes_ bytes of which the last kPadBytes are
// padding; records are shared only outside unpacked mode; no stored voxel is
// Air with non-zero occupancy; every material is < 64.
// Thread-safety: const methods may run concurrently; writes need exclusion.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "common/codec/byte_order.h"
#include "common/codec/decode_error.h"
#include "common/voxel/voxel.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace terrane {

namespace row_packed_detail {
// Pre-filled rows of every material at default occupancy, long enough for the
// largest box (32), shared read-only by every box.
extern const std::array<std::array<Voxel, 32>, kMaterialCount> kUniformRows;
inline const Voxel* uniform_row(Material material) { return kUniformRows[material & 63].data(); }
// Per-size layer maps of all-uniform boxes, for boxes that own no headers.
const std::uint16_t* uniform_headers(int size, Material material);

inline constexpr std::uint8_t kKindMask = 0xC0;
inline constexpr std::uint8_t kKindIndex = 0x40;  // first record bytes below it are raw
inline constexpr std::uint8_t kKindRuns = 0x80;
inline constexpr std::uint8_t kTagOccupancy = 0x20;
inline constexpr std::uint8_t kPaletteMask = 0x1F;
inline constexpr std::uint8_t kInlinePalette = 31;
inline constexpr int kMaxPalette = 16;
inline constexpr int kMaxRunPalette = 8;
inline constexpr int kMaxTablePalettes = 31;
inline constexpr int kMaxTableBytes = 255;

// Index bits per voxel for a palette of p materials (1..16).
inline constexpr int index_bits(int p) { return p <= 2 ? 1 : p <= 4 ? 2 : 4; }

// The palette a record uses: its first byte is P - 1, then P materials.
inline const std::uint8_t* record_palette(const std::uint8_t* rec, const std::uint8_t* table) {
  const unsigned id = rec[0] & kPaletteMask;
  return id == kInlinePalette ? rec + 1 : table + table[1 + id];
}

// A run record's body: R run bytes (index << 5 | first x), except that the
// first run's byte holds R - 1 where its first x (always 0) would be.
inline int run_count(const std::uint8_t* body) { return (body[0] & 31) + 1; }

// The palette index of voxel x in a run body. Runs' first x ascend, so the
// run holding x is the count of runs 1..R-1 starting at or before x: for up
// to 16 runs one compare of 16 bytes (the body is followed by at least 16
// readable bytes: a box's padding), else a scan.
inline unsigned run_index_at_scalar(const std::uint8_t* body, int x);
inline unsigned run_index_at(const std::uint8_t* body, int x) {
#if defined(__SSE2__)
  const int runs = run_count(body);
  if (runs <= 16) {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(body));
    const __m128i starts = _mm_and_si128(v, _mm_set1_epi8(31));
    const __m128i at_or_before = _mm_cmpgt_epi8(_mm_set1_epi8(static_cast<char>(x + 1)), starts);
    const unsigned mask = static_cast<unsigned>(_mm_movemask_epi8(at_or_before)) & ((1u << runs) - 2u);
    return static_cast<unsigned>(body[std::popcount(mask)]) >> 5;
  }
#endif
  return run_index_at_scalar(body, x);
}

// The scan alone, reading only the R run bytes (for bytes with no padding
// after them, as an image being checked).
inline unsigned run_index_at_scalar(const std::uint8_t* body, int x) {
  const int runs = run_count(body);
  int r = 0;
  while (r + 1 < runs && (body[r + 1] & 31) <= x) ++r;
  return static_cast<unsigned>(body[r]) >> 5;
}

// Bytes of the record starting at rec. Precondition: a valid record for n
// whose table palettes are in `table`.
int record_bytes(const std::uint8_t* rec, const std::uint8_t* table, int n);

// For bytes that are not trusted (a stored image, see RowPackedBox::
// read_image): the bytes of the record at rec if it is a valid record of n
// voxels within avail bytes, naming only palettes of `table` (a table that
// passed checked_table_bytes, or null) and holding no Air voxel of non-zero
// occupancy; else -1. Reads nothing beyond rec + avail.
int checked_record_bytes(const std::uint8_t* rec, std::size_t avail, const std::uint8_t* table, int n);
// The bytes of the palette table at the front of d bytes of box data if it
// is valid and laid out as PaletteTable::write lays it out (palettes back to
// back, each of 1..16 materials below 64 in ascending order, within 255
// bytes); else -1.
int checked_table_bytes(const std::uint8_t* data, std::size_t d);

// A box's palette table while rows are encoded: lookup by material set.
class PaletteTable {
 public:
  PaletteTable() = default;
  // Adopts the table at the front of a box's data (nullptr: empty).
  explicit PaletteTable(const std::uint8_t* table);
  int size() const { return count_; }
  int bytes() const { return 1 + count_ + used_; }
  // The materials of palette id as a set (bit m for material m).
  std::uint64_t mask(int id) const { return masks_[static_cast<std::size_t>(id)]; }
  // Whether some palette holds every material of a row (materials: their
  // set, p of them) and keeps its record as small as the row's own palette
  // would: of at most kMaxRunPalette materials if the row takes a run record
  // (runs), of the same index width as p if it takes an index record.
  bool serves(std::uint64_t materials, int p, bool runs) const;
  // Whether a palette of p materials would fit.
  bool fits(int p) const { return p <= kMaxPalette && count_ < kMaxTablePalettes && 2 + count_ + used_ + 1 + p <= kMaxTableBytes; }
  // Adds a palette if the table has room; returns its id or -1.
  int add(const Material* materials, int p);
  // Writes the table (bytes() bytes).
  void write(std::uint8_t* out) const;
  // Palette bytes (P - 1, materials) of id.
  const std::uint8_t* palette(int id) const { return pool_.data() + offsets_[static_cast<std::size_t>(id)]; }

 private:
  int count_ = 0;
  int used_ = 0;  // bytes of palettes
  std::array<std::uint8_t, kMaxTablePalettes> offsets_{};  // into pool_
  std::array<std::uint64_t, kMaxTablePalettes> masks_{};   // each palette's materials as a set
  std::array<std::uint8_t, kMaxTableBytes> pool_{};
};

// What encode_row needs to know of a row: its distinct materials (ascending)
// and whether any voxel has a non-default occupancy.
struct RowSummary {
  int p = 0;                  // distinct materials (17 means more than 16)
  Material materials[17] = {};
  std::uint64_t mask = 0;     // the same as a set: bit m for material m
  int runs = 0;               // runs of one material along the row
  bool uniform = false;       // one voxel value at default occupancy
  bool occupancy = false;     // some voxel has a non-default occupancy
};
RowSummary summarize_row(const Voxel* row, int n);
// Whether a row of n voxels (not uniform, at most 16 materials) takes a run
// record rather than an index record with its own palette (the occupancy
// section costs the same in both).
inline bool takes_runs(const RowSummary& s, int n) {
  return s.p <= kMaxRunPalette && s.runs < (n * index_bits(s.p) + 7) / 8;
}
// Whether a palette of `size` materials keeps the records of rows over p
// materials as small as their own palette would, given which records those
// rows take: at most kMaxRunPalette materials for run records, the index
// width of p for index records.
inline bool keeps_record_size(int p, bool runs, bool index, int size) {
  return size <= kMaxPalette && (!runs || size <= kMaxRunPalette) && (!index || index_bits(size) == index_bits(p));
}

// Encodes row (n voxels, Air already normalised) against table. Returns 0 for
// a uniform row (the caller stores only a header), else the record's length,
// written to out (capacity >= 2n bytes). Takes the shortest of the index,
// run and raw records over every palette that can serve the row: its own
// (from the table, or inline), or a table palette holding its materials and
// others (a run record costs the same with any palette of up to 8
// materials, an index record with any of the same index width).
int encode_row(const Voxel* row, int n, const PaletteTable& table, std::uint8_t* out);
// The same with the row's summary already made (summarize_row(row, n)).
int encode_row(const Voxel* row, int n, const RowSummary& summary, const PaletteTable& table, std::uint8_t* out);

// Index or run record -> n voxels. The scalar decoder is the reference.
void decode_record_scalar(const std::uint8_t* rec, const std::uint8_t* table, Voxel* out, int n);
#if defined(__x86_64__) || defined(__i386__)
// The SSSE3 decoder for n = 32 (row_packed_simd.h) may read up to 16 bytes
// past the record and the palette. Without compile-time SSSE3, call it only
// when kHaveSsse3.
extern const bool kHaveSsse3;
#endif

// One voxel of an index or run record.
Voxel record_voxel(const std::uint8_t* rec, const std::uint8_t* table, int n, int x);
}  // namespace row_packed_detail

}  // namespace terrane

#include "common/voxel/row_packed_simd.h"

namespace terrane {

struct RowPackedStats {
  std::size_t uniform_rows = 0;    // header only
  std::size_t raw_rows = 0;        // raw records (2 bytes per voxel)
  std::size_t index_rows = 0;      // index records
  std::size_t run_rows = 0;        // run records
  std::size_t occupancy_rows = 0;  // records with an occupancy section (or raw)
  std::size_t shared_rows = 0;     // allocated rows whose record an earlier row already uses
  std::size_t table_bytes = 0;     // the palette table
  std::size_t data_bytes = 0;      // table, records and padding
  // Bytes of the distinct records by kind, of inline palettes among them
  // (P - 1 and the materials).
  std::size_t index_bytes = 0, run_bytes = 0, raw_bytes = 0, inline_palette_bytes = 0;
  std::size_t narrow_layers = 0, wide_layers = 0;  // layers with their own headers
  RowPackedStats& operator+=(const RowPackedStats& o) {
    index_bytes += o.index_bytes;
    run_bytes += o.run_bytes;
    raw_bytes += o.raw_bytes;
    inline_palette_bytes += o.inline_palette_bytes;
    narrow_layers += o.narrow_layers;
    wide_layers += o.wide_layers;
    uniform_rows += o.uniform_rows;
    raw_rows += o.raw_rows;
    index_rows += o.index_rows;
    run_rows += o.run_rows;
    occupancy_rows += o.occupancy_rows;
    shared_rows += o.shared_rows;
    table_bytes += o.table_bytes;
    data_bytes += o.data_bytes;
    return *this;
  }
};

template <int N>
class RowPackedBox {
 public:
  static_assert(N == 4 || N == 8 || N == 16 || N == 32, "row-packed boxes are 4, 8, 16 or 32 wide");
  static constexpr int kSize = N;
  static constexpr int kRows = N * N;
  static constexpr std::uint16_t kAllocated = 0x8000;
  static constexpr std::uint16_t kOffsetMask = 0x7FFF;
  // Bytes of padding after the records: the SSSE3 decoder (N = 32) loads 16
  // bytes at the palette and at the indices.
  static constexpr std::uint32_t kPadBytes = 16;
  // Repacks allowed between two compact() calls before the box unpacks
  // itself for good: enough that ordinary editing stays packed, few enough
  // that a stream of tiny writes costs at most a bounded number of copies.
  static constexpr int kRepackBudget = 32;

  // A scratch row for read_row to decode records into.
  using Row = std::array<Voxel, N>;

  explicit RowPackedBox(Material fill = kAir);
  // A moved-from box is left uniform Air, usable as any other.
  RowPackedBox(RowPackedBox&& other) noexcept { *this = std::move(other); }
  RowPackedBox& operator=(RowPackedBox&& other) noexcept {
    if (this == &other) return *this;
    headers_ = other.headers_;
    owned_headers_ = std::move(other.owned_headers_);
    data_ = std::move(other.data_);
    data_bytes_ = other.data_bytes_;
    repacks_ = other.repacks_;
    shift_ = other.shift_;
    owns_headers_ = other.owns_headers_;
    other.headers_ = row_packed_detail::uniform_headers(N, kAir);
    other.data_bytes_ = 0;
    other.repacks_ = 0;
    other.shift_ = 0;
    other.owns_headers_ = false;
    return *this;
  }
  RowPackedBox(const RowPackedBox&) = delete;
  RowPackedBox& operator=(const RowPackedBox&) = delete;
  ~RowPackedBox() = default;

  RowPackedBox clone() const;

  // The article's readRow: the N voxels of row (y, z). Returns a pointer into
  // the box, into the shared uniform rows, or (for index and run records)
  // into scratch. Valid until the next write or until scratch is reused.
  const Voxel* read_row(int y, int z, Row& scratch) const {
    const std::uint16_t h = header(y, z);
    if (!(h & kAllocated)) return row_packed_detail::uniform_row(static_cast<Material>(h & 63));
    const std::uint8_t* rec = data_.get() + (static_cast<std::uint32_t>(h & kOffsetMask) << shift_);
    if (rec[0] < row_packed_detail::kKindIndex) return reinterpret_cast<const Voxel*>(rec);
    decode(rec, data_.get(), scratch.data());
    return scratch.data();
  }

  // Copies voxels [x0, x0 + n) of row (y, z) to out: a uniform row is
  // filled, a raw row copied, a record decoded (straight into out when the
  // part is the whole row, else into scratch and copied).
  // Precondition: 0 <= x0, n >= 0, x0 + n <= N.
  void read_row_part(int y, int z, int x0, int n, Voxel* out, Row& scratch) const {
    read_part_of(header(y, z), x0, n, out, scratch);
  }
  // read_row_part of rows y in [y0, y1), z in [z0, z1) to dest(y, z) (a
  // Voxel* per row), except that a row with the same header as the row
  // before it in its layer (the same record, or the same uniform material)
  // copies that row's part rather than decoding it again.
  template <class Dest>
  void read_rows_part(int y0, int y1, int z0, int z1, int x0, int n, Dest&& dest) const {
    Row scratch;
    for (int y = y0; y < y1; ++y) {
      std::uint16_t last = 0;
      const Voxel* last_out = nullptr;
      for (int z = z0; z < z1; ++z) {
        Voxel* out = dest(y, z);
        const std::uint16_t h = header(y, z);
        if (last_out != nullptr && h == last) {
          std::copy_n(last_out, n, out);
          continue;
        }
        read_part_of(h, x0, n, out, scratch);
        last = h;
        last_out = out;
      }
    }
  }

  // Whether any voxel of the box [x0, x1) × [y0, y1) × [z0, z1) is non-Air
  // with an occupancy of at least min_occupancy (solid_enough), read in
  // place: a layer of one uniform material answers for all its rows at once;
  // a uniform row by its material; a record without occupancies, whose
  // non-Air voxels all have full occupancy (or any record when
  // min_occupancy is 0), by its palette (Air, id 0, can only be its first
  // material, index 0) and then its runs or indices; others voxel by voxel.
  // Precondition: 0 <= x0 <= x1 <= N, the same for y and z.
  bool box_has_solid(int x0, int x1, int y0, int y1, int z0, int z1, std::uint8_t min_occupancy) const {
    if (x0 >= x1 || z0 >= z1) return false;
    const auto* map = reinterpret_cast<const std::uint8_t*>(headers_);
    for (int y = y0; y < y1; ++y) {
      if (map[y] & 0x80) {
        if ((map[y] & 63) != kAir) return true;
        continue;
      }
      for (int z = z0; z < z1; ++z)
        if (header_has_solid(header(y, z), x0, x1, min_occupancy)) return true;
    }
    return false;
  }

 private:
  // read_row_part of the row with header h.
  void read_part_of(std::uint16_t h, int x0, int n, Voxel* out, Row& scratch) const {
    if (!(h & kAllocated)) {
      std::fill_n(out, n, solid(static_cast<Material>(h & 63)));
      return;
    }
    const std::uint8_t* rec = record(h);
    if (rec[0] < row_packed_detail::kKindIndex) {
      std::copy_n(reinterpret_cast<const Voxel*>(rec) + x0, n, out);
      return;
    }
    if (n == N) {
      decode(rec, data_.get(), out);
      return;
    }
    decode(rec, data_.get(), scratch.data());
    std::copy_n(scratch.data() + x0, n, out);
  }
  // box_has_solid of the part [x0, x1) of the row with header h, for x0 < x1.
  bool header_has_solid(std::uint16_t h, int x0, int x1, std::uint8_t min_occupancy) const {
    using namespace row_packed_detail;
    if (!(h & kAllocated)) return (h & 63) != kAir;
    const std::uint8_t* rec = record(h);
    const unsigned tag = rec[0];
    if (tag < kKindIndex) return any_solid_enough(reinterpret_cast<const Voxel*>(rec), x0, x1, min_occupancy);
    // (A span of a few voxels, as an overlap test of a player's box asks,
    // reads them one by one.)
    constexpr int kFew = 4;
    // With min_occupancy 0 every non-Air voxel counts, whatever its
    // occupancy: the materials answer, as for a record without occupancies.
    if ((tag & kTagOccupancy) && min_occupancy > 0) {
      if (x1 - x0 <= kFew) {
        for (int x = x0; x < x1; ++x)
          if (solid_enough(record_voxel(rec, data_.get(), N, x), min_occupancy)) return true;
        return false;
      }
      Row scratch;
      decode(rec, data_.get(), scratch.data());
      return any_solid_enough(scratch.data(), x0, x1, min_occupancy);
    }
    const std::uint8_t* pal = record_palette(rec, data_.get());
    if (pal[1] != kAir) return true;  // (a record's voxels are all of its palette's materials)
    const std::uint8_t* body = (tag & kPaletteMask) == kInlinePalette ? rec + 3 + pal[0] : rec + 1;
    if ((tag & kKindMask) == kKindRuns) {
      if (x1 - x0 <= kFew) {
        for (int x = x0; x < x1; ++x)
          if (run_index_at(body, x) != 0) return true;
        return false;
      }
      // A run of a non-zero index overlapping [x0, x1).
      const int runs = run_count(body);
      for (int r = 0; r < runs; ++r) {
        const int start = r == 0 ? 0 : body[r] & 31;
        if (start >= x1) break;
        const int end = r + 1 < runs ? body[r + 1] & 31 : N;
        if (end > x0 && (body[r] >> 5) != 0) return true;
      }
      return false;
    }
    const unsigned p1 = pal[0];
    if (p1 < 2) {
      // 1 bit per voxel, voxel x at bit x of the body (little-endian; the
      // box's padding makes 4 bytes readable).
      std::uint32_t bits;
      std::memcpy(&bits, body, 4);
      const int n = x1 - x0;
      const std::uint32_t span = n >= 32 ? ~0u : ((1u << n) - 1u) << x0;
      return (bits & span) != 0;
    }
    for (int x = x0; x < x1; ++x) {
      constexpr int g2 = N * 2 / 8, g4 = N * 4 / 8;
      const unsigned index = p1 < 4 ? (body[x % g2] >> (2 * (x / g2))) & 3 : (body[x % g4] >> (4 * (x / g4))) & 15;
      if (index != 0) return true;
    }
    return false;
  }

 public:
  // One voxel, in place: records without occupancy are read here (a ray
  // cast or an overlap test reads voxel by voxel), the rest by record_voxel.
  Voxel get(int x, int y, int z) const {
    using namespace row_packed_detail;
    const std::uint16_t h = header(y, z);
    if (!(h & kAllocated)) return solid(static_cast<Material>(h & 63));
    const std::uint8_t* rec = data_.get() + (static_cast<std::uint32_t>(h & kOffsetMask) << shift_);
    const unsigned tag = rec[0];
    if (tag < kKindIndex) return reinterpret_cast<const Voxel*>(rec)[x];
    if (tag & kTagOccupancy) return record_voxel(rec, data_.get(), N, x);
    const std::uint8_t* pal = record_palette(rec, data_.get());
    const std::uint8_t* body = (tag & kPaletteMask) == kInlinePalette ? rec + 3 + pal[0] : rec + 1;
    if ((tag & kKindMask) == kKindRuns) return solid(pal[1 + run_index_at(body, x)]);
    // Index records (layout in the header comment): G = N * bits / 8 bytes.
    const unsigned p1 = pal[0];
    unsigned index;
    if (p1 < 2) {
      index = (body[x / 8] >> (x % 8)) & 1;
    } else if (p1 < 4) {
      constexpr int g = N * 2 / 8;
      index = (body[x % g] >> (2 * (x / g))) & 3;
    } else {
      constexpr int g = N * 4 / 8;
      index = (body[x % g] >> (4 * (x / g))) & 15;
    }
    return solid(pal[1 + index]);
  }

  // Rewrites rows y in [y0, y1), z in [z0, z1): for each, fn(y, z, row)
  // receives the row's current N voxels in `row` and leaves the new content
  // there. Air occupancy is normalised afterwards. Two-stage as described
  // above. Preconditions: 0 <= y0 <= y1 <= N, same for z; materials < 64.
  template <class RowFn>
  void modify_rows(int y0, int y1, int z0, int z1, RowFn&& fn);

  void set(int x, int y, int z, Voxel v) {
    modify_rows(y, y + 1, z, z + 1, [&](int, int, Voxel* row) { row[x] = v; });
  }
  void fill(Material m);  // whole box uniform with default occupancy

  // Uniform box: every voxel the same material at default occupancy.
  bool is_uniform() const { return !owns_headers_; }
  Material uniform_material() const { return static_cast<Material>(header(0, 0) & 63); }
  bool unpacked() const { return shift_ != 0; }

  // Pessimistic full unpack: every row its own raw record, so writes never repack.
  void unpack_all();
  // Repacks every row to its smallest record with a palette table chosen for
  // the whole box, shares identical records and leaves unpacked mode (unless
  // the records pass 32 KiB, beyond 15-bit byte offsets: such a box, more
  // than half raw rows, stays unpacked).
  void compact();

  // The box as it is in memory, for a store that loads boxes without
  // encoding them again (WORLD_FORMAT.md, "Chunk image"), appended to out:
  //   uniform box:  0 | material
  //   packed box:   1 | layer map (N bytes) | its slots' words (u16 LE) |
  //                 D (u16 LE) | D bytes of data (table, records; no padding)
  // Precondition: !unpacked().
  void write_image(std::vector<std::uint8_t>& out) const;
  // Reads an image from in at pos and advances pos past it. The invariants
  // above that reads and writes rely on are checked (layer map and slots in
  // order, every row's record valid, at most 2N bytes and inside the data,
  // no record inside another, the table as PaletteTable writes it, a layer
  // map not all one material): a damaged image is an error, never a box
  // that reads or writes out of bounds. Records the image shares stay
  // shared. (A packed box whose records all hold one material is accepted:
  // uniform() is then false, as after a write that made it so.)
  static Result<RowPackedBox> read_image(std::span<const std::uint8_t> in, std::size_t& pos);

  // The first byte of row (y, z)'s record (its kind and palette), or -1 for
  // a uniform row.
  int record_tag(int y, int z) const {
    const std::uint16_t h = header(y, z);
    return (h & kAllocated) ? record(h)[0] : -1;
  }

  // Every heap byte this box owns (headers, table, records, padding), not
  // counting sizeof(*this).
  std::size_t heap_bytes() const;
  RowPackedStats stats() const;

 private:
  static void decode(const std::uint8_t* rec, const std::uint8_t* table, Voxel* out) {
#if defined(__x86_64__) || defined(__i386__)
    if constexpr (N == 32) {
#if defined(__SSSE3__)
      row_packed_detail::decode_record32_ssse3(rec, table, out);
      return;
#endif
      if (row_packed_detail::kHaveSsse3) {
        row_packed_detail::decode_record32_ssse3(rec, table, out);
        return;
      }
    }
#endif
    row_packed_detail::decode_record_scalar(rec, table, out, N);
  }
  static constexpr std::uint8_t kWideLayer = 0x40;
  static constexpr int kUnitWords = N / 2 + 2;
  static constexpr unsigned kNarrowUniform = 192;  // narrow row bytes from here on: uniform material + 192
  // Row (y, z)'s header, through the layer map, in the wide form (a narrow
  // layer's row is given as kAllocated | its offset, or its material).
  std::uint16_t header(int y, int z) const {
    const std::uint8_t layer = reinterpret_cast<const std::uint8_t*>(headers_)[y];
    if (layer & 0x80) return static_cast<std::uint16_t>(layer & 63);
    const std::uint16_t* slot = headers_ + N / 2 + (layer & 63) * kUnitWords;
    if (layer & kWideLayer) return slot[z];
    const unsigned b = reinterpret_cast<const std::uint8_t*>(slot + 2)[z];
    return b >= kNarrowUniform ? static_cast<std::uint16_t>(b - kNarrowUniform)
                               : static_cast<std::uint16_t>(kAllocated | (slot[z / (N / 2)] + b));
  }
  std::uint16_t header(int r) const { return header(r / N, r % N); }
  // Words of the owned headers (map and slots).
  std::size_t header_words() const;
  // Takes N² headers (row order, wide form) as the box's, kept per layer as
  // above. narrow_base (2N entries, or null): a layer's base offsets (its
  // two halves), or -1 for a wide layer; narrow_bytes (N² entries) then
  // gives each narrow row's offset from its half's base.
  void adopt_headers(const std::uint16_t* all, const std::int32_t* narrow_base = nullptr,
                     const std::uint8_t* narrow_bytes = nullptr);
  const std::uint8_t* record(std::uint16_t h) const {
    return data_.get() + (static_cast<std::uint32_t>(h & kOffsetMask) << shift_);
  }
  const std::uint8_t* table() const { return data_ ? data_.get() : nullptr; }
  void read_row_into(int y, int z, Voxel* out) const;
  // Rebuilds all storage at once: rows in the rectangle y0..y1 × z0..z1 take
  // the content given (row-major in that rectangle, N voxels each), encoded
  // against `table` (which grows by their palettes while it has room if
  // grow_table); other rows keep their records, whose palettes `table` must
  // keep at the same ids. Identical records are stored
  // once. Becomes uniform when every row ends up uniform alike. Falls back to
  // unpacked mode if the records would not fit 15-bit byte offsets.
  // (known: the touched rows' summaries, if the caller made them.)
  void rebuild_rect(int y0, int y1, int z0, int z1, const Voxel* content, row_packed_detail::PaletteTable& table,
                    bool grow_table, const row_packed_detail::RowSummary* known = nullptr);
  // Unpacked mode from the rows in the rectangle (content as for
  // rebuild_rect) and the box's other rows.
  void unpack_from(int y0, int y1, int z0, int z1, const Voxel* content);
  // compact() of the given content (N² rows of N voxels, Air normalised).
  void compact_from(const Voxel* content);
  void become_uniform(Material m);

  const std::uint16_t* headers_ = row_packed_detail::uniform_headers(N, kAir);  // layer map and slots: owned_headers_ or a shared map
  std::unique_ptr<std::uint16_t[]> owned_headers_;
  std::unique_ptr<std::uint8_t[]> data_;  // palette table, records, then kPadBytes of padding
  std::uint32_t data_bytes_ = 0;          // bytes allocated in data_ (0 when none)
  std::uint16_t repacks_ = 0;             // since the last compact()
  std::uint8_t shift_ = 0;                // offset scale: 0 packed, 1 unpacked
  bool owns_headers_ = false;
};

}  // namespace terrane

#include "common/voxel/row_packed_box_impl.h"
