#include "server/ops/backup_schedule.h"

#include <pthread.h>
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <sstream>

#include "common/world/sqlite_store.h"
#include "server/base/log.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

constexpr const char* kPrefix = "world-";
// world-20261129T095018.123Z
constexpr std::size_t kNameSize = 26;

std::string backup_name(std::chrono::system_clock::time_point t) {
  const std::time_t seconds = std::chrono::system_clock::to_time_t(t);
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(t.time_since_epoch()).count() % 1000;
  std::tm utc{};
  ::gmtime_r(&seconds, &utc);
  char date[24];
  std::strftime(date, sizeof date, "%Y%m%dT%H%M%S", &utc);
  char name[40];
  std::snprintf(name, sizeof name, "%s%s.%03dZ", kPrefix, date, static_cast<int>(ms));
  return name;
}

bool is_backup_name(const std::string& name) {
  return name.size() == kNameSize && name.rfind(kPrefix, 0) == 0 && name.back() == 'Z' && name[14] == 'T' &&
         name[21] == '.';
}

}  // namespace

BackupSchedule::BackupSchedule(BackupOptions options, std::string world_dir)
    : options_(std::move(options)), world_dir_(std::move(world_dir)) {}

BackupSchedule::~BackupSchedule() { stop(); }

void BackupSchedule::start() {
  if (thread_.joinable() || options_.every.count() <= 0) return;
  server_log().info("backups every {} s to {}, the newest {} kept", std::chrono::duration<double>(options_.every).count(), options_.dir,
                    options_.keep);
  thread_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "terrane-backup");
    run();
  });
}

void BackupSchedule::stop() {
  {
    std::lock_guard lock(m_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void BackupSchedule::run() {
  auto due = std::chrono::steady_clock::now() + options_.every;
  std::unique_lock lock(m_);
  while (!wake_.wait_until(lock, due, [this] { return stopping_; })) {
    lock.unlock();
    backup_once();
    lock.lock();
    // The next is due a period after this one was; one that took longer
    // than the period is followed by the next at once, not by a burst.
    due = std::max(due + options_.every, std::chrono::steady_clock::now());
  }
}

std::string BackupSchedule::backup_once(std::string* error) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto now = std::chrono::system_clock::now();
  const std::string path = (fs::path(options_.dir) / backup_name(now)).string();
  const auto failed = [&](const std::string& why) {
    counters_.failed.fetch_add(1, std::memory_order_relaxed);
    server_log().error("scheduled backup to {} failed: {}", path, why);
    if (error) *error = why;
    return std::string();
  };
  std::error_code ec;
  fs::create_directories(options_.dir, ec);
  if (ec) return failed("cannot create " + options_.dir + ": " + ec.message());
  auto store = SqliteStore::open(world_dir_);
  if (!store) return failed(store.error().message);
  if (auto st = (*store)->backup_to(path, nullptr); !st) return failed(st.error().message);
  store->reset();
  counters_.made.fetch_add(1, std::memory_order_relaxed);
  counters_.last_success_unix_ms.store(
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count(), std::memory_order_relaxed);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Retention: the newest keep, this one among them.
  auto names = backups_in(options_.dir);
  std::vector<std::string> removed;
  while (names.size() > static_cast<std::size_t>(std::max(options_.keep, 1))) {
    fs::remove_all(fs::path(options_.dir) / names.front(), ec);
    if (ec) {
      server_log().error("scheduled backups: cannot remove the old backup {}: {}",
                         (fs::path(options_.dir) / names.front()).string(), ec.message());
      break;
    }
    removed.push_back(names.front());
    names.erase(names.begin());
  }
  std::ostringstream gone;
  for (const auto& r : removed) gone << (gone.tellp() > 0 ? ", " : "") << r;
  server_log().info("scheduled backup: the world copied to {} in {:.2f} s; {} kept{}{}", path, seconds, names.size(),
                    removed.empty() ? "" : ", removed ", gone.str());
  return path;
}

std::vector<std::string> BackupSchedule::backups_in(const std::string& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (is_backup_name(name) && it->is_directory(ec)) names.push_back(name);
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::string render_backup_metrics(const BackupCounters& c) {
  std::ostringstream m;
  m << std::fixed << std::setprecision(3);
  m << "# HELP terrane_backups_total Scheduled backups made (--backup-every).\n"
       "# TYPE terrane_backups_total counter\n"
       "terrane_backups_total "
    << c.made.load(std::memory_order_relaxed)
    << "\n# HELP terrane_backup_failures_total Scheduled backups that failed (the log says why).\n"
       "# TYPE terrane_backup_failures_total counter\n"
       "terrane_backup_failures_total "
    << c.failed.load(std::memory_order_relaxed)
    << "\n# HELP terrane_backup_last_success_timestamp_seconds When the last scheduled backup that succeeded "
       "began (Unix time; 0: none yet).\n"
       "# TYPE terrane_backup_last_success_timestamp_seconds gauge\n"
       "terrane_backup_last_success_timestamp_seconds "
    << static_cast<double>(c.last_success_unix_ms.load(std::memory_order_relaxed)) / 1000.0 << "\n";
  return m.str();
}

}  // namespace terrane
