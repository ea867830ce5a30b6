// Listener: the server's listening socket. It accepts connections, each
// on a strand of its own (the session's strand from then on), and hands
// each socket to the accept function until that declines or the socket
// closes.
//
// Threading: the accepts and the accept function run on the io threads;
// bind() before they run, close() on an io thread (a post), port() from
// any thread. No lock: the socket is the io threads' one at a time (one
// accept is pending at once).
#pragma once

#include <asio.hpp>
#include <cstdint>
#include <functional>
#include <string>

#include "common/codec/decode_error.h"

namespace terrane {

class Listener {
 public:
  // Takes an accepted socket (on its strand); false: accept no more.
  using AcceptFn = std::function<bool(asio::ip::tcp::socket socket)>;

  explicit Listener(asio::io_context& io) : io_(io), acceptor_(io) {}
  Listener(const Listener&) = delete;
  Listener& operator=(const Listener&) = delete;

  // Listens on address:port (port 0: any free one); fails with what to tell
  // the operator.
  FileResult<Ok> bind(const std::string& address, std::uint16_t port);
  // The port listened on (0 before bind()).
  std::uint16_t port() const { return port_; }
  // Accepts from now on, handing each connection to on_accept.
  void start(AcceptFn on_accept);
  // Accepts no more (the pending accept ends).
  void close();

 private:
  void accept();

  asio::io_context& io_;
  asio::ip::tcp::acceptor acceptor_;
  std::uint16_t port_ = 0;
  AcceptFn on_accept_;
};

}  // namespace terrane
