// Authentication helpers for the server's sessions: the tokens file and
// the addresses clients come from. (Rates: server/base/rate_limit.h.)
//
// Thread-safety: every function is pure.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>

#include "common/world/world_store.h"
#include "server/net/net_options.h"

namespace terrane {

// A tokens file (protocol/tokens_file.h: "NAME TOKEN [player|admin]" a
// line, '#' comments) by name. Errors name the file and line.
FileResult<std::unordered_map<std::string, PlayerToken>> load_tokens_file(const std::string& path);

// An IP address as the server prints and compares it (lower case, IPv4
// for v4-mapped IPv6, so "::FFFF:1.2.3.4" is "1.2.3.4"); text that is not
// an address comes back as it is.
std::string canonical_address(const std::string& text);

// An IP network "ADDRESS/PREFIX" (IPv4 or IPv6) as the server prints and
// compares it: the network's own address, host bits cleared, so
// "10.1.2.3/8" is "10.0.0.0/8"; nullopt for text that is not one.
std::optional<std::string> canonical_network(const std::string& text);
// Whether an address (canonical_address's form) lies in a network
// (canonical_network's form).
bool address_in_network(const std::string& address, const std::string& network);

// True for 127.0.0.0/8, ::1 and localhost.
bool is_loopback_address(const std::string& address);
// 0.0.0.0 or :: (every address of the machine: not one a client can be sent to).
bool is_any_address(const std::string& address);

}  // namespace terrane
