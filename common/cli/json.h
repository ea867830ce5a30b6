// JSON text for the tools' reports and answers: a string's escaped body.
// One escaper for every JSON Terrane writes (bots reports, admin answers).
#pragma once

#include <cstdio>
#include <string>
#include <string_view>

namespace terrane {

// s escaped for use between JSON quotes: quote, backslash and control
// characters; '<' too, so the text is also safe inside HTML.
inline std::string json_escape(std::string_view s) {
  std::string o;
  o.reserve(s.size());
  for (const char c : s) {
    switch (c) {
      case '"': o += "\\\""; break;
      case '\\': o += "\\\\"; break;
      case '\n': o += "\\n"; break;
      case '\r': o += "\\r"; break;
      case '\t': o += "\\t"; break;
      case '<': o += "\\u003c"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char b[8];
          std::snprintf(b, sizeof b, "\\u%04x", static_cast<unsigned>(static_cast<unsigned char>(c)));
          o += b;
        } else {
          o += c;
        }
    }
  }
  return o;
}

// The same, quoted: a whole JSON string.
inline std::string json_string(std::string_view s) {
  std::string o(1, '"');  // appended, not operator+: GCC 12 misreads that chain at -O3
  o.append(json_escape(s));
  o.push_back('"');
  return o;
}

}  // namespace terrane
