#include "server/base/log.h"

#include <spdlog/sinks/stdout_color_sinks.h>

namespace terrane {

spdlog::logger& server_log() {
  static std::shared_ptr<spdlog::logger> log = [] {
    auto l = spdlog::get("server");
    if (!l) l = spdlog::stdout_color_mt("server");
    // Local time with its offset from UTC (+00:00 in a container), so lines
    // from machines in different zones line up.
    l->set_pattern("[%Y-%m-%d %H:%M:%S.%e %z] [%n] [%^%l%$] %v");
    l->flush_on(spdlog::level::info);
    return l;
  }();
  return *log;
}

}  // namespace terrane
