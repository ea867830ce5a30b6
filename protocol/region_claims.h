// Region claims (PROTOCOL.md, "Resuming after a reconnect"): a resuming
// client's claims (Holdings), region by region, as bytes. A region is the
// 8^3 chunks of a horizon image (coarse_region_of); its 512 chunks, in
// horizon-mask order (i = (y*8 + z)*8 + x), are runs of equal claims, so
// a view of unchanged terrain is claimed in a few bytes a region instead
// of 32 a chunk (HeldChunk).
//
// encode_region_claims and decode_region_claims are the format; the
// server takes the decoded claims as it takes HeldChunk entries.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/decode_error.h"
#include "protocol/messages.h"

namespace terrane {

// The chunks of a region, and what a region's runs add up to.
inline constexpr std::size_t kRegionClaimSlots = 512;
// A run's form byte for chunks not claimed.
inline constexpr std::uint8_t kRegionClaimNone = 15;

// Appends the bytes of claims (any order; each chunk at most once) to out,
// regions in ascending (y, z, x) order.
void encode_region_claims(std::span<const HeldChunkMsg> claims, std::vector<std::uint8_t>& out);

// Appends the claims of bytes to out, regions in the order sent, each
// region's chunks in index order. Errors, each with the offset of the
// byte at fault: truncation, a varint too long, a region count of 0, a run
// count of 0 or over 512, a run of 0 chunks or past the 512th, runs that
// end before the 512th, a form other than 0..4 or 15, a chunk beyond the
// wire's range (±2^19), trailing bytes, and more than max_claims claims
// in all (out's size counts).
Status decode_region_claims(std::span<const std::uint8_t> bytes, std::vector<HeldChunkMsg>& out,
                            std::size_t max_claims);

}  // namespace terrane
