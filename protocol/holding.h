// Holding: what a client holds of one 32³ chunk — the chunk's form (how
// much of it, and how exact) and the revision of the chunk it came from.
//
// One name for one idea on every side of the wire (PROTOCOL.md,
// "Holdings"): the form a stream record gives its chunk, a Holdings entry
// of a resuming client, the server's record of what each client holds,
// the client library's replica, and the bots, Python and the viewer, which
// all ask the client library.
//
// A chunk not held has no Holding (it is unknown, never Air).
//
// The numbers are the wire's: a stream record of kind 0..5 gives its chunk
// that form, and a Holdings entry carries one of 0..4. The horizon forms
// (6, 7) come only from a region's horizon image record, never as a
// chunk's own record, and are never claimed.
#pragma once

#include <cstdint>

namespace terrane {

enum class HoldingForm : std::uint8_t {
  kFull = 0,      // every voxel, at the revision
  kMip1 = 1,      // mip level 1: the chunk's 16^3 mip
  kMip2 = 2,      // mip level 2: 8^3
  kMip3 = 3,      // mip level 3: 4^3
  kEmpty = 4,     // all Air, known at full resolution
  kEstimate = 5,  // a 4^3 mip estimated from the world's generator for a
                  // chunk never generated (revision 0): approximate
  kHorizon4 = 6,  // 2^3 voxels from its region's horizon image: approximate
  kHorizon5 = 7,  // 1 voxel from its region's horizon image: approximate
};

inline constexpr int kHoldingForms = 8;

// The mip level's form (level 1..3).
constexpr HoldingForm mip_form(int level) { return static_cast<HoldingForm>(level); }
// The form a horizon image of level 4..6 gives the chunks it covers: level
// 6 (one voxel per 2^3 chunks) gives each chunk its block's voxel, Horizon 5.
constexpr HoldingForm horizon_form(int level) {
  return level <= 4 ? HoldingForm::kHorizon4 : HoldingForm::kHorizon5;
}

struct Holding {
  HoldingForm form = HoldingForm::kEmpty;
  std::uint64_t revision = 0;

  // The detail held, as a mip level: 0 every voxel (Full, Empty), 1..3 a
  // mip (an Estimate is level 3), 4..5 a horizon image's.
  constexpr int level() const {
    switch (form) {
      case HoldingForm::kFull:
      case HoldingForm::kEmpty: return 0;
      case HoldingForm::kEstimate: return 3;
      case HoldingForm::kHorizon4: return 4;
      case HoldingForm::kHorizon5: return 5;
      default: return static_cast<int>(form);
    }
  }
  // Every voxel known (Full or Empty): chunk hashes, edits, updates.
  constexpr bool full_resolution() const { return form == HoldingForm::kFull || form == HoldingForm::kEmpty; }
  // A mip of the chunk's own voxels (Mip 1..3).
  constexpr bool mip() const { return form >= HoldingForm::kMip1 && form <= HoldingForm::kMip3; }
  // Not made from the chunk's voxels at the revision (an Estimate, a
  // horizon image's): never claimed in Holdings, hashed or edited.
  constexpr bool approximate() const { return form >= HoldingForm::kEstimate; }
  constexpr bool horizon() const { return form == HoldingForm::kHorizon4 || form == HoldingForm::kHorizon5; }

  friend constexpr bool operator==(const Holding&, const Holding&) = default;
};

// A Holdings entry's form must be one of these (approximate forms are
// never claimed: their revision does not identify their voxels).
constexpr bool claimable(HoldingForm f) { return static_cast<int>(f) <= static_cast<int>(HoldingForm::kEmpty); }

// "Full", "Mip1", ..., "Horizon5": for messages and reports.
constexpr const char* form_name(HoldingForm f) {
  switch (f) {
    case HoldingForm::kFull: return "Full";
    case HoldingForm::kMip1: return "Mip1";
    case HoldingForm::kMip2: return "Mip2";
    case HoldingForm::kMip3: return "Mip3";
    case HoldingForm::kEmpty: return "Empty";
    case HoldingForm::kEstimate: return "Estimate";
    case HoldingForm::kHorizon4: return "Horizon4";
    case HoldingForm::kHorizon5: return "Horizon5";
  }
  return "?";
}

}  // namespace terrane
