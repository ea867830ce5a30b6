// The client library's named logger ("client"): lifecycle at info, a
// server's bad input at warn. Any thread (spdlog's loggers are).
#pragma once

#include <memory>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

namespace terrane {

inline spdlog::logger& client_log() {
  static std::shared_ptr<spdlog::logger> log = [] {
    auto l = spdlog::get("client");
    if (!l) l = spdlog::stdout_color_mt("client");
    return l;
  }();
  return *log;
}

}  // namespace terrane
