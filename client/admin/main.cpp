// terrane-admin: an operator's commands to a running terrane-server, over
// the game protocol with an admin token (server/ops/admin.h lists them).
//
//   terrane-admin --connect HOST:PORT --token T [--json] COMMAND [ARGS...]
//
// Exit status: 0 the command succeeded, 1 the server refused it or could
// not be reached, 2 bad usage. With --json, stdout is exactly one JSON
// document whatever happens (a failure: {"error": "..."}); the client
// library's log lines always go to stderr.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "client/client.h"
#include "client/client_log.h"
#include "common/cli/cli.h"
#include "common/cli/json.h"

namespace terrane {
namespace {

constexpr const char* kHelp =
    "usage: terrane-admin --connect HOST:PORT --token T [--name NAME] [--json] COMMAND [ARGS...]\n"
    "\n"
    "Runs an operator's command on a terrane-server. The token must have the admin role: the\n"
    "server's --admin-token, or a tokens-file line 'NAME TOKEN admin' (give --name NAME).\n"
    "\n"
    "  --connect HOST:PORT   the server (required)\n"
    "  --token T             an admin token (required; or the TERRANE_ADMIN_TOKEN variable)\n"
    "  --name NAME           the name to join as (default admin)\n"
    "  --json                print the answer as one JSON document on stdout (for scripts);\n"
    "                        a failure prints {\"error\": \"...\"} and exits non-zero\n"
    "  --timeout S           seconds to wait for the answer (default 120)\n"
    "  --help                this text\n"
    "\n"
    "Commands:\n"
    "  status                          the server at a glance\n"
    "  players                         who is connected: name, address, position, ping, bytes\n"
    "  kick NAME [REASON...]           end NAME's session (they may join again)\n"
    "  ban NAME|ADDRESS [--for DURATION] [REASON...]\n"
    "                                  refuse NAME or ADDRESS at the handshake (DURATION: 90s,\n"
    "                                  15m, 2h, 7d; default: until unbanned); ends their sessions\n"
    "  unban NAME|ADDRESS              lift a ban\n"
    "  bans                            the bans in force\n"
    "  whitelist on|off|add NAME|remove NAME|list\n"
    "                                  while on, only listed players may join (admins always may)\n"
    "  say TEXT...                     a message to every client\n"
    "  log [--player NAME] [--box X0,Y0,Z0,X1,Y1,Z1] [--since DURATION] [--limit N]\n"
    "                                  who changed what, newest first (default limit 50)\n"
    "  rollback --player NAME [--since DURATION] [--box X0,Y0,Z0,X1,Y1,Z1]\n"
    "                                  undo NAME's edits newest first, leaving voxels others\n"
    "                                  changed since as they are: one edit, acknowledged,\n"
    "                                  stored, sent to every holder and itself logged\n"
    "  save                            wait until every edit applied so far is stored\n"
    "  backup PATH                     a consistent copy of the running world in the new\n"
    "                                  directory PATH, on the server's machine\n"
    "  shutdown [--in SECONDS] [--restart] [--reason TEXT...]\n"
    "                                  warn every client (and again 10 min, 5 min, 2 min, 60 s,\n"
    "                                  30 s, 10 s and 5 s before), then stop (saving); with --restart\n"
    "                                  clients are told the server comes back, so they reconnect;\n"
    "                                  /health says draining meanwhile\n"
    "  shutdown --cancel               cancel a pending shutdown (also: cancel-shutdown)\n"
    "  help                            the server's own list of commands\n";

// Set once the command line asks for --json: every failure is then also
// a JSON object on stdout.
bool g_json = false;

void json_error(const std::string& message) {
  if (g_json) std::printf("{\"error\": %s}\n", json_string(message).c_str());
}

int usage_error(const std::string& message) {
  json_error(message);
  std::fprintf(stderr, "terrane-admin: %s\n\n%s", message.c_str(), kHelp);
  return 2;
}

// A failure to reach the server or have the command run: exit status 1.
int failure(const std::string& message) {
  json_error(message);
  std::fprintf(stderr, "terrane-admin: %s\n", message.c_str());
  return 1;
}

int run(int argc, char** argv) {
  // The library's log goes to stderr: stdout holds the answer alone.
  // (The logger may exist already: its sinks are replaced, not the logger.)
  auto& sinks = client_log().sinks();
  sinks.clear();
  sinks.push_back(std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
  std::string connect, token, name = "admin";
  bool& json = g_json;
  for (int k = 1; k < argc && std::string(argv[k]).rfind("--", 0) == 0; ++k) {
    const std::string a = argv[k];
    if (a == "--json") json = true;
    if (a == "--connect" || a == "--token" || a == "--name" || a == "--timeout") ++k;
  }
  double timeout_s = 120;
  if (const char* t = std::getenv("TERRANE_ADMIN_TOKEN")) token = t;
  int i = 1;
  for (; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](const char* flag) -> const char* {
      if (i + 1 >= argc) return nullptr;
      (void)flag;
      return argv[++i];
    };
    if (a == "--help" || a == "-h") return std::printf("%s", kHelp), 0;
    if (a == "--json") {
      json = true;
    } else if (a == "--connect" || a == "--token" || a == "--name" || a == "--timeout") {
      const char* v = value(a.c_str());
      if (v == nullptr) return usage_error(a + ": missing value");
      if (a == "--connect") connect = v;
      if (a == "--token") token = v;
      if (a == "--name") name = v;
      if (a == "--timeout") {
        char* end = nullptr;
        timeout_s = std::strtod(v, &end);
        if (end == v || *end != '\0' || timeout_s <= 0) return usage_error("--timeout: not a positive number: " + std::string(v));
      }
    } else if (a.rfind("--", 0) == 0) {
      return usage_error("unknown option " + a);
    } else {
      break;
    }
  }
  if (connect.empty()) return usage_error("--connect HOST:PORT is required");
  if (token.empty()) return usage_error("--token T is required (or set TERRANE_ADMIN_TOKEN)");
  if (i >= argc) return usage_error("no command given");
  const std::string command = argv[i++];
  std::vector<std::string> args(argv + i, argv + argc);
  const auto hp = parse_host_port(connect);
  if (!hp || hp->second == 0) return usage_error("--connect: '" + connect + "' is not HOST:PORT (port 1..65535)");

  ClientOptions o;
  o.host = hp->first;
  o.port = hp->second;
  o.name = name;
  o.auth_token = token;
  o.stream = false;
  o.reconnect = false;
  Client client(o);
  std::string err;
  if (!client.connect(&err)) return failure("cannot reach " + connect + ": " + err);
  const auto limit = std::chrono::milliseconds(static_cast<long long>(timeout_s * 1000));
  client.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, limit);
  if (!client.welcome())
    return failure(connect + " refused the connection: " +
                   (client.closed() ? client.disconnect_reason() : std::string("no answer")));
  const std::uint32_t id = client.admin(command, args);
  if (id == 0) return usage_error("command or arguments too long (command 32 bytes, 16 arguments of 1024)");
  std::optional<AdminResultMsg> result;
  client.wait_until(
      [&](const ClientView& v) {
        if (auto it = v.admin_results.find(id); it != v.admin_results.end()) result = it->second;
        return result.has_value() || v.closed;
      },
      limit);
  client.disconnect();
  if (!result)
    return failure("no answer from " + connect +
                   (client.closed() && !client.disconnect_reason().empty() ? ": " + client.disconnect_reason() : ""));
  std::string text = result->text;
  while (!text.empty() && text.back() == '\n') text.pop_back();
  if (json && !result->ok && result->json.find("\"error\"") == std::string::npos) {
    // A refusal whose JSON was cut (too long for a frame): the text says why.
    return failure(text);
  } else if (json) {
    std::printf("%s\n", result->json.c_str());
    if (!result->ok) std::fprintf(stderr, "terrane-admin: %s\n", text.c_str());
  } else {
    std::fputs(result->text.c_str(), result->ok ? stdout : stderr);
    if (!result->text.empty() && result->text.back() != '\n') std::fputc('\n', result->ok ? stdout : stderr);
  }
  return result->ok ? 0 : 1;
}

}  // namespace
}  // namespace terrane

int main(int argc, char** argv) { return terrane::run(argc, argv); }
