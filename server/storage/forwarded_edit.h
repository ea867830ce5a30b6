// An edit forwarded between the servers of a shared world as its inbox row
// stores it (STORE_POSTGRESQL.md, "Forwarded edits"): the EditRequest
// frame its client sent, header and all. The cluster room encodes it where
// the row is written (ClusterControl::forward); the world decodes a row it
// takes (SharedAuthority), checking it as a client's frame is checked.
// Threading: plain functions, any thread.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "protocol/messages.h"

namespace terrane {

// The stored bytes of edit: build_edit_request(edit), so the rows keep the
// format they had (a server of another build reads them).
std::vector<std::uint8_t> encode_forwarded_edit(const EditRequestMsg& edit);

// Another server's row, checked as a client's frame is (its length, the
// message, its meaning); an error when it is not an EditRequest frame.
Result<EditRequestMsg> decode_forwarded_edit(std::span<const std::uint8_t> frame);

}  // namespace terrane
