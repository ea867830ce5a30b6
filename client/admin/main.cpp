// terrane-admin: an operator's commands to a running terrane-server, over
// the game protocol with an admin token (server/ops/admin.h lists them).
//
//   terrane-admin --connect HOST:PORT --token T [--json] COMMAND [ARGS...]
//
// Exit status: 0 the command succeeded, 1 the server refused it or could
// not be reached, 2 bad usage.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "client/client.h"
#include "common/cli/cli.h"

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
    "  --json                print the answer as JSON (for scripts)\n"
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
    "                                  warn every client, then stop (saving); --restart tells\n"
    "                                  clients the server comes back, so they reconnect\n"
    "  help                            the server's own list of commands\n";

int usage_error(const std::string& message) {
  std::fprintf(stderr, "terrane-admin: %s\n\n%s", message.c_str(), kHelp);
  return 2;
}

int run(int argc, char** argv) {
  std::string connect, token, name = "admin";
  bool json = false;
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
  if (!client.connect(&err)) {
    std::fprintf(stderr, "terrane-admin: cannot reach %s: %s\n", connect.c_str(), err.c_str());
    return 1;
  }
  const auto limit = std::chrono::milliseconds(static_cast<long long>(timeout_s * 1000));
  client.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, limit);
  if (!client.welcome()) {
    std::fprintf(stderr, "terrane-admin: %s refused the connection: %s\n", connect.c_str(),
                 client.closed() ? client.disconnect_reason().c_str() : "no answer");
    return 1;
  }
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
  if (!result) {
    std::fprintf(stderr, "terrane-admin: no answer from %s%s\n", connect.c_str(),
                 client.closed() && !client.disconnect_reason().empty() ? (": " + client.disconnect_reason()).c_str() : "");
    return 1;
  }
  if (json) {
    std::printf("%s\n", result->json.c_str());
  } else {
    std::fputs(result->text.c_str(), result->ok ? stdout : stderr);
    if (!result->text.empty() && result->text.back() != '\n') std::fputc('\n', result->ok ? stdout : stderr);
  }
  return result->ok ? 0 : 1;
}

}  // namespace
}  // namespace terrane

int main(int argc, char** argv) { return terrane::run(argc, argv); }
