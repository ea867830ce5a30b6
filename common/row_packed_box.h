// RowPackedBox<N>: an N³ box of voxels stored row-packed, the in-memory format
// of the storage article ("Memory format, take two"), used for a chunk's full
// resolution (N = 32) and for each level of its mip pyramid (16, 8, 4).
//
// Each of the N² rows along x, addressed by (y, z), has a 2-byte header:
//
//   bit 15 14 13 ......... 0
//        0  -  - . material      uniform row: N voxels of `material`, default occupancy
//        1  0  index             raw row: record `index` of the raw area (2N bytes each)
//        1  1  offset            palette row: its record starts at byte `offset` of data_
//
// data_ holds, in this order: the box's palette table (32³ boxes only), the
// palette records, the raw records (from raw_base_, 2-byte aligned), then
// padding.
//
//   palette table: entries at multiples of 4 bytes (entry id = offset / 4,
//   at most 1 KiB; a box whose entries need more uses 8-byte units, see
//   entry_shift_), each
//     +------+-----------+-------------------------+
//     | info | P mats    | P occupancies (if flag) |
//     +------+-----------+-------------------------+
//     Rows with the same set of voxel values share an entry (encode_row sorts
//     the palette), and a rebuild merges default-occupancy sets of one index
//     width while their union still fits it, so a row may use an entry
//     holding more values than it needs.
//     info bits 7-6: index width b (1 = 1 bit, 2 = 2 bits, 3 = 4 or 3 bits)
//          bit 5: occupancies present (else each voxel has its material's
//                 default occupancy and the occupancy bytes are absent)
//          bit 4: with width code 3, 3 bits instead of 4 (P <= 8)
//          bits 3-0: P - 1 (P = 1..16 palette entries)
//
//   palette record, 1 + G bytes, at any byte offset (14 bits: the table
//   and the palette records together stay under 16 KiB, else rows go raw):
//     +-------------+-------------------+
//     | entry id    | G index bytes     |
//     +-------------+-------------------+
//     Boxes narrower than 32 (the mips) have no table: the entry itself
//     replaces the id byte (their rows rarely share palettes).
//     G = ceil(N·b / 8). 1 bit: voxel x is bit x % 8 of byte x / 8. 2 and 4
//     bits: voxel x's index is the b bits at bit b·(x / G) of byte x % G,
//     which for N = 32 puts voxels 0..15 and 16..31 in the two halves of an
//     SSE register after a few shifts. 3 bits: a 2-bit plane (2N/8 bytes,
//     laid out as 2-bit indices) holds index bits 0-1, then a 1-bit plane
//     (N/8 bytes) holds bit 2. The SSSE3 decoder loads the 16-byte
//     palette from the table and expands a row with shifts, masks and pshufb
//     lookups, without branches.
//
//   raw record, 2N bytes:
//     +------+------+------+------+-- ... --+
//     | m0   | occ0 | m1   | occ1 |         |   read_row returns a pointer to it
//     +------+------+------+------+-- ... --+
//
// Uniform rows cost only their header; read_row returns a pointer into a
// shared read-only table of pre-filled rows per material. Raw rows are read
// in place; palette rows are decoded into the caller's scratch row. Every
// path is constant-time with no allocation. Identical records inside a box
// are stored once (several headers share an offset). A box whose rows are all
// uniform with one material owns no headers at all: it points at a shared
// header table ("a uniform chunk stores one value").
//
// Writes are two-stage, as in the article: the rows a write touches are
// materialised, modified and encoded first; if every touched row keeps its
// record kind and size (a palette row: its voxels all in its current entry)
// and its record is not shared, the new records are written in place,
// otherwise the box is rebuilt once with one allocation. A box that
// keeps being rebuilt by small writes switches to unpacked mode (every row a
// raw record of its own, record r for row r, writes in place, no repacking)
// until compact() is called.
//
// Invariants: headers_ points at N² headers; every allocated header names a
// valid record inside data_ whose entry id names a valid table entry; data_
// holds data_units_ voxels of which the last kPadUnits are padding (when any
// palette row exists) so the SIMD decoder may over-read; records are shared
// only outside unpacked mode (where every row is raw record r and there is no
// table); no stored voxel is Air with non-zero occupancy; every material is < 64.
// Thread-safety: const methods may run concurrently; writes need exclusion.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>

