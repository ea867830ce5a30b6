// RowPackedBox<N>: an N³ box of voxels stored row-packed, the in-memory format
// of the storage article ("Memory format, take two"), used for a chunk's full
// resolution (N = 32) and for each level of its mip pyramid (16, 8, 4).
//
// Each of the N² rows along x, addressed by (y, z), has a 2-byte header:
//
//   bit 15 14 13 ........ 0
//        0  -  -  . material   uniform row: N voxels of `material`, default occupancy
//        1  0  offset          raw row: N voxels at raw_[offset * N] (2 bytes each)
//        1  1  offset          byte row: N materials at bytes_[offset * N], every
//                              voxel with its material's default occupancy
//
// Uniform rows cost only their header; read_row returns a pointer into a
// shared read-only table of pre-filled rows per material, so it stays
// constant-time. Byte rows are this implementation's addition to the article:
// rows whose voxels all have default occupancy (ores, strata, block worlds)
// keep one byte per voxel and are widened into the caller's scratch row on
// read, still constant-time. A box whose rows are all uniform with one
// material owns no headers at all: it points at a shared header table
// ("a uniform chunk stores one value").
//
// Writes are two-stage, as in the article: the rows a write touches are
// materialised and classified first, storage is reallocated at most once when
// the row classes change, then written. A box that keeps being repacked by
// small writes switches to unpacked mode (every row raw, writes in place, no
// repacking) until compact() is called.
//
// Invariants: headers_ points at N² headers; raw_count_ and byte_count_ are
// the exact sizes (in rows) of raw_ and bytes_, every allocated header's
// offset is below its array's count and each slot is used by one row only;
// no stored voxel is Air with non-zero occupancy.
// Thread-safety: const methods may run concurrently; writes need exclusion.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/voxel.h"

namespace terrane {

namespace row_packed_detail {
// Pre-filled rows of every material at default occupancy, long enough for the
// largest box (32), shared read-only by every box.
extern const std::array<std::array<Voxel, 32>, kMaterialCount> kUniformRows;
inline const Voxel* uniform_row(Material material) { return kUniformRows[material & 63].data(); }
// Byte-row widening; the scalar path is the reference the SIMD path is tested
// against. n is a multiple of 16 for the SSE2 path.
inline void widen_scalar(const std::uint8_t* materials, Voxel* out, int n) {
  for (int i = 0; i < n; ++i) out[i] = solid(materials[i]);
}
#if defined(__SSE2__)
inline void widen_sse2(const std::uint8_t* materials, Voxel* out, int n) {
  const __m128i zero = _mm_setzero_si128();
  const __m128i ones = _mm_set1_epi8(-1);
  for (int i = 0; i < n; i += 16) {
    const __m128i m = _mm_loadu_si128(reinterpret_cast<const __m128i*>(materials + i));
    const __m128i occ = _mm_andnot_si128(_mm_cmpeq_epi8(m, zero), ones);  // 255 unless Air
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i), _mm_unpacklo_epi8(m, occ));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i + 8), _mm_unpackhi_epi8(m, occ));
  }
}
#endif
// Per-size tables of all-uniform headers, for boxes that own none.
const std::uint16_t* uniform_headers(int size, Material material);
}  // namespace row_packed_detail

struct RowPackedStats {
  std::size_t uniform_rows = 0;
  std::size_t raw_rows = 0;
  std::size_t byte_rows = 0;
};

template <int N>
class RowPackedBox {
 public:
  static_assert(N == 4 || N == 8 || N == 16 || N == 32, "row-packed boxes are 4, 8, 16 or 32 wide");
  static constexpr int kSize = N;
  static constexpr int kRows = N * N;
  static constexpr std::uint16_t kAllocated = 0x8000;
  static constexpr std::uint16_t kByteRow = 0x4000;
  static constexpr std::uint16_t kOffsetMask = 0x3FFF;
  // Repacks allowed between two compact() calls before the box unpacks
  // itself for good: enough that ordinary editing stays packed, few enough
  // that a stream of tiny writes costs at most a bounded number of copies.
  static constexpr int kRepackBudget = 32;

