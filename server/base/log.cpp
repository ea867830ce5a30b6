#include "server/base/log.h"

#include <time.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <utility>

#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/base_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/sinks/stdout_sinks.h>

#include "common/cli/json.h"

namespace terrane {
namespace {

// Local time with its offset from UTC (+00:00 in a container), so lines
// from machines in different zones line up.
constexpr const char* kTextPattern = "[%Y-%m-%d %H:%M:%S.%e %z] [%n] [%^%l%$] %v";

// One JSON object a line; the message escaped (common/cli/json.h).
class JsonFormatter final : public spdlog::formatter {
 public:
  void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override {
    const std::string line = json_log_line(msg.time, msg.level, {msg.logger_name.data(), msg.logger_name.size()},
                                           {msg.payload.data(), msg.payload.size()});
    dest.append(line.data(), line.data() + line.size());
    dest.push_back('\n');
  }
  std::unique_ptr<spdlog::formatter> clone() const override { return std::make_unique<JsonFormatter>(); }
};

// A file appended to, reopened at its path on demand (after logrotate moved
// it). spdlog's basic_file_sink cannot reopen.
class ReopenableFileSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  explicit ReopenableFileSink(std::string path) : path_(std::move(path)) {}
  ~ReopenableFileSink() override {
    if (file_ != nullptr) std::fclose(file_);
  }
  // Opens (again) path_ for appending; "" or why not (the old file kept).
  std::string open() {
    std::lock_guard<std::mutex> lock(mutex_);
    std::FILE* f = std::fopen(path_.c_str(), "a");
    if (f == nullptr) return "cannot open log file " + path_ + ": " + std::strerror(errno);
    if (file_ != nullptr) std::fclose(file_);
    file_ = f;
    return "";
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    spdlog::memory_buf_t line;
    formatter_->format(msg, line);
    if (file_ != nullptr) std::fwrite(line.data(), 1, line.size(), file_);
  }
  void flush_() override {
    if (file_ != nullptr) std::fflush(file_);
  }

 private:
  const std::string path_;
  std::FILE* file_ = nullptr;
};

// The file sink configure_server_log made, for reopen_server_log (null on
// stdout). Set once before the threads start.
std::shared_ptr<ReopenableFileSink>& file_sink() {
  static std::shared_ptr<ReopenableFileSink> sink;
  return sink;
}

}  // namespace

spdlog::logger& server_log() {
  static std::shared_ptr<spdlog::logger> log = [] {
    auto l = spdlog::get("server");
    if (!l) l = spdlog::stdout_color_mt("server");
    l->set_pattern(kTextPattern);
    l->flush_on(spdlog::level::info);
    return l;
  }();
  return *log;
}

std::string configure_server_log(LogFormat format, const std::string& path) {
  spdlog::sink_ptr sink;
  std::shared_ptr<ReopenableFileSink> file;
  if (path.empty()) {
    sink = format == LogFormat::kText ? spdlog::sink_ptr(std::make_shared<spdlog::sinks::stdout_color_sink_mt>())
                                      : spdlog::sink_ptr(std::make_shared<spdlog::sinks::stdout_sink_mt>());
  } else {
    file = std::make_shared<ReopenableFileSink>(path);
    if (auto err = file->open(); !err.empty()) return err;
    sink = file;
  }
  if (format == LogFormat::kJson)
    sink->set_formatter(std::make_unique<JsonFormatter>());
  else
    sink->set_formatter(std::make_unique<spdlog::pattern_formatter>(kTextPattern));
  spdlog::logger& l = server_log();
  l.flush();
  l.sinks().assign(1, sink);
  file_sink() = std::move(file);
  return "";
}

bool set_server_log_level(std::string_view name) {
  // Named here, not by spdlog::level::from_str, which takes "warning" and
  // "err" too and reads any other name as off.
  using spdlog::level::level_enum;
  constexpr std::pair<std::string_view, level_enum> kLevels[] = {
      {"trace", level_enum::trace}, {"debug", level_enum::debug}, {"info", level_enum::info},
      {"warn", level_enum::warn},   {"error", level_enum::err},   {"off", level_enum::off}};
  for (const auto& [level_name, level] : kLevels)
    if (name == level_name) {
      server_log().set_level(level);  // made (and registered) first, so set_level below reaches it too
      spdlog::set_level(level);       // every registered logger, and the level of those made later
      return true;
    }
  return false;
}

std::string reopen_server_log() {
  const auto& file = file_sink();
  return file ? file->open() : "";
}

std::string json_log_line(std::chrono::system_clock::time_point time, spdlog::level::level_enum level,
                          std::string_view logger, std::string_view message) {
  const std::time_t seconds = std::chrono::system_clock::to_time_t(time);
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(time.time_since_epoch()).count() % 1000;
  std::tm local{};
  ::localtime_r(&seconds, &local);
  char date[32], zone[8];
  std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%S", &local);
  std::strftime(zone, sizeof zone, "%z", &local);  // +hhmm
  char stamp[48];
  std::snprintf(stamp, sizeof stamp, "%s.%03d%.3s:%.2s", date, static_cast<int>(ms < 0 ? ms + 1000 : ms), zone,
                zone + 3);
  const auto level_name = spdlog::level::to_string_view(level);
  std::string line = "{\"time\":\"";
  line += stamp;
  line += "\",\"level\":\"";
  line.append(level_name.data(), level_name.size());
  line += "\",\"logger\":";
  line += json_string(logger);
  line += ",\"message\":";
  line += json_string(message);
  line += "}";
  return line;
}

}  // namespace terrane
