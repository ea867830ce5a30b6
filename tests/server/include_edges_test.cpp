// The include edges between libraries and between the server's rooms, as
// written down: common uses nothing of ours, protocol uses common, server
// and client use both and never each other (README.md); within the server,
// server/README.md's table "Allowed includes". Reads the sources' #include
// lines; an edge the table does not allow fails with the file and line.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace terrane {
namespace {

namespace fs = std::filesystem;

const fs::path kSource = fs::path(TERRANE_SOURCE_DIR);

struct Include {
  fs::path file;  // relative to the source root
  int line = 0;
  std::string target;  // as written: "server/world/world_owner.h"
};

// Every #include "..." of the .h and .cpp files below dir.
std::vector<Include> includes_under(const std::string& dir) {
  std::vector<Include> out;
  const std::regex inc(R"(^\s*#\s*include\s+"([^"]+)\")");
  for (const auto& e : fs::recursive_directory_iterator(kSource / dir)) {
    if (!e.is_regular_file()) continue;
    const auto ext = e.path().extension();
    if (ext != ".h" && ext != ".cpp") continue;
    std::ifstream in(e.path());
    std::string text;
    int n = 0;
    while (std::getline(in, text)) {
      ++n;
      std::smatch m;
      if (std::regex_search(text, m, inc)) out.push_back({fs::relative(e.path(), kSource), n, m[1]});
    }
  }
  return out;
}

// The room of a server path: its first folder below server/, or "top".
std::string room_of(const fs::path& p) {
  auto it = p.begin();
  if (it == p.end() || *it != "server") return {};
  ++it;
  if (it == p.end()) return {};
  auto next = it;
  ++next;
  return next == p.end() ? "top" : it->string();
}

// server/README.md's table: room -> rooms it may include.
std::map<std::string, std::set<std::string>> allowed_edges() {
  std::ifstream in(kSource / "server" / "README.md");
  std::map<std::string, std::set<std::string>> out;
  std::string line;
  bool in_section = false;
  const std::regex row(R"(^\|\s*`([a-z_]+)`\s*\|(.*)\|\s*$)");
  const std::regex name("`([a-z_]+)`");
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0) in_section = line == "## Allowed includes";
    std::smatch m;
    if (!in_section || !std::regex_match(line, m, row)) continue;
    auto& allowed = out[m[1]];
    const std::string rest = m[2];
    for (std::sregex_iterator i(rest.begin(), rest.end(), name), end; i != end; ++i) allowed.insert((*i)[1]);
  }
  return out;
}

TEST(IncludeEdges, LibrariesIncludeOnlyTheLayersBelow) {
  const std::map<std::string, std::set<std::string>> layers = {
      {"common", {"common"}},
      {"protocol", {"common", "protocol"}},
      {"server", {"common", "protocol", "server"}},
      {"client", {"common", "protocol", "client"}},
  };
  std::size_t checked = 0;
  for (const auto& [lib, may] : layers)
    for (const Include& inc : includes_under(lib)) {
      const std::string top = inc.target.substr(0, inc.target.find('/'));
      if (inc.target.find('/') == std::string::npos || layers.count(top) == 0) continue;  // generated or third-party
      ++checked;
      EXPECT_TRUE(may.count(top) != 0) << inc.file.string() << ":" << inc.line << " includes " << inc.target
                                       << ": " << lib << " may not use " << top;
    }
  EXPECT_GT(checked, 300u) << "the sources were not found under " << kSource;
}

TEST(IncludeEdges, ServerRoomsIncludeOnlyTheEdgesTheirTableAllows) {
  const auto allowed = allowed_edges();
  ASSERT_GE(allowed.size(), 7u) << "server/README.md's 'Allowed includes' table not found";
  std::set<std::string> rooms_seen;
  std::size_t edges = 0;
  for (const Include& inc : includes_under("server")) {
    const std::string from = room_of(inc.file);
    rooms_seen.insert(from);
    ASSERT_TRUE(allowed.count(from) != 0) << inc.file.string() << ": room '" << from
                                          << "' is not in server/README.md's table";
    if (inc.target.rfind("server/", 0) != 0) continue;
    const std::string to = room_of(inc.target);
    if (to == from) continue;
    ++edges;
    EXPECT_TRUE(allowed.at(from).count(to) != 0)
        << inc.file.string() << ":" << inc.line << " includes " << inc.target << ": " << from << " -> " << to
        << " is not an allowed edge (server/README.md, 'Allowed includes')";
  }
  EXPECT_GT(edges, 20u);
  // Every room of the table exists (a table row for a folder gone is stale).
  for (const auto& [room, may] : allowed) EXPECT_TRUE(rooms_seen.count(room) != 0) << "no files in room " << room;
}

}  // namespace
}  // namespace terrane