  // A scratch row for read_row to widen byte rows into.
  using Row = std::array<Voxel, N>;

  explicit RowPackedBox(Material fill = kAir);
  RowPackedBox(RowPackedBox&&) noexcept = default;
  RowPackedBox& operator=(RowPackedBox&&) noexcept = default;
  RowPackedBox(const RowPackedBox&) = delete;
  RowPackedBox& operator=(const RowPackedBox&) = delete;
  ~RowPackedBox() = default;

  RowPackedBox clone() const;

  // The article's readRow: the N voxels of row (y, z). Returns a pointer into
  // the box, into the shared uniform rows, or (for byte rows) into scratch.
  // The pointer is valid until the next write or until scratch is reused.
  const Voxel* read_row(int y, int z, Row& scratch) const {
    const std::uint16_t h = headers_[y * N + z];
    if (!(h & kAllocated)) return row_packed_detail::uniform_row(static_cast<Material>(h & 63));
    const std::size_t at = static_cast<std::size_t>(h & kOffsetMask) * N;
    if (!(h & kByteRow)) return raw_.get() + at;
    widen(bytes_.get() + at, scratch.data());
    return scratch.data();
  }

  Voxel get(int x, int y, int z) const {
    const std::uint16_t h = headers_[y * N + z];
    if (!(h & kAllocated)) return solid(static_cast<Material>(h & 63));
    const std::size_t at = static_cast<std::size_t>(h & kOffsetMask) * N + x;
    return (h & kByteRow) ? solid(bytes_[at]) : raw_[at];
  }

  // Rewrites rows y in [y0, y1), z in [z0, z1): for each, fn(y, z, row)
  // receives the row's current N voxels in `row` and leaves the new content
  // there. Air occupancy is normalised afterwards. Two-stage as described
  // above. Preconditions: 0 <= y0 <= y1 <= N, same for z.
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

  // Pessimistic full unpack: every row raw, so writes never repack.
  void unpack_all();
  // Repacks every row to its smallest class and leaves unpacked mode.
  void compact();

  // Every heap byte this box owns (headers, raw rows, byte rows), not
  // counting sizeof(*this).
  std::size_t heap_bytes() const;
  RowPackedStats stats() const;

 private:
  enum class RowClass : std::uint8_t { kUniform, kRaw, kByte };
  struct Classified {
    RowClass cls;
    Material material;  // for kUniform
  };

  // Byte row -> voxels: each material with its default occupancy.
  static void widen(const std::uint8_t* materials, Voxel* out) {
#if defined(__SSE2__)
    if constexpr (N % 16 == 0) {
      row_packed_detail::widen_sse2(materials, out, N);
      return;
    }
#endif
    row_packed_detail::widen_scalar(materials, out, N);
  }
  static Classified classify(const Voxel* row);
  void read_row_into(int y, int z, Voxel* out) const;
  RowClass class_of(std::uint16_t h) const {
    return !(h & kAllocated) ? RowClass::kUniform : ((h & kByteRow) ? RowClass::kByte : RowClass::kRaw);
  }
  // Reallocates storage once so that the rows in y0..y1 x z0..z1 take the
  // new content and classes given (row-major in that rectangle); other rows
  // keep theirs. Becomes uniform when every row ends up uniform alike.
  void rebuild_rect(int y0, int y1, int z0, int z1, const Voxel* content, const Classified* classes);
  void become_uniform(Material m);
  std::uint16_t* mutable_headers();

  const std::uint16_t* headers_;        // N² headers: owned_headers_ or a shared table
  std::unique_ptr<std::uint16_t[]> owned_headers_;
  std::unique_ptr<Voxel[]> raw_;
  std::unique_ptr<std::uint8_t[]> bytes_;
  std::uint16_t raw_count_ = 0;   // rows in raw_
  std::uint16_t byte_count_ = 0;  // rows in bytes_
  std::uint16_t repacks_ = 0;     // since the last compact()
  bool owns_headers_ = false;
  bool unpacked_ = false;
};

}  // namespace terrane

#include "common/row_packed_box_impl.h"
