#include "server/net/listener.h"

namespace terrane {

FileResult<Ok> Listener::bind(const std::string& address, std::uint16_t port) {
  asio::error_code ec;
  const auto addr = asio::ip::make_address(address, ec);
  if (ec) return FileError{"bad bind address " + address + ": " + ec.message(), {}};
  const asio::ip::tcp::endpoint ep(addr, port);
  acceptor_.open(ep.protocol(), ec);
  if (!ec) acceptor_.set_option(asio::ip::tcp::acceptor::reuse_address(true), ec);
  if (!ec) acceptor_.bind(ep, ec);
  if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) return FileError{"cannot listen on " + address + ":" + std::to_string(port) + ": " + ec.message(), {}};
  port_ = acceptor_.local_endpoint().port();
  return Ok{};
}

void Listener::start(AcceptFn on_accept) {
  on_accept_ = std::move(on_accept);
  accept();
}

void Listener::close() {
  asio::error_code ignored;
  acceptor_.close(ignored);
}

void Listener::accept() {
  acceptor_.async_accept(asio::make_strand(io_), [this](const asio::error_code& ec, asio::ip::tcp::socket socket) {
    if (ec) {
      if (ec != asio::error::operation_aborted && acceptor_.is_open()) accept();
      return;
    }
    if (on_accept_(std::move(socket))) accept();
  });
}

}  // namespace terrane
