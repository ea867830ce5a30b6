// Session: one client connection on the server. Owns the socket, reads
// frames, verifies and parses them (protocol/messages.h) and hands the
// parsed messages to the server; writes frames from a bounded queue, each
// frame's segments (protocol/out_frame.h) and several frames in one
// gathered write.
//
// Threading: every member runs on the session's own strand (the socket's
// executor). send() and close() may be called from any thread: they post to
// that strand. queued_bytes() is an atomic the world owner reads to decide
// how much more to stream. A Session lives in a shared_ptr kept alive by its
// pending handlers and by the server's peer table.
//
// State machine:
//
//   [reading] --bad frame / timeout / backlog--> [closing] --queue flushed-->
//       |                                         (Disconnect     [draining]
//       +--peer EOF / socket error--------------> queued)            |
//                                                                    v
//   [closed] <------------ EOF from peer or linger deadline ---------+
//
// A closing session sends nothing but the control frames already queued
// (acks, rejections, notices) and its Disconnect frame, then shuts down
// its sending side and discards input until the peer closes (so the peer
// reads the reason instead of a reset) or the linger deadline passes.
#pragma once

#include <asio.hpp>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include "protocol/framing.h"
#include "protocol/messages.h"
#include "protocol/out_frame.h"
#include "server/base/counters.h"
#include "server/net/net_options.h"
#include "server/base/rate_limit.h"
#include "server/net/limits.h"

namespace terrane {


struct ChunkHashRequestMsg {
  Vec3i chunk_pos;
};

// What a session hands to the server (already checked for meaning).
struct HoldingsMsg {
  std::vector<HeldChunkMsg> chunks;
  std::uint64_t world_id = 0;  // the world they came from (0: unchecked)
};

// A Pong answering one of the server's Pings (the round trip it measures).
struct PongMsg {
  std::uint64_t nonce = 0;
};

using InboundMessage = std::variant<HelloMsg, ClientStateMsg, EditRequestMsg, ChunkHashRequestMsg, ReadBoxMsg,
                                    HoldingsMsg, AdminRequestMsg, PongMsg>;

using SharedFrame = std::shared_ptr<const Frame>;

// Priority classes of outbound frames. Control frames (EditAck, EditReject,
// Pong) go out before queued data, once the first data frame (the Welcome
// or the Disconnect) has gone: before it the protocol allows the server to
// send nothing else. Data frames (everything about the world:
// stream records, updates, chunk hashes) keep their order,
// so an update never overtakes the chunk data it applies to and a region
// hash reflects every update queued before it. Between near chunks and far
// mips the replicator decides (server/replication/replicator.h).
enum class SendClass : std::uint8_t { kData, kControl };

class Session : public std::enable_shared_from_this<Session> {
 public:
  // Called on the session strand.
  using InboundFn = std::function<void(std::uint64_t id, InboundMessage msg)>;
  // Called once, on the session strand, when the socket is closed.
  using ClosedFn = std::function<void(std::uint64_t id, const std::string& reason)>;

  // Called on the session strand each time the send queue runs empty, so
  // the owner can stream more at once instead of at the next tick.
  using DrainedFn = std::function<void(std::uint64_t id)>;

  Session(asio::ip::tcp::socket socket, std::uint64_t id, const SessionLimits& limits, InboundFn on_message,
          ClosedFn on_closed, DrainedFn on_drained = nullptr);

  void start();
  // Queues a frame (any thread): its segments go out in one gathered
  // write, its shared bytes uncopied (protocol/out_frame.h). Over the byte
  // cap the session is closed as too far behind.
  void send(OutFrame frame, SendClass cls = SendClass::kData);
  // A frame built once for many sessions: sent as one shared segment.
  void send(SharedFrame frame, SendClass cls = SendClass::kData) { send(OutFrame(std::move(frame)), cls); }
  // Sends Disconnect(text) after nothing else, then closes (any thread);
  // why is counted (NetCounters::disconnects).
  void close(CloseReason why, std::string text);

  std::uint64_t id() const { return id_; }
  // The session's strand: post here to run beside its I/O.
  asio::ip::tcp::socket::executor_type executor() { return socket_.get_executor(); }
  std::size_t queued_bytes() const { return queued_bytes_.load(std::memory_order_relaxed); }
  std::uint64_t bytes_sent() const { return bytes_sent_.load(std::memory_order_relaxed); }
  std::uint64_t bytes_received() const { return bytes_received_.load(std::memory_order_relaxed); }
  // "IP:PORT" of the peer, and its IP alone (what bans take).
  const std::string& remote() const { return remote_; }
  const std::string& address() const { return address_; }

 private:
  enum class State { kReading, kClosing, kDraining, kClosed };
  using Clock = std::chrono::steady_clock;

  void do_read();
  void on_frame(std::span<const std::uint8_t> body);
  void enqueue(OutFrame frame, SendClass cls);
  // Starts a write after the handlers already waiting on the strand have
  // run, so the frames they queue go out in the same system call.
  void schedule_write();
  void do_write();
  // Writes the next run of the gathered buffers; on_written moves past
  // what the socket took and writes the rest, then ends the write.
  void write_some();
  void on_written(const asio::error_code& ec, std::size_t n);
  // Feeds bytes read to the frame reader; false once the session closes over them.
  bool on_bytes(std::span<const std::uint8_t> bytes);
  void read_failed(const asio::error_code& ec);
  void begin_close(CloseReason why, const std::string& text);
  void finish_close();
  // Moves this session's queued bytes and the server-wide total together.
  void add_queued(std::int64_t delta);
  void arm_watchdog();

  asio::ip::tcp::socket socket_;
  asio::steady_timer watchdog_;
  std::uint64_t id_;
  SessionLimits limits_;
  InboundFn on_message_;
  ClosedFn on_closed_;
  DrainedFn on_drained_;
  std::string remote_;
  std::string address_;

  State state_ = State::kReading;
  bool welcomed_ = false;  // set once a Hello was accepted by the parser
  std::string close_reason_;
  CloseReason close_why_ = CloseReason::kPeerClosed;
  FrameReader reader_;
  std::deque<OutFrame> queue_;          // data
  std::deque<OutFrame> control_queue_;  // sent first
  std::vector<OutFrame> inflight_;          // the frames of the write under way
  std::vector<asio::const_buffer> write_bufs_;  // their segments (kept for its capacity)
  std::size_t write_next_ = 0;               // the first not yet written
  std::size_t write_gathered_ = 0;           // their bytes
  bool writing_ = false;
  bool write_scheduled_ = false;  // a do_write is posted to the strand
  bool data_started_ = false;     // the first data frame has been written
  Clock::time_point last_read_;
  Clock::time_point write_started_;
  Clock::time_point close_started_;
  Clock::time_point frame_started_;  // when the partial frame buffered began
  bool partial_frame_ = false;
  TokenBucket inbound_;
  std::atomic<std::size_t> queued_bytes_{0};
  std::atomic<std::uint64_t> bytes_sent_{0};
  std::atomic<std::uint64_t> bytes_received_{0};
};

}  // namespace terrane
