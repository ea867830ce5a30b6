#include "client/io_side.h"

namespace terrane {

IoSide::IoSide(asio::io_context* shared)
    : own_(shared != nullptr ? nullptr : std::make_unique<asio::io_context>()),
      io_(shared != nullptr ? *shared : *own_),
      strand_(asio::make_strand(io_)) {}

void IoSide::start_thread() {
  io_.restart();
  thread_ = std::thread([this] { io_.run(); });
}

void IoSide::finish() {
  if (thread_.joinable()) {
    thread_.join();
    return;
  }
  if (!owned()) ops_.wait_idle();
}

}  // namespace terrane
