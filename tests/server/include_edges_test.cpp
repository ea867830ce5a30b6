// The include edges between libraries and between the server's rooms, as
// written down: common uses nothing of ours, protocol uses common, server
// and client use both and never each other (README.md); within the server,
// server/README.md's table "Allowed includes". Reads the sources' #include
// lines; an edge the table does not allow fails with the file and line.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
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
  for (const auto& e : fs::recursive_directory_iterator(kSource / dir)) {
    if (!e.is_regular_file()) continue;
    const auto ext = e.path().extension();
    if (ext != ".h" && ext != ".cpp") continue;
    std::ifstream in(e.path());
    std::string text;
    int n = 0;
    while (std::getline(in, text)) {
      ++n;
      // #include "..." (std::regex is avoided: GCC 12 warns inside it under ASan).
      const std::size_t start = text.find_first_not_of(" \t");
      if (start == std::string::npos || text.compare(start, 10, "#include \"") != 0) continue;
      const std::size_t close = text.find('"', start + 10);
      if (close == std::string::npos) continue;
      out.push_back({fs::relative(e.path(), kSource), n, text.substr(start + 10, close - start - 10)});
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

// The `...` names of text, in order.
std::vector<std::string> quoted_names(const std::string& text) {
  std::vector<std::string> out;
  for (std::size_t at = text.find('`'); at != std::string::npos;) {
    const std::size_t end = text.find('`', at + 1);
    if (end == std::string::npos) break;
    out.push_back(text.substr(at + 1, end - at - 1));
    at = text.find('`', end + 1);
  }
  return out;
}

// server/README.md's table: room -> rooms it may include. A row is
// "| `room` | `a`, `b` |".
std::map<std::string, std::set<std::string>> allowed_edges() {
  std::ifstream in(kSource / "server" / "README.md");
  std::map<std::string, std::set<std::string>> out;
  std::string line;
  bool in_section = false;
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0) in_section = line == "## Allowed includes";
    if (!in_section || line.rfind("| `", 0) != 0) continue;
    const std::size_t second_bar = line.find('|', 1);
    if (second_bar == std::string::npos) continue;
    const auto room = quoted_names(line.substr(0, second_bar));
    if (room.size() != 1) continue;
    auto& allowed = out[room[0]];
    for (const std::string& to : quoted_names(line.substr(second_bar))) allowed.insert(to);
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