#include "common/row_packed_simd.h"
#include "common/voxel.h"

namespace terrane {

namespace row_packed_detail {
// Pre-filled rows of every material at default occupancy, long enough for the
// largest box (32), shared read-only by every box.
extern const std::array<std::array<Voxel, 32>, kMaterialCount> kUniformRows;
inline const Voxel* uniform_row(Material material) { return kUniformRows[material & 63].data(); }
// Per-size tables of all-uniform headers, for boxes that own none.
const std::uint16_t* uniform_headers(int size, Material material);

inline constexpr std::uint8_t kPaletteTag = 0x40;  // encode_row: first bytes below it are raw
inline constexpr std::uint8_t kTagOccupancy = 0x20;
inline constexpr std::uint8_t kTagThreeBits = 0x10;
inline constexpr int kMaxPalette = 16;

inline int index_bits(unsigned info) {
  return (info >> 6) == 3 ? ((info & kTagThreeBits) ? 3 : 4) : static_cast<int>(info >> 6);
}
// Bytes of a table entry with this info byte (before padding to 4).
inline int entry_bytes(unsigned info) {
  return 1 + (static_cast<int>(info & 15) + 1) * ((info & kTagOccupancy) ? 2 : 1);
}
// Index bytes of a palette row of n voxels.
inline int index_bytes(unsigned info, int n) { return (n * index_bits(info) + 7) / 8; }

// Encodes row (n voxels, Air already normalised) into a self-contained form:
// returns 0 for a uniform row (default occupancy, one material: the caller
// stores only a header); 2n for a raw record (the n voxels, written to out);
// else a palette form of fewer than 2n bytes: a table entry (info, sorted
// palette) directly followed by the index bytes. out has capacity >= 2n.
int encode_row(const Voxel* row, int n, std::uint8_t* out);
// Index bytes of row (n voxels) against an existing table entry, into idx
// (capacity 2n). False when some voxel is not in the entry's palette.
bool encode_with_entry(const Voxel* row, int n, const std::uint8_t* entry, std::uint8_t* idx);

// Palette row (table entry + index bytes) -> n voxels. The scalar decoder is
// the reference.
void decode_palette_scalar(const std::uint8_t* entry, const std::uint8_t* idx, Voxel* out, int n);
#if defined(__x86_64__) || defined(__i386__)
// The SSSE3 decoder for n = 32 (row_packed_simd.h) reads 16 bytes at
// entry + 1, at the occupancies and at idx (at most 15 past the entry and
// 11 past the indices). Without compile-time SSSE3, call it only when
// kHaveSsse3.
extern const bool kHaveSsse3;
#endif

// One voxel of a palette row (constant time).
inline Voxel palette_voxel(const std::uint8_t* entry, const std::uint8_t* idx, int n, int x) {
  const unsigned info = entry[0];
  const int bits = index_bits(info);
  const int p = static_cast<int>(info & 15) + 1;
  const bool occ = (info & kTagOccupancy) != 0;
  const int groups = (n * bits + 7) / 8;
  int i;
  if (bits == 1) {
    i = (idx[x / 8] >> (x % 8)) & 1;
  } else if (bits == 3) {  // a 2-bit plane, then a 1-bit plane for index bit 2
    const int g2 = (2 * n + 7) / 8;
    i = ((idx[x % g2] >> (2 * (x / g2))) & 3) | (((idx[g2 + x / 8] >> (x % 8)) & 1) << 2);
  } else {
    i = (idx[x % groups] >> (bits * (x / groups))) & ((1 << bits) - 1);
  }
  const Material m = entry[1 + i];
  return Voxel{m, occ ? entry[1 + p + i] : default_occupancy(m)};
}
}  // namespace row_packed_detail

struct RowPackedStats {
  std::size_t uniform_rows = 0;  // header only
  std::size_t raw_rows = 0;      // allocated rows carrying per-voxel occupancy (raw or palette record)
  std::size_t byte_rows = 0;     // allocated rows of default occupancy stored as palette records
  std::size_t palette_rows = 0;  // allocated rows stored as palette records
  std::size_t shared_rows = 0;   // allocated rows whose record an earlier row already uses
  std::size_t data_bytes = 0;    // palette table, records and padding
};

template <int N>
class RowPackedBox {
 public:
  static_assert(N == 4 || N == 8 || N == 16 || N == 32, "row-packed boxes are 4, 8, 16 or 32 wide");
  static constexpr int kSize = N;
  static constexpr int kRows = N * N;
  static constexpr std::uint16_t kAllocated = 0x8000;
  static constexpr std::uint16_t kPaletteRow = 0x4000;
  static constexpr std::uint16_t kOffsetMask = 0x3FFF;
  // Boxes narrower than 32 keep each palette inline in its record (their
  // rows rarely share palettes); 32³ boxes use the table.
  static constexpr bool kInlinePalettes = N < 32;
  // Voxels of padding after the records when a palette row exists: the
  // SSSE3 decoder (N = 32 only) loads 16 bytes at the palette, the
  // occupancies and the indices, at most 15 bytes past the table or 11 past
  // the last record.
  static constexpr std::uint32_t kPadUnits = N == 32 ? 8 : 0;
  // Repacks allowed between two compact() calls before the box unpacks
  // itself for good: enough that ordinary editing stays packed, few enough
  // that a stream of tiny writes costs at most a bounded number of copies.
  static constexpr int kRepackBudget = 32;
  static constexpr std::uint8_t kPackedShift = 2;

