// A small command-line parser shared by Terrane's tools: long options
// (--name value, --name=value, boolean --flag), positional arguments, and
// typed getters that produce clear errors naming the option and the value.
#pragma once

#include <charconv>
#include <cstdint>
#include <string_view>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/vec3.h"

namespace terrane {

class CommandLine {
 public:
  // value_options take a value; flag_options do not. Anything else starting
  // with "--" is an error ("unknown option --x").
  CommandLine(std::set<std::string> value_options, std::set<std::string> flag_options);

  // Parses argv[first..argc). Returns an error message, or empty on success.
  std::string parse(int argc, char** argv, int first);

  // Reads options from a file: one "name = value" (or "name value") per
  // line, a flag as "name" or "name = true|false", '#' comments; a value
  // in quotes ("..." or '...') is what is between them (a '#' inside is
  // kept). Options
  // already given on the command line win. Returns an error naming the file
  // and line, or empty on success.
  std::string load_file(const std::string& path);

  bool has(const std::string& name) const { return values_.count(name) > 0; }
  bool flag(const std::string& name) const { return flags_.count(name) > 0; }
  const std::vector<std::string>& positional() const { return positional_; }

  // Typed getters: the default when absent; on a malformed value, *error is
  // set to a message naming the option (and the value is the default).
  std::string get(const std::string& name, const std::string& fallback = "") const;
  std::int64_t get_int(const std::string& name, std::int64_t fallback, std::int64_t min, std::int64_t max,
                       std::string* error) const;
  double get_double(const std::string& name, double fallback, double min, double max, std::string* error) const;
  // "x0,y0,z0,x1,y1,z1" (half-open box, each max > min).
  std::optional<Region> get_region(const std::string& name, std::string* error) const;
  // "x,y,z" integers.
  std::optional<Vec3i> get_vec3i(const std::string& name, std::string* error) const;

 private:
  std::set<std::string> value_options_, flag_options_;
  std::map<std::string, std::string> values_;
  std::set<std::string> flags_;
  std::vector<std::string> positional_;
};

// Parses "a,b,c,..." into exactly n integers; false if malformed or out of
// the type's range.
template <class Int>
bool parse_int_list(std::string_view text, Int* out, int n) {
  const char* p = text.data();
  const char* end = text.data() + text.size();
  for (int i = 0; i < n; ++i) {
    auto [next, ec] = std::from_chars(p, end, out[i]);
    if (ec != std::errc()) return false;
    p = next;
    if (i + 1 < n) {
      if (p == end || *p != ',') return false;
      ++p;
    }
  }
  return p == end;
}

// text without the spaces, tabs and carriage returns around it (option
// files' and scenario files' lines, their names and values).
std::string trim_blanks(std::string_view text);

// "HOST:PORT" or "[V6]:PORT" (port 0..65535) into its parts; the error
// names what is wrong. Every tool's address flags go through it.
FileResult<std::pair<std::string, std::uint16_t>> parse_host_port(const std::string& text);

}  // namespace terrane
