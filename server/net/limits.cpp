#include "server/net/limits.h"

#include <algorithm>

#include <asio/ip/address.hpp>
#include <asio/ip/network_v4.hpp>
#include <asio/ip/network_v6.hpp>

#include "protocol/tokens_file.h"
#include "server/base/log.h"

namespace terrane {

FileResult<std::unordered_map<std::string, PlayerToken>> load_tokens_file(const std::string& path) {
  auto entries = read_tokens_file(path);
  if (!entries) return entries.error();
  std::unordered_map<std::string, PlayerToken> tokens;
  for (TokensFileEntry& e : *entries) tokens.emplace(std::move(e.name), PlayerToken{std::move(e.token), e.admin});
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