  // A scratch row for read_row to decode palette rows into.
  using Row = std::array<Voxel, N>;

  explicit RowPackedBox(Material fill = kAir);
  // A moved-from box is left uniform Air, usable as any other.
  RowPackedBox(RowPackedBox&& other) noexcept { *this = std::move(other); }
  RowPackedBox& operator=(RowPackedBox&& other) noexcept {
    if (this == &other) return *this;
    headers_ = other.headers_;
    owned_headers_ = std::move(other.owned_headers_);
    data_ = std::move(other.data_);
    data_units_ = other.data_units_;
    raw_base_ = other.raw_base_;
    repacks_ = other.repacks_;
    entry_shift_ = other.entry_shift_;
    other.headers_ = row_packed_detail::uniform_headers(N, kAir);
    other.data_units_ = 0;
    other.raw_base_ = 0;
    other.repacks_ = 0;
    other.entry_shift_ = kPackedShift;
    return *this;
  }
  RowPackedBox(const RowPackedBox&) = delete;
  RowPackedBox& operator=(const RowPackedBox&) = delete;
  ~RowPackedBox() = default;

  RowPackedBox clone() const;

  // The article's readRow: the N voxels of row (y, z). Returns a pointer into
  // the box, into the shared uniform rows, or (for palette rows) into scratch.
  // The pointer is valid until the next write or until scratch is reused.
  const Voxel* read_row(int y, int z, Row& scratch) const {
    const std::uint16_t h = headers_[y * N + z];
    if (!(h & kAllocated)) return row_packed_detail::uniform_row(static_cast<Material>(h & 63));
    if (!(h & kPaletteRow)) return raw_record(h);
    const std::uint8_t* rec = bytes() + (h & kOffsetMask);
    const std::uint8_t* entry = entry_of(rec);
    decode(entry, indices_of(rec, entry), scratch.data());
    return scratch.data();
  }

