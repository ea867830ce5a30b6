// The server library's named spdlog logger ("server"). Created on first use;
// stdout, flushed at info so lifecycle lines (e.g. "listening on") reach a
// pipe at once.
#pragma once

#include <spdlog/spdlog.h>

namespace terrane {

spdlog::logger& server_log();

}  // namespace terrane
