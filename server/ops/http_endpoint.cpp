#include "server/ops/http_endpoint.h"

#include "common/cli/json.h"

#include <httplib.h>


namespace terrane {


FileResult<std::unique_ptr<HttpEndpoint>> HttpEndpoint::bind(const std::string& host, std::uint16_t port,
                                                              MetricsFn metrics, HealthFn health) {
  std::unique_ptr<HttpEndpoint> e(new HttpEndpoint());
  e->http_ = std::make_unique<httplib::Server>();
  httplib::Server& s = *e->http_;
  // Two threads are plenty for scrapes and health checks.
  s.new_task_queue = [] { return new httplib::ThreadPool(2); };
  s.set_read_timeout(5, 0);
  s.set_write_timeout(5, 0);
  s.set_keep_alive_max_count(100);
  s.set_payload_max_length(4096);
  // SO_REUSEADDR only: cpp-httplib's default adds SO_REUSEPORT, which would
  // let a second server bind the same port and take half the scrapes.
  s.set_socket_options([](int sock) {
    int yes = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
  s.Get("/metrics", [metrics](const httplib::Request&, httplib::Response& res) {
    res.set_content(metrics(), "text/plain; version=0.0.4; charset=utf-8");
  });
  s.Get("/health", [health](const httplib::Request& req, httplib::Response& res) {
    const Health h = health();
    res.status = h.ok() ? 200 : 503;
    const std::string state = health_state_name(h.state);
    if (req.get_param_value("format") == "json" ||
        req.get_header_value("Accept").find("application/json") != std::string::npos)
      res.set_content("{\"state\": \"" + state + "\", \"reason\": " + json_string(h.text) + "}\n",
                      "application/json");
    else
      res.set_content(h.ok() ? state + "\n" : state + ": " + h.text + "\n", "text/plain; charset=utf-8");
  });
  s.Get("/", [](const httplib::Request&, httplib::Response& res) {
    res.set_content("terrane-server: GET /metrics (Prometheus text format), GET /health\n", "text/plain");
  });
  int bound = 0;
  if (port == 0)
    bound = s.bind_to_any_port(host);
  else
    bound = s.bind_to_port(host, port) ? port : -1;
  if (bound <= 0)
    return FileError{"metrics: cannot listen on " + host + ":" + std::to_string(port) +
                         " (address in use, or not an address of this machine)",
                     {}};
  e->port_ = static_cast<std::uint16_t>(bound);
  return e;
}

HttpEndpoint::~HttpEndpoint() { stop(); }

void HttpEndpoint::start() {
  if (started_) return;
  started_ = true;
  thread_ = std::thread([this] {
    http_->listen_after_bind();
    listen_returned_ = true;
  });
  // cpp-httplib's stop() does nothing until the listener runs: wait for it,
  // so a stop right after start cannot leave the thread listening.
  while (!http_->is_running() && !listen_returned_) std::this_thread::yield();
}

void HttpEndpoint::stop() {
  if (http_) http_->stop();
  if (thread_.joinable()) thread_.join();
}

}  // namespace terrane
