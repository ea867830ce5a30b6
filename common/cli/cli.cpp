#include "common/cli/cli.h"

#include <fstream>

#include <charconv>
#include <cstdlib>

namespace terrane {

std::string trim_blanks(std::string_view text) {
  const auto a = text.find_first_not_of(" \t\r");
  if (a == std::string_view::npos) return std::string();
  return std::string(text.substr(a, text.find_last_not_of(" \t\r") - a + 1));
}

CommandLine::CommandLine(std::set<std::string> value_options, std::set<std::string> flag_options)
    : value_options_(std::move(value_options)), flag_options_(std::move(flag_options)) {}

std::string CommandLine::parse(int argc, char** argv, int first) {
  for (int i = first; i < argc; ++i) {
    std::string a = argv[i];
    if (a.size() > 2 && a.compare(0, 2, "--") == 0) {
      std::string name = a.substr(2);
      std::optional<std::string> inline_value;
      if (auto eq = name.find('='); eq != std::string::npos) {
        inline_value = name.substr(eq + 1);
        name = name.substr(0, eq);
      }
      if (flag_options_.count(name)) {
        if (inline_value) return "option --" + name + " takes no value";
        flags_.insert(name);
      } else if (value_options_.count(name)) {
        if (inline_value) {
          values_[name] = *inline_value;
        } else {
          if (i + 1 >= argc) return "option --" + name + " needs a value";
          values_[name] = argv[++i];
        }
      } else {
        return "unknown option --" + name;
      }
    } else {
      positional_.push_back(a);
    }
  }
  return {};
}

std::string CommandLine::load_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) return "cannot read " + path;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const std::string where = path + ":" + std::to_string(number) + ": ";
    // A '#' starts a comment, except inside a value in quotes ("..." or
    // '...'), which is what is between them.
    line = trim_blanks(line);
    const std::string head = trim_blanks(line.substr(0, line.find('#')));
    if (head.empty()) continue;
    std::string name;
    std::size_t value_at = head.size();  // where the value starts, in head and line alike
    if (const auto eq = head.find('='); eq != std::string::npos) {
      name = trim_blanks(head.substr(0, eq));
      value_at = eq + 1;
    } else if (const auto sp = head.find_first_of(" \t"); sp != std::string::npos) {
      name = head.substr(0, sp);
      value_at = sp;
    } else {
      name = head;
    }
    if (name.rfind("--", 0) == 0) name = name.substr(2);
    std::string value = trim_blanks(line.substr(value_at));
    if (!value.empty() && (value[0] == '"' || value[0] == '\'')) {
      const auto close = value.find(value[0], 1);
      if (close == std::string::npos) return where + name + ": a quote opened and not closed";
      const std::string rest = trim_blanks(value.substr(close + 1));
      if (!rest.empty() && rest[0] != '#') return where + name + ": text after the closing quote";
      value = value.substr(1, close - 1);
    } else {
      value = trim_blanks(value.substr(0, value.find('#')));
    }
    if (flag_options_.count(name)) {
      if (value.empty() || value == "true") {
        flags_.insert(name);
      } else if (value != "false") {
        return where + name + " is a flag: true or false, not '" + value + "'";
      }
    } else if (value_options_.count(name)) {
      if (value.empty()) return where + name + " needs a value";
      values_.emplace(name, value);  // the command line wins
    } else {
      return where + "unknown option '" + name + "'";
    }
  }
  return {};
}

std::string CommandLine::get(const std::string& name, const std::string& fallback) const {
  auto it = values_.find(name);
  return it == values_.end() ? fallback : it->second;
}

std::int64_t CommandLine::get_int(const std::string& name, std::int64_t fallback, std::int64_t min,
                                  std::int64_t max, std::string* error) const {
  auto it = values_.find(name);
  if (it == values_.end()) return fallback;
  std::int64_t v = 0;
  const std::string& s = it->second;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || p != s.data() + s.size()) {
    *error = "--" + name + ": '" + s + "' is not a whole number";
    return fallback;
  }
  if (v < min || v > max) {
    *error = "--" + name + ": " + s + " is out of range [" + std::to_string(min) + ", " + std::to_string(max) + "]";
    return fallback;
  }
  return v;
}

double CommandLine::get_double(const std::string& name, double fallback, double min, double max,
                               std::string* error) const {
  auto it = values_.find(name);
  if (it == values_.end()) return fallback;
  const std::string& s = it->second;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || end != s.c_str() + s.size()) {
    *error = "--" + name + ": '" + s + "' is not a number";
    return fallback;
  }
  if (!(v >= min && v <= max)) {
    *error = "--" + name + ": " + s + " is out of range [" + std::to_string(min) + ", " + std::to_string(max) + "]";
    return fallback;
  }
  return v;
}

std::optional<Region> CommandLine::get_region(const std::string& name, std::string* error) const {
  auto it = values_.find(name);
  if (it == values_.end()) return std::nullopt;
  std::int32_t v[6];
  if (!parse_int_list(it->second, v, 6)) {
    *error = "--" + name + ": '" + it->second + "' is not x0,y0,z0,x1,y1,z1 (six whole numbers)";
    return std::nullopt;
  }
  const Region r{{v[0], v[1], v[2]}, {v[3], v[4], v[5]}};
  if (r.empty()) {
    *error = "--" + name + ": '" + it->second + "' is empty (each of x1, y1, z1 must exceed x0, y0, z0)";
    return std::nullopt;
  }
  constexpr std::int64_t kMaxCoordinate = std::int64_t{1} << 30;
  constexpr std::int64_t kMaxSpan = std::int64_t{1} << 20;
  for (int i = 0; i < 6; ++i) {
    if (v[i] < -kMaxCoordinate || v[i] > kMaxCoordinate) {
      *error = "--" + name + ": coordinate " + std::to_string(v[i]) + " is beyond +-2^30";
      return std::nullopt;
    }
  }
  if (std::int64_t{v[3]} - v[0] > kMaxSpan || std::int64_t{v[4]} - v[1] > kMaxSpan || std::int64_t{v[5]} - v[2] > kMaxSpan) {
    *error = "--" + name + ": '" + it->second + "' spans more than 2^20 voxels on an axis";
    return std::nullopt;
  }
  return r;
}

std::optional<Vec3i> CommandLine::get_vec3i(const std::string& name, std::string* error) const {
  auto it = values_.find(name);
  if (it == values_.end()) return std::nullopt;
  std::int32_t v[3];
  if (!parse_int_list(it->second, v, 3)) {
    *error = "--" + name + ": '" + it->second + "' is not x,y,z (three whole numbers)";
    return std::nullopt;
  }
  return Vec3i{v[0], v[1], v[2]};
}

FileResult<std::pair<std::string, std::uint16_t>> parse_host_port(const std::string& text) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == text.size())
    return FileError{"'" + text + "' is not HOST:PORT (e.g. 127.0.0.1:9464)", {}};
  std::string host = text.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  unsigned port = 0;
  const char* first = text.data() + colon + 1;
  const char* last = text.data() + text.size();
  const auto [end, ec] = std::from_chars(first, last, port);
  if (ec != std::errc{} || end != last || port > 65535)
    return FileError{"'" + text + "': port must be a number from 0 to 65535", {}};
  return std::pair{host, static_cast<std::uint16_t>(port)};
}

}  // namespace terrane
