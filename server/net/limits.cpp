#include "server/net/limits.h"

#include <algorithm>
#include <fstream>
#include <sstream>
#include <vector>

#include <asio/ip/address.hpp>
#include <asio/ip/network_v4.hpp>
#include <asio/ip/network_v6.hpp>

#include "protocol/messages.h"
#include "server/base/log.h"

namespace terrane {

FileResult<std::unordered_map<std::string, PlayerToken>> load_tokens_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) return FileError{"cannot read tokens file " + path, {}};
  std::unordered_map<std::string, PlayerToken> tokens;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const std::string where = path + ":" + std::to_string(number) + ": ";
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
    if (!tokens.emplace(name, PlayerToken{token, role == "admin"}).second) return FileError{where + "player '" + name + "' listed twice", {}};
  }
  if (in.bad()) return FileError{"error reading tokens file " + path, {}};
  return tokens;
}

std::string canonical_address(const std::string& text) {
  asio::error_code ec;
  auto a = asio::ip::make_address(text, ec);
  if (ec) return text;
  if (a.is_v6() && a.to_v6().is_v4_mapped()) a = asio::ip::make_address_v4(asio::ip::v4_mapped, a.to_v6());
  return a.to_string();
}

std::optional<std::string> canonical_network(const std::string& text) {
  if (text.find('/') == std::string::npos) return std::nullopt;
  asio::error_code ec;
  const auto v4 = asio::ip::make_network_v4(text, ec);
  if (!ec) return v4.canonical().to_string();
  const auto v6 = asio::ip::make_network_v6(text, ec);
  if (!ec) return v6.canonical().to_string();
  return std::nullopt;
}

bool address_in_network(const std::string& address, const std::string& network) {
  asio::error_code ec;
  const auto a = asio::ip::make_address(address, ec);
  if (ec) return false;
  if (a.is_v4()) {
    const auto n = asio::ip::make_network_v4(network, ec);
    return !ec && asio::ip::make_network_v4(a.to_v4(), n.prefix_length()).canonical() == n.canonical();
  }
  const auto n = asio::ip::make_network_v6(network, ec);
  return !ec && asio::ip::make_network_v6(a.to_v6(), n.prefix_length()).canonical() == n.canonical();
}

bool is_loopback_address(const std::string& address) {
  if (address == "localhost") return true;
  asio::error_code ec;
  const auto a = asio::ip::make_address(address, ec);
  return !ec && a.is_loopback();
}

bool is_any_address(const std::string& address) {
  asio::error_code ec;
  const auto a = asio::ip::make_address(address, ec);
  return !ec && a.is_unspecified();
}

}  // namespace terrane
