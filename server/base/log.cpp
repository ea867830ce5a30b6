#include "server/base/log.h"

#include <fmt/format.h>
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

std::string printable(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (const char ch : text) {
    const auto b = static_cast<unsigned char>(ch);
    if (b < 0x20 || b == 0x7f) out += fmt::format("\\x{:02x}", b);
    else out += ch;
  }
  return out;
}

}  // namespace terrane
