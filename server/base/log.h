// The server library's named spdlog logger ("server"). Created on first use
// on stdout, as text, at level info; flushed at info so lifecycle lines
// (e.g. "listening on") reach a pipe or file at once. configure_server_log
// chooses JSON lines and a file instead (terrane-server --log-format,
// --log-file), and set_server_log_level the lowest level logged
// (--log-level), once, before the server's threads start;
// reopen_server_log (SIGHUP) reopens the file at its path, so a rotated log
// (logrotate's move, then kill -HUP) goes on in a new file. Any thread may
// log; the file's sink has its own lock (spdlog's).
#pragma once

#include <chrono>
#include <string>
#include <string_view>

#include <spdlog/spdlog.h>

namespace terrane {

spdlog::logger& server_log();

// A line's form: text ("[2026-11-29 09:50:18.123 +00:00] [server] [info]
// message") or one JSON object a line ({"time":"2026-11-29T09:50:18.123+00:00",
// "level":"info","logger":"server","message":"..."}).
enum class LogFormat { kText, kJson };

// Sends the server's log to path (appended; "" = stdout) in format. Returns
// "" or why the file cannot be opened (the log is then unchanged). Call
// before other threads log.
std::string configure_server_log(LogFormat format, const std::string& path);

// The lowest level logged by every logger of the process (the "server"
// logger, and any made later): "trace", "debug", "info", "warn", "error"
// or "off" (nothing). False, and nothing changed, for any other name. A
// release build has no debug or trace lines (SPDLOG_ACTIVE_LEVEL). Call
// before other threads log.
bool set_server_log_level(std::string_view name);

// Reopens the log file at its path (after it was moved away); nothing when
// the log is on stdout. Returns "" or why it cannot be opened (the old file
// is kept then). Any thread.
std::string reopen_server_log();

// The JSON form of one log line as configure_server_log writes it (without
// the newline), for tests: time is a point of the system clock, shown in
// local time with its offset.
std::string json_log_line(std::chrono::system_clock::time_point time, spdlog::level::level_enum level,
                          std::string_view logger, std::string_view message);

}  // namespace terrane
