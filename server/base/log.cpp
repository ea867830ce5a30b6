#include "server/base/log.h"

#include <spdlog/sinks/stdout_color_sinks.h>

namespace terrane {

spdlog::logger& server_log() {
  static std::shared_ptr<spdlog::logger> log = [] {
    auto l = spdlog::get("server");
    if (!l) l = spdlog::stdout_color_mt("server");
    l->flush_on(spdlog::level::info);
    return l;
  }();
  return *log;
}

}  // namespace terrane
