// The server library's named spdlog logger ("server"). Created on first use;
// stdout, flushed at info so lifecycle lines (e.g. "listening on") reach a
// pipe at once.
#pragma once

#include <spdlog/spdlog.h>

#include <string>
#include <string_view>

namespace terrane {

spdlog::logger& server_log();

// Text from a client (a name, a token) as a log line may hold it: control
// characters as \xNN, so no client can end a line or forge the next one.
std::string printable(std::string_view text);

}  // namespace terrane
