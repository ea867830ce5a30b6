// Test support for the bots' tests: parse_bots_options over a command line
// given as strings, after the program's name, as terrane-bots parses argv.
#pragma once

#include <string>
#include <vector>

#include "client/bots/options.h"

namespace terrane::bots {

inline std::string parse_flags(std::vector<std::string> args, BotsOptions* o) {
  args.insert(args.begin(), "terrane-bots");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  bool help = false;
  return parse_bots_options(static_cast<int>(argv.size()), argv.data(), 1, o, &help);
}

}  // namespace terrane::bots
