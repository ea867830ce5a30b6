// Authentication helpers for the server's sessions: the tokens file and
// the addresses clients come from. (Rates: server/base/rate_limit.h.)
//
// Thread-safety: every function is pure.
#pragma once

#include <cstdint>
#include <string>
#include <unordered_map>

#include "common/world/world_store.h"
#include "server/base/options.h"

namespace terrane {

// A tokens file: one player per line, "NAME TOKEN [ROLE]" separated by
// whitespace, ROLE being player (the default) or admin; blank lines and
// lines starting with '#' are ignored. Errors name the file and line (a
// line without a token, an unknown role, a duplicate name, a name or token
// over the protocol's limits).
FileResult<std::unordered_map<std::string, PlayerToken>> load_tokens_file(const std::string& path);

// An IP address as the server prints and compares it (lower case, IPv4
// for v4-mapped IPv6, so "::FFFF:1.2.3.4" is "1.2.3.4"); text that is not
// an address comes back as it is.
std::string canonical_address(const std::string& text);

// True for 127.0.0.0/8, ::1 and localhost.
bool is_loopback_address(const std::string& address);
// 0.0.0.0 or :: (every address of the machine: not one a client can be sent to).
bool is_any_address(const std::string& address);

}  // namespace terrane
