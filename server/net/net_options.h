// The net room's options: the listening socket, the io threads, the client
// cap and each session's limits. Plain data, filled by main.cpp (part of
// ServerOptions, server/server_options.h) and read by the Server, which
// hands each piece to its owner (Listener, SessionTable, ClientSession).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>

#include "protocol/framing.h"
#include "server/base/counters.h"

namespace terrane {

// A player of the tokens file (server/net/limits.h reads it).
struct PlayerToken {
  std::string token;
  bool admin = false;  // may run terrane-admin commands
};

// One session's limits (server/net/session.h applies them).
struct SessionLimits {
  std::size_t max_frame_bytes = kDefaultMaxFrameBytes;
  // Hard cap on queued outbound bytes: a client this far behind is dropped.
  std::size_t max_queue_bytes = 16u << 20;
  std::chrono::milliseconds handshake_timeout{5000};
  std::chrono::milliseconds idle_timeout{30000};
  // A write that makes no progress for this long drops the client.
  std::chrono::milliseconds write_timeout{10000};
  std::chrono::milliseconds linger{1000};
  // A frame whose first byte arrived must be complete within this (a
  // slowloris trickling one frame forever is dropped).
  std::chrono::milliseconds frame_timeout{10000};
  // Inbound bytes per second per client (0 = unlimited) and the burst
  // allowed above it.
  double inbound_bytes_per_second = 1 << 20;
  double inbound_burst_bytes = 4 << 20;
  // SO_SNDBUF for client sockets; 0 keeps the OS default. A small buffer
  // makes a stalled reader visible sooner (and bounds kernel memory).
  int socket_send_buffer_bytes = 0;
  ServerCounters* counters = nullptr;  // not owned; may be null
};

struct NetOptions {
  std::string bind_address = "127.0.0.1";
  std::uint16_t port = 0;               // 0: any free port (see Server::port())
  int io_threads = 2;
  std::size_t max_clients = 1024;
  SessionLimits session;
};

}  // namespace terrane
