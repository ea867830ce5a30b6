// RowPackedBox<N>: an N³ box of voxels stored row-packed, the in-memory format
// of the storage article ("Memory format, take two"), used for a chunk's full
// resolution (N = 32) and for each level of its mip pyramid (16, 8, 4).
//
// Each of the N² rows along x, addressed by (y, z), has a 2-byte header:
//
//   bit 15 14 ........... 0
//        0  -  . material      uniform row: N voxels of `material`, default occupancy
//        1  offset             allocated row: its record starts at data_[offset]
//                              (offset in voxels, i.e. 2-byte units: 15 bits
//                              address 64 KiB, the size of an all-raw 32³ box)
//
// An allocated row's record says what it is in its first byte:
//
//   raw record (first byte < 0x40, it is voxel 0's material), 2N bytes:
//     +------+------+------+------+-- ... --+
//     | m0   | occ0 | m1   | occ1 |         |   read_row returns a pointer to it
//     +------+------+------+------+-- ... --+
//
//   palette record (first byte >= 0x40), padded to an even length:
//     +-----+-----------+---------------+-------------------+
//     | tag | P mats    | P occupancies | G index bytes     |
//     +-----+-----------+---------------+-------------------+
//     tag bits 7-6: index width b (1 = 1 bit, 2 = 2 bits, 3 = 4 bits)
//         bit 5: occupancies present (else each voxel has its material's
//                default occupancy and the occupancy bytes are absent)
//         bit 4: 0;  bits 3-0: P - 1 (P = 1..16 palette entries)
//     G = ceil(N·b / 8) index bytes. 1 bit: voxel x is bit x % 8 of byte
//     x / 8. 2 and 4 bits: voxel x's index is the b bits at bit b·(x / G) of
//     byte x % G, which for N = 32 puts voxels 0..15 and 16..31 in the two
//     halves of an SSE register after a few shifts. The SSSE3 decoder expands
//     a row with shifts, masks and pshufb lookups, without branches.
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
// record size (and its record is not shared) the new records are written in
// place, otherwise the box is rebuilt once with one allocation. A box that
// keeps being rebuilt by small writes switches to unpacked mode (every row a
// raw record of its own at offset r·N, writes in place, no repacking) until
// compact() is called.
//
// Invariants: headers_ points at N² headers; every allocated header's offset
// starts a valid record inside data_; data_ holds data_units_ voxels of which
// the last kPadUnits are padding so the SIMD decoder may over-read; records
// are shared only outside unpacked mode; no stored voxel is Air with non-zero
// occupancy; every material is < 64.
// Thread-safety: const methods may run concurrently; writes need exclusion.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>

#include "common/voxel/row_packed_simd.h"
#include "common/voxel/voxel.h"

namespace terrane {

namespace row_packed_detail {
// Pre-filled rows of every material at default occupancy, long enough for the
// largest box (32), shared read-only by every box.
extern const std::array<std::array<Voxel, 32>, kMaterialCount> kUniformRows;
inline const Voxel* uniform_row(Material material) { return kUniformRows[material & 63].data(); }
// Per-size tables of all-uniform headers, for boxes that own none.
const std::uint16_t* uniform_headers(int size, Material material);

inline constexpr std::uint8_t kPaletteTag = 0x40;  // first record bytes below it are raw
inline constexpr std::uint8_t kTagOccupancy = 0x20;
inline constexpr int kMaxPalette = 16;

// Bytes of the record starting at rec (even). Precondition: a valid record for n.
inline int record_bytes(const std::uint8_t* rec, int n) {
  const unsigned tag = rec[0];
  if (tag < kPaletteTag) return 2 * n;
  const int bits = (tag >> 6) == 3 ? 4 : static_cast<int>(tag >> 6);
  const int p = static_cast<int>(tag & 15) + 1;
  const int size = 1 + p * ((tag & kTagOccupancy) ? 2 : 1) + (n * bits + 7) / 8;
  return (size + 1) & ~1;
}

// Encodes row (n voxels, Air already normalised). Returns 0 for a uniform row
// (default occupancy, one material: the caller stores only a header), else
// the record's even length, written to out (capacity >= 2n bytes). Chooses a
// palette record when it is shorter than the raw one.
int encode_row(const Voxel* row, int n, std::uint8_t* out);

// Palette record -> n voxels. The scalar decoder is the reference.
void decode_palette_scalar(const std::uint8_t* rec, Voxel* out, int n);
#if defined(__x86_64__) || defined(__i386__)
// The SSSE3 decoder for n = 32 (row_packed_simd.h) may read up to 16 bytes
// past the record. Without compile-time SSSE3, call it only when kHaveSsse3.
extern const bool kHaveSsse3;
#endif

// One voxel of a palette record (constant time).
inline Voxel palette_voxel(const std::uint8_t* rec, int n, int x) {
  const unsigned tag = rec[0];
  const int bits = (tag >> 6) == 3 ? 4 : static_cast<int>(tag >> 6);
  const int p = static_cast<int>(tag & 15) + 1;
  const bool occ = (tag & kTagOccupancy) != 0;
  const int groups = (n * bits + 7) / 8;
  const std::uint8_t* idx = rec + 1 + p * (occ ? 2 : 1);
  const int i = bits == 1 ? (idx[x / 8] >> (x % 8)) & 1 : (idx[x % groups] >> (bits * (x / groups))) & ((1 << bits) - 1);
  const Material m = rec[1 + i];
  return Voxel{m, occ ? rec[1 + p + i] : default_occupancy(m)};
}
}  // namespace row_packed_detail

struct RowPackedStats {
  std::size_t uniform_rows = 0;  // header only
  std::size_t raw_rows = 0;      // allocated rows carrying per-voxel occupancy (raw or palette record)
  std::size_t byte_rows = 0;     // allocated rows of default occupancy (palette, or raw when > 16 materials)
  std::size_t palette_rows = 0;  // allocated rows stored as palette records
  std::size_t shared_rows = 0;   // allocated rows whose record an earlier row already uses
  std::size_t data_bytes = 0;    // record bytes including padding
};

template <int N>
class RowPackedBox {
 public:
  static_assert(N == 4 || N == 8 || N == 16 || N == 32, "row-packed boxes are 4, 8, 16 or 32 wide");
  static constexpr int kSize = N;
  static constexpr int kRows = N * N;
  static constexpr std::uint16_t kAllocated = 0x8000;
  static constexpr std::uint16_t kOffsetMask = 0x7FFF;
  // Voxels of padding after the records: the SSSE3 decoder (N = 32 only)
  // loads 16 bytes at the palette, the occupancies and the indices, at most
  // 12 bytes past the shortest record.
  static constexpr std::uint32_t kPadUnits = N == 32 ? 8 : 0;
  // Repacks allowed between two compact() calls before the box unpacks
  // itself for good: enough that ordinary editing stays packed, few enough
  // that a stream of tiny writes costs at most a bounded number of copies.
  static constexpr int kRepackBudget = 32;

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
    repacks_ = other.repacks_;
    owns_headers_ = other.owns_headers_;
    unpacked_ = other.unpacked_;
    other.headers_ = row_packed_detail::uniform_headers(N, kAir);
    other.data_units_ = 0;
    other.repacks_ = 0;
    other.owns_headers_ = false;
    other.unpacked_ = false;
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
    const Voxel* rec = data_.get() + (h & kOffsetMask);
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(rec);
    if (bytes[0] < row_packed_detail::kPaletteTag) return rec;
    decode(bytes, scratch.data());
    return scratch.data();
  }

