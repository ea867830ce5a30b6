#include "server/tools/world_tool.h"

#include <fmt/format.h>

#include <filesystem>

#include "common/world/sqlite_store.h"

namespace terrane::world_tool {

int usage_error(const std::string& message, const char* help) {
  std::fprintf(stderr, "terrane-world: %s\n\n%s", message.c_str(), help);
  return 2;
}

int failure(const std::string& message) {
  std::fprintf(stderr, "terrane-world: %s\n", message.c_str());
  return 1;
}

std::vector<Vec3i> chunks_in(const Region& r) {
  std::vector<Vec3i> out;
  for_each_chunk_in(r, [&](Vec3i c) { out.push_back(c); });
  return out;
}

std::string world_place(const CommandLine& cl, WorldPlace* out) {
  if (cl.has("world") && cl.has("store")) return "give --world DIR or --store URL, not both";
  if (!cl.has("world") && !cl.has("store")) return "--world DIR (or --store URL) is required";
  out->where = cl.has("world") ? cl.get("world") : cl.get("store");
  out->postgres = PostgresStore::is_url(out->where);
  if (const auto scheme = out->where.find("://"); !out->postgres && scheme != std::string::npos)
    return fmt::format("'{}...' is neither a postgresql:// URL nor a world directory",
                       out->where.substr(0, scheme + 3));
  return {};
}

std::optional<std::uint32_t> writer_id(const CommandLine& cl, const WorldPlace& place,
                                       std::optional<std::uint32_t> fallback, std::string* error) {
  if (!place.postgres) {
    if (cl.has("server-id")) *error = "--server-id is for a PostgreSQL world (--store postgresql://...)";
    return std::nullopt;
  }
  if (!cl.has("server-id") && !fallback) {
    *error = "--server-id N is required to write a PostgreSQL world: an id (0 to 2147483647) no running "
             "server uses";
    return std::nullopt;
  }
  return static_cast<std::uint32_t>(cl.get_int("server-id", fallback.value_or(0), 0, kMaxServerId, error));
}

FileStatus open_tool_world(const WorldPlace& place, std::optional<std::uint32_t> writer,
                           const std::function<WorldMeta()>& make, ToolWorld& out, const char* writing) {
  if (!place.postgres) {
    if (writing) {
      if (make) {
        std::error_code ec;
        std::filesystem::create_directories(place.where, ec);
        if (ec) return FileError{"world " + place.where + ": cannot create directory: " + ec.message(), {}};
      } else if (!SqliteStore::exists(place.where)) {
        return FileError{"world " + place.where + ": no world here (" + kWorldDatabaseName + " missing)", {}};
      }
      auto lock = WorldLock::take(place.where, writing);
      if (!lock) return lock.error();
      out.lock = std::move(*lock);
    }
    const bool create = make && !SqliteStore::exists(place.where);
    auto w = create ? World::create(place.where, make()) : World::open(place.where);
    if (!w) return w.error();
    out.world = std::move(*w);
    out.created = create;
    return Ok{};
  }
  auto store = PostgresStore::open(place.where);
  if (!store) return FileError{store.error().message, std::nullopt};
  PostgresStore& pg = **store;
  if (writer)
    if (auto s = out.leases.attach(place.where, *writer, pg); !s) return s;
  if (!pg.has_world()) {
    if (!make)
      return FileError{fmt::format("world {}: the database holds no world (make one with terrane-world migrate, "
                                   "generate or import, or start a server on it)",
                                   pg.where()),
                       std::nullopt};
    if (auto made = pg.create_world(make()); !made) return FileError{made.error().message, std::nullopt};
    out.created = true;
  }
  auto w = World::open(std::unique_ptr<WorldStore>(std::move(*store)));
  if (!w) return w.error();
  out.world = std::move(*w);
  return Ok{};
}

}  // namespace terrane::world_tool
