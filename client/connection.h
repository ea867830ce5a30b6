// Connection: a client's link to a terrane-server: the socket, the
// handshake's Hello, framing both ways (the send queue, the frame reader),
// the keepalive Ping and the silence timeout, reconnecting with backoff
// and following Redirects (resuming with the replica's Holdings, which the
// handler supplies). What the frames mean is the handler's (the Client).
//
// Threading: its handlers run on its IoSide (client/io_side.h): a thread of
// its own (started by connect()), or, with ClientOptions::io_context set, a
// strand of that shared io_context. That io side does all socket I/O and
// calls the ConnectionHandler, one call at a time. send() may be called
// from any thread; connect() and disconnect() from the application's
// (they block: in shared mode never from the io_context's threads). The
// methods marked "io side" only from the handler's calls.
//
// States (io side):
//
//   connect() --> [linked] --drop, or Disconnect "server shutting down"-->
//                    ^        (reconnect on)                             |
//                    |                                                   v
//                    +---- Welcome again <-- Hello, Holdings, state <-- [waiting: backoff]
//   [linked] --Disconnect with another reason, protocol error,
//              disconnect(), or reconnect attempts used up--> [closed]
//   [linked] --silence_timeout with nothing read--> as a drop, except on a
//              reconnect's connection that has not sent one frame (the
//              server accepts connections but does not answer) --> [closed]
//   [linked] --Redirect--> [leaving: sends held until every edit written is
//              answered, at most redirect_wait] --> Hello (resume token),
//              Holdings, state at the server named --> [linked]
//              (a connection that fails there: as a drop)
//
// While waiting, sends are queued (up to max_send_queue_bytes) and go out
// after the new handshake.
#pragma once

#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "client/client_options.h"
#include "client/emulated_link.h"
#include "client/io_side.h"
#include "client/pending_ops.h"
#include "client/redirects.h"
#include "client/send_queue.h"
#include "protocol/framing.h"
#include "protocol/messages.h"

namespace terrane {

// Why a connection's session starts: connect(), a reconnect after a drop,
// or a Redirect followed (the last two resume: Holdings may go first).
enum class SessionStart : std::uint8_t { kFirst, kReconnect, kRedirect };

// What a Connection tells its owner. Every call is made on the io side.
class ConnectionHandler {
 public:
  virtual ~ConnectionHandler() = default;
  // The frames that follow Hello on a new connection, in order.
  virtual std::vector<Outbound> session_frames(SessionStart start) = 0;
  // n bytes were read from the socket (before any emulated link).
  virtual void on_bytes_read(std::size_t n) = 0;
  // One whole frame's body, unverified. The handler may call send(),
  // lost(), close() and offer_redirect().
  virtual void on_frame(std::span<const std::uint8_t> body) = 0;
  // The byte stream broke the framing (the connection closes next).
  virtual void on_framing_error() = 0;
  // A frame reached the socket.
  virtual void on_written(const Outbound& sent) = 0;
  // Whether an edit written to this server still waits for its answer (a
  // Redirect is followed only once none does).
  virtual bool awaiting_answers() = 0;
  // The connection dropped and a reconnect is being tried: whatever was
  // queued is gone.
  virtual void on_reconnecting(const std::string& reason) = 0;
  // A Redirect is being followed. cut_edit: an edit whose request was cut
  // off mid-write (0 if none): it may or may not have gone.
  virtual void on_redirected(const RedirectMsg& to, std::uint32_t cut_edit) = 0;
  // The connection is closed for good.
  virtual void on_closed(const std::string& reason) = 0;
};

class Connection {
 public:
  // handler outlives the Connection.
  Connection(const ClientOptions& options, ConnectionHandler& handler);
  ~Connection();
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  // Resolves and connects (blocking up to connect_timeout), then starts
  // the io side: Hello, the handler's session frames, reading. Returns
  // false with *error set if the connection cannot be made. Call once.
  bool connect(std::string* error);
  // Sends Disconnect, closes and waits until the io side is done (joins
  // the owned thread, or waits for no pending handler). Idempotent;
  // concurrent callers all return once it is done.
  void disconnect();
  // Any thread: queues a frame; false when closed or the queue is full.
  bool send(Frame frame, wire::Body type, std::uint32_t edit_id = 0);
  // Work the handler has done off the io side (a chunk cache's load, on
  // the cache's threads) that will post() its answer: while the token
  // lives, the io side does not finish, so disconnect() waits for it.
  struct OffsideWork {
    PendingOps::Guard guard;
    asio::executor_work_guard<asio::io_context::executor_type> work;
  };
  OffsideWork offside_work() { return OffsideWork{guard(), asio::make_work_guard(io_.context())}; }
  // Any thread: fn runs on the io side (one handler call among the
  // others), unless the connection is closed by then.
  void post(std::function<void()> fn);
  bool closed() const { return closed_; }

  // --- io side ---------------------------------------------------------------
  // The connection ended: reconnects (with options.reconnect, when the
  // server may come back: a drop without a reason, or a server that said
  // it restarts; a reason like "authentication failed" or a limit would
  // only repeat) or closes for good.
  void lost(const std::string& reason, bool may_return);
  // Closes for good (a protocol error).
  void close(const std::string& reason);
  // A Redirect arrived: true when it will be followed.
  bool offer_redirect(RedirectMsg r);
  // Why this connection's session started.
  SessionStart session() const { return session_; }

 private:
  bool connect_shared(const asio::ip::tcp::resolver::results_type& endpoints, std::string* error);
  void start_session();  // Hello (+ the handler's frames) and the read loop
  void do_read();
  bool feed(std::span<const std::uint8_t> bytes);  // false once this connection is gone
  void arm_delivery();                              // the emulated link's next delivery
  void arm_keepalive();
  void do_write();
  void schedule_reconnect();
  // A Redirect is pending: follows it once nothing written waits for an
  // answer (or at redirect_wait).
  void follow_when_ready();
  void follow_redirect();
  // Back to the server that sent the Redirect (target could not be reached).
  void redirect_failed(std::uint64_t gen, const std::string& target, const std::string& why);
  // Ends this connection's socket and timers (a new one follows).
  void drop_socket();
  PendingOps::Guard guard() { return io_.guard(); }

  ClientOptions options_;
  ConnectionHandler& handler_;
  IoSide io_;
  asio::ip::tcp::socket socket_;      // the rest: io side unless marked
  asio::steady_timer keepalive_;
  asio::steady_timer delivery_;       // the emulated link's
  asio::steady_timer reconnect_timer_;
  asio::steady_timer redirect_timer_;
  bool started_ = false;              // connect() succeeded (caller's thread)
  std::once_flag disconnect_once_;
  FrameReader reader_;
  SendQueue queue_;
  EmulatedLink link_;
  Redirects redirects_;
  asio::ip::tcp::resolver::results_type endpoints_;
  // When this connection last read a byte: silence_timeout.
  std::chrono::steady_clock::time_point last_heard_{};
  // A whole frame has come on this connection: a server that never sends
  // one is hung (silence on a reconnect) or not a terrane-server (bytes
  // that are no frame).
  bool framed_ = false;
  std::atomic<bool> closed_{false};   // any thread reads
  std::atomic<bool> leaving_{false};  // disconnect() was called
  std::uint64_t generation_ = 0;      // bumps per connection; stale handlers return
  std::chrono::milliseconds backoff_{0};
  int attempts_ = 0;
  SessionStart session_ = SessionStart::kFirst;
  bool linked_ = false;               // a connected socket to write to
  bool delivery_armed_ = false;
  bool redirect_timer_armed_ = false;
};

}  // namespace terrane
