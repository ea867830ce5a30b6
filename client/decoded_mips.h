// DecodedMips: the mips and horizon images of the replicas of one
// process, kept once for all the replicas that hold equal ones.
//
// A process running many clients (the terrane-bots load test) receives
// the same mip of a chunk version once per client whose view holds it at
// that level, and the same horizon image once per client that sees the
// region from afar; kept per client, those copies were most of a bot's
// memory. A replica never changes a mip or an image in place (a record
// replaces it whole; updates apply to full-resolution chunks only), so
// replicas can hold them as one immutable object.
//
// Mips are kept as their record's bytes (a MipUnit: the network-codec
// unit, several times smaller than its voxels) and horizon images as
// voxels (a Box: one a region, read often). Found by a key the caller
// derives from the record (a hash of its bytes), and taken only when the
// bytes (units) or the voxels (boxes) are equal too: nothing is trusted
// across clients but that comparison, so a replica holds exactly what its
// own record says (entries whose keys are equal but contents differ are
// kept side by side).
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

namespace terrane {

// A mip's voxels as one network-codec unit (NET_CODEC.md) of side^3
// voxels: the bytes of the record that brought it. Immutable; the bytes
// decoded once before they were kept, so they always decode.
struct MipUnit {
  int side = 0;
  std::vector<std::uint8_t> bytes;

  // Its voxels into out (resized to side^3).
  void decode(Box& out) const;
  // Heap bytes, with the object itself.
  std::size_t heap_bytes() const { return sizeof(MipUnit) + bytes.capacity(); }
};

class DecodedMips {
 public:
  // The key of a record's bytes (payload) at a level (the same bytes at
  // another level are other voxels).
  static std::size_t key_of(std::span<const std::uint8_t> bytes, int level);
  // The key of voxels themselves (for records whose bytes the caller does
  // not have).
  static std::size_t key_of(const Box& voxels);

  // An immutable box equal to voxels: one kept under key whose voxels are
  // equal, else a new one, kept under key from now on.
  std::shared_ptr<const Box> intern(std::size_t key, const Box& voxels);
  // The same for a mip's unit: one kept under key of this side and these
  // very bytes, else a new one. Precondition: bytes are one unit of side^3
  // voxels that decoded without error.
  std::shared_ptr<const MipUnit> intern_unit(std::size_t key, int side, std::span<const std::uint8_t> bytes);

  struct Stats {
    std::uint64_t hits = 0, misses = 0;
    std::size_t entries = 0;  // live boxes and units kept
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
  // Keeps the live items only, in a table of at least twice their number.
  template <class T>
  static void rebuild(Table<T>& t);

  mutable std::mutex m_;
  Table<Box> boxes_;
  Table<MipUnit> units_;
  Stats stats_;
};

}  // namespace terrane
