// DecodedMips: the mips and horizon images of the replicas of one
// process, kept once for all the replicas that hold equal ones.
//
// A process running many clients (the terrane-bots load test) receives
// the same mip of a chunk version once per client whose view holds it at
// that level, and the same horizon image once per client that sees the
// region from afar; kept per client, those copies were most of a bot's
// memory. A replica never changes a mip or an image in place (a record
// replaces it whole, a patch makes a new one; updates apply to
// full-resolution chunks only), so replicas can hold them as one
// immutable object.
//
// A mip is kept as its record's bytes (MipVoxels in unit form: the
// network-codec unit, several times smaller than its voxels: a bot holds
// thousands of mips and reads few), or as voxels when a patch made it (in
// box form: encoding it again would cost each patch more than it saves);
// horizon images as voxels (a Box: one a region, read often). Found by a
// key the caller derives from the record (a hash of its bytes, or of the
// voxels), and taken only when the bytes (units) or the voxels (boxes) are
// equal too: nothing is trusted across clients but that comparison, so a
// replica holds exactly what its own record says (entries whose keys are
// equal but contents differ are kept side by side).
// Weak: an entry lives as long as some replica holds it; a table forgets
// the dead ones when it is rebuilt (at 3/4 full), so it is bounded by what
// the replicas hold. The tables are flat (open addressing, linear
// probing): a process's bots intern every mip they receive, and a node
// map's lookups cost as much as the rest of applying them.
// Thread-safety: every member may be called from any thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "common/voxel/box.h"
#include "protocol/stream_batch.h"

namespace terrane {

// A held mip's side^3 voxels, immutable: one network-codec unit
// (NET_CODEC.md), the bytes of the record that brought it, which decoded
// without error before they were kept; or the voxels themselves.
class MipVoxels {
 public:
  static MipVoxels of_unit(int side, std::span<const std::uint8_t> bytes);
  static MipVoxels of_box(const Box& voxels);

  int side() const { return side_; }
  bool encoded() const { return !unit_.empty(); }
  std::span<const std::uint8_t> unit() const { return unit_; }
  // The voxels held in box form; null in unit form.
  const Box* box() const { return encoded() ? nullptr : &box_; }
  // The voxels: the box held, or the unit decoded into scratch.
  const Box& read(Box& scratch) const;
  // Heap bytes, with the object itself.
  std::size_t heap_bytes() const;

 private:
  int side_ = 0;
  std::vector<std::uint8_t> unit_;
  Box box_;  // (box form)
};

class DecodedMips {
 public:
  // The key of a record's bytes (payload) at a level (the same bytes at
  // another level are other voxels): of its first kKeyBytes only, so a
  // record's unit is found before it is decoded (known_unit), when its
  // length is not known yet.
  static constexpr std::size_t kKeyBytes = 8;
  // Live items kept under one key at most (units that begin alike, or
  // boxes whose hashes collide): a lookup looks at no more, whatever bytes
  // a server sends; a new one beyond takes the first one's place (and is
  // no longer shared). Terrain's 4^3 units often begin alike: with 4, the
  // join scenario's bots held 150 KiB of mips a bot (and decoded 61,800
  // mip records), with 16, 134 KiB (55,400; 130 KiB before units were
  // found before decoding).
  static constexpr std::size_t kMaxPerKey = 16;
  static std::size_t key_of(std::span<const std::uint8_t> bytes, int level);
  // The key of voxels themselves (for records whose bytes the caller does
  // not have).
  static std::size_t key_of(const Box& voxels);

  // An immutable box equal to voxels: one kept under key whose voxels are
  // equal, else a new one, kept under key from now on.
  std::shared_ptr<const Box> intern(std::size_t key, const Box& voxels);
  // A mip in unit form of these very bytes (side^3 voxels) kept under key,
  // else a new one. Precondition: bytes are one unit of side^3 voxels that
  // decoded without error.
  std::shared_ptr<const MipVoxels> intern_unit(std::size_t key, int side, std::span<const std::uint8_t> bytes);
  // Before decoding a Mip or Estimate record of level: the mip kept here
  // in unit form whose bytes rest (a batch's bytes from the record's
  // payload on) begins with, and their length; {0, null} when none (and
  // always for units shorter than kKeyBytes, which decode at once). The
  // bytes are compared whole: a unit found is exactly the record's.
  KnownPayload known_unit(int level, std::span<const std::uint8_t> rest);
  // A mip in box form of equal voxels kept under key, else a new one.
  std::shared_ptr<const MipVoxels> intern_mip_box(std::size_t key, const Box& voxels);

  struct Stats {
    std::uint64_t hits = 0, misses = 0;
    std::uint64_t known_units = 0;  // of the hits: records not decoded at all (known_unit)
    std::uint64_t units_kept = 0;   // records decoded and kept in unit form (intern_unit calls)
    std::size_t entries = 0;  // live boxes and mips kept
    std::size_t bytes = 0;    // their bytes and the tables (heap)
  };
  Stats stats() const;

 private:
  template <class T>
  struct Table {
    struct Slot {
      std::size_t key = 0;
      std::weak_ptr<const T> item;
      bool used = false;  // an item was kept here (alive or dead since)
    };
    std::vector<Slot> slots;  // a power of two of them, or none
    std::size_t used = 0;     // slots used
  };
  // The live item under key for which same(item) holds, else make()'s,
  // kept under key. Under m_.
  template <class T, class Same, class Make>
  std::shared_ptr<const T> intern_in(Table<T>& t, std::size_t key, Same&& same, Make&& make);
  // Where a key's probe starts in a table of mask + 1 slots. Keys are
  // hashes already; the multiply spreads keys that differ only in their
  // high bits (the level).
  static std::size_t home_slot(std::size_t key, std::size_t mask) { return (key * 0x9E3779B97F4A7C15ull >> 20) & mask; }
  // Keeps the live items only, in a table of at least twice their number.
  template <class T>
  static void rebuild(Table<T>& t);

  mutable std::mutex m_;
  Table<Box> boxes_;
  Table<MipVoxels> mips_;
  Stats stats_;
};

}  // namespace terrane
