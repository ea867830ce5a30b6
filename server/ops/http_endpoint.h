// HttpEndpoint: the operator's HTTP port (`terrane-server --metrics
// ADDR:PORT`): GET /metrics (Prometheus text format) and GET /health (200
// "ready" while the server ticks and stores; 503 "STATE: reason" when it is
// starting, draining or failing, server/ops/metrics.h; with ?format=json or
// "Accept: application/json", {"state": ..., "reason": ...}).
//
// Threading: its own small pool (cpp-httplib), apart from the game's io
// threads; the handlers only read atomics (server/base/counters.h), so a slow or
// hostile scraper costs the game nothing but those threads. Requests are
// bounded by cpp-httplib (8 KiB of headers, no body accepted, 5 s timeouts).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "common/cli/cli.h"
#include "common/codec/decode_error.h"
#include "server/ops/metrics.h"

namespace httplib {
class Server;
}

namespace terrane {

class HttpEndpoint {
 public:
  using MetricsFn = std::function<std::string()>;
  using HealthFn = std::function<Health()>;

  // Binds host:port (port 0: any free one). Serves nothing until start().
  static FileResult<std::unique_ptr<HttpEndpoint>> bind(const std::string& host, std::uint16_t port,
                                                         MetricsFn metrics, HealthFn health);
  ~HttpEndpoint();
  HttpEndpoint(const HttpEndpoint&) = delete;
  HttpEndpoint& operator=(const HttpEndpoint&) = delete;

  void start();
  void stop();  // idempotent; joins the listening thread
  std::uint16_t port() const { return port_; }

 private:
  HttpEndpoint() = default;
  std::unique_ptr<httplib::Server> http_;
  std::thread thread_;
  std::uint16_t port_ = 0;
  bool started_ = false;
  std::atomic<bool> listen_returned_{false};
};


}  // namespace terrane
