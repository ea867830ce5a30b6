#include "protocol/tokens_file.h"

#include <fstream>
#include <sstream>
#include <unordered_set>

#include "protocol/messages.h"

namespace terrane {

FileResult<std::vector<TokensFileEntry>> parse_tokens_file(const std::string& text, const std::string& source) {
  std::vector<TokensFileEntry> entries;
  std::unordered_set<std::string> names;
  std::istringstream in(text);
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const std::string where = source + ":" + std::to_string(number) + ": ";
    // Words up to a comment: a word that opens with '#' ends the line (a
    // '#' inside a token is part of it).
    std::istringstream in_line(line);
    std::vector<std::string> words;
    for (std::string w; in_line >> w && w[0] != '#';) words.push_back(std::move(w));
    if (words.empty()) continue;
    const std::string& name = words[0];
    if (words.size() < 2) return FileError{where + "player '" + name + "' has no token", {}};
    const std::string& token = words[1];
    const std::string role = words.size() > 2 ? words[2] : "player";
    if (role != "player" && role != "admin")
      return FileError{where + "role '" + role + "' is neither player nor admin", {}};
    if (words.size() > 3) return FileError{where + "expected 'NAME TOKEN [player|admin]', found more", {}};
    if (name.size() > kMaxClientNameBytes) return FileError{where + "name longer than 64 bytes", {}};
    if (token.size() > kMaxAuthTokenBytes) return FileError{where + "token longer than 256 bytes", {}};
    if (!names.insert(name).second) return FileError{where + "player '" + name + "' listed twice", {}};
    entries.push_back(TokensFileEntry{name, token, role == "admin", number});
  }
  return entries;
}

FileResult<std::vector<TokensFileEntry>> read_tokens_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) return FileError{"cannot read tokens file " + path, {}};
  std::stringstream text;
  text << in.rdbuf();
  if (in.bad()) return FileError{"error reading tokens file " + path, {}};
  return parse_tokens_file(text.str(), path);
}

}  // namespace terrane