  Voxel get(int x, int y, int z) const {
    const std::uint16_t h = headers_[y * N + z];
    if (!(h & kAllocated)) return solid(static_cast<Material>(h & 63));
    if (!(h & kPaletteRow)) return raw_record(h)[x];
    const std::uint8_t* rec = bytes() + (h & kOffsetMask);
    const std::uint8_t* entry = entry_of(rec);
    return row_packed_detail::palette_voxel(entry, indices_of(rec, entry), N, x);
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
  bool is_uniform() const { return owned_headers_ == nullptr; }
  Material uniform_material() const { return static_cast<Material>(headers_[0] & 63); }
  bool unpacked() const { return entry_shift_ == 0; }

  // Pessimistic full unpack: every row its own raw record, so writes never repack.
  void unpack_all();
  // Repacks every row to its smallest record, shares identical records and
  // palettes and leaves unpacked mode.
  void compact();

  // Every heap byte this box owns (headers, table, records, padding), not
  // counting sizeof(*this).
  std::size_t heap_bytes() const;
  RowPackedStats stats() const;

 private:
  static void decode(const std::uint8_t* entry, const std::uint8_t* idx, Voxel* out) {
#if defined(__x86_64__) || defined(__i386__)
    if constexpr (N == 32) {
#if defined(__SSSE3__)
      row_packed_detail::decode_palette32_ssse3(entry, idx, out);
      return;
#endif
      if (row_packed_detail::kHaveSsse3) {
        row_packed_detail::decode_palette32_ssse3(entry, idx, out);
        return;
      }
    }
#endif
    row_packed_detail::decode_palette_scalar(entry, idx, out, N);
  }
  const std::uint8_t* bytes() const { return reinterpret_cast<const std::uint8_t*>(data_.get()); }
  // A palette record's table entry and index bytes.
  const std::uint8_t* entry_of(const std::uint8_t* rec) const {
    if constexpr (kInlinePalettes) return rec;
    return bytes() + (std::size_t{rec[0]} << entry_shift_);
  }
  static const std::uint8_t* indices_of(const std::uint8_t* rec, const std::uint8_t* entry) {
    if constexpr (kInlinePalettes) return rec + row_packed_detail::entry_bytes(entry[0]);
    return rec + 1;
  }
  const Voxel* raw_record(std::uint16_t h) const {
    return data_.get() + raw_base_ + std::size_t{static_cast<unsigned>(h & kOffsetMask)} * N;
  }
  Voxel* raw_record_mut(std::uint16_t h) {
    return data_.get() + raw_base_ + std::size_t{static_cast<unsigned>(h & kOffsetMask)} * N;
  }
  void read_row_into(int y, int z, Voxel* out) const;
  // The self-contained encoding (as encode_row) of a stored row, into out
  // (capacity 2N). Returns its size (0 for uniform rows).
  int stored_encoding(std::uint16_t h, std::uint8_t* out) const;
  // Rebuilds all storage at once: rows in the rectangle y0..y1 × z0..z1 take
  // the encodings given (row-major in that rectangle, as encode_row: sizes[i]
  // == 0 means uniform with materials[i], else the encoding at records +
  // i·2N); other rows keep theirs. Identical palettes and records are stored
  // once. Becomes uniform when every row ends up uniform alike.
  void rebuild_rect(int y0, int y1, int z0, int z1, const std::uint8_t* records, const std::uint16_t* sizes,
                    const Material* materials);
  void become_uniform(Material m);
  std::uint16_t* mutable_headers();

  const std::uint16_t* headers_ = row_packed_detail::uniform_headers(N, kAir);  // N² headers: owned_headers_ or a shared table
  std::unique_ptr<std::uint16_t[]> owned_headers_;  // null for a uniform box
  std::unique_ptr<Voxel[]> data_;  // palette table, palette records, raw records, kPadUnits of padding
  std::uint32_t data_units_ = 0;   // voxels allocated in data_ (0 when none)
  std::uint16_t raw_base_ = 0;     // voxel offset of raw record 0 in data_
  std::uint8_t repacks_ = 0;       // since the last compact()
  // log2 of the table's entry unit (2, or 3 when 4-byte units would need
  // more than 256 ids); 0 in unpacked mode.
  std::uint8_t entry_shift_ = kPackedShift;
};

}  // namespace terrane

#include "common/row_packed_box_impl.h"