  Voxel get(int x, int y, int z) const {
    const std::uint16_t h = headers_[y * N + z];
    if (!(h & kAllocated)) return solid(static_cast<Material>(h & 63));
    const Voxel* rec = data_.get() + (h & kOffsetMask);
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(rec);
    if (bytes[0] < row_packed_detail::kPaletteTag) return rec[x];
    return row_packed_detail::palette_voxel(bytes, N, x);
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
  Material uniform_material() const { return static_cast<Material>(headers_[0] & 63); }
  bool unpacked() const { return unpacked_; }

  // Pessimistic full unpack: every row its own raw record, so writes never repack.
  void unpack_all();
  // Repacks every row to its smallest record, shares identical records and
  // leaves unpacked mode.
  void compact();

  // Every heap byte this box owns (headers, records, padding), not counting
  // sizeof(*this).
  std::size_t heap_bytes() const;
  RowPackedStats stats() const;

 private:
  static void decode(const std::uint8_t* rec, Voxel* out) {
#if defined(__x86_64__) || defined(__i386__)
    if constexpr (N == 32) {
#if defined(__SSSE3__)
      row_packed_detail::decode_palette32_ssse3(rec, out);
      return;
#endif
      if (row_packed_detail::kHaveSsse3) {
        row_packed_detail::decode_palette32_ssse3(rec, out);
        return;
      }
    }
#endif
    row_packed_detail::decode_palette_scalar(rec, out, N);
  }
  const std::uint8_t* record(std::uint16_t h) const {
    return reinterpret_cast<const std::uint8_t*>(data_.get() + (h & kOffsetMask));
  }
  void read_row_into(int y, int z, Voxel* out) const;
  // Rebuilds all storage at once: rows in the rectangle y0..y1 × z0..z1 take
  // the encodings given (row-major in that rectangle: sizes[i] == 0 means
  // uniform with materials[i], else the record at records + i·2N); other rows
  // keep theirs. Identical records are stored once. Becomes uniform when every
  // row ends up uniform alike.
  void rebuild_rect(int y0, int y1, int z0, int z1, const std::uint8_t* records, const std::uint16_t* sizes,
                    const Material* materials);
  void become_uniform(Material m);
  std::uint16_t* mutable_headers();

  const std::uint16_t* headers_ = row_packed_detail::uniform_headers(N, kAir);  // N² headers: owned_headers_ or a shared table
  std::unique_ptr<std::uint16_t[]> owned_headers_;
  std::unique_ptr<Voxel[]> data_;  // records, then kPadUnits of padding
  std::uint32_t data_units_ = 0;   // voxels allocated in data_ (0 when none)
  std::uint16_t repacks_ = 0;      // since the last compact()
  bool owns_headers_ = false;
  bool unpacked_ = false;
};

}  // namespace terrane

#include "common/voxel/row_packed_box_impl.h"
