// Test support: a strict JSON parser (RFC 8259: one value, whitespace
// around it, nothing after), so tests can check that what a tool printed is
// exactly one JSON document and read its fields. Numbers are doubles;
// \u escapes outside ASCII are kept as '?' (tests compare ASCII only).
#pragma once

#include <cctype>
#include <cstdlib>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace terrane::testing_support {

struct JsonDoc {
  enum class Kind { kNull, kBool, kNumber, kString, kArray, kObject } kind = Kind::kNull;
  bool boolean = false;
  double number = 0;
  std::string string;
  std::vector<JsonDoc> array;
  std::map<std::string, JsonDoc> object;

  bool has(const std::string& key) const { return kind == Kind::kObject && object.count(key) != 0; }
  // The member key (a null value when absent or not an object).
  const JsonDoc& operator[](const std::string& key) const {
    static const JsonDoc kNone;
    if (kind != Kind::kObject) return kNone;
    const auto it = object.find(key);
    return it == object.end() ? kNone : it->second;
  }
};

namespace json_detail {

struct Parser {
  std::string_view s;
  std::size_t at = 0;
  std::string error;

  void blanks() {
    while (at < s.size() && (s[at] == ' ' || s[at] == '\t' || s[at] == '\n' || s[at] == '\r')) ++at;
  }
  bool fail(const std::string& why) {
    if (error.empty()) error = why + " at byte " + std::to_string(at);
    return false;
  }
  bool literal(std::string_view word) {
    if (s.substr(at, word.size()) != word) return fail("expected " + std::string(word));
    at += word.size();
    return true;
  }
  bool string(std::string* out) {
    if (at >= s.size() || s[at] != '"') return fail("expected a string");
    ++at;
    while (at < s.size() && s[at] != '"') {
      const char c = s[at++];
      if (static_cast<unsigned char>(c) < 0x20) return fail("a control character in a string");
      if (c != '\\') {
        out->push_back(c);
        continue;
      }
      if (at >= s.size()) return fail("a string ends in an escape");
      const char e = s[at++];
      switch (e) {
        case '"': out->push_back('"'); break;
        case '\\': out->push_back('\\'); break;
        case '/': out->push_back('/'); break;
        case 'b': out->push_back('\b'); break;
        case 'f': out->push_back('\f'); break;
        case 'n': out->push_back('\n'); break;
        case 'r': out->push_back('\r'); break;
        case 't': out->push_back('\t'); break;
        case 'u': {
          if (at + 4 > s.size()) return fail("a short \\u escape");
          for (std::size_t i = 0; i < 4; ++i)
            if (!std::isxdigit(static_cast<unsigned char>(s[at + i]))) return fail("a bad \\u escape");
          const long code = std::strtol(std::string(s.substr(at, 4)).c_str(), nullptr, 16);
          out->push_back(code < 0x80 ? static_cast<char>(code) : '?');
          at += 4;
          break;
        }
        default: return fail("a bad escape");
      }
    }
    if (at >= s.size()) return fail("an unterminated string");
    ++at;
    return true;
  }
  bool number(double* out) {
    const std::size_t begin = at;
    if (at < s.size() && s[at] == '-') ++at;
    if (at >= s.size() || !std::isdigit(static_cast<unsigned char>(s[at]))) return fail("expected a digit");
    if (s[at] == '0' && at + 1 < s.size() && std::isdigit(static_cast<unsigned char>(s[at + 1])))
      return fail("a leading zero");
    while (at < s.size() && std::isdigit(static_cast<unsigned char>(s[at]))) ++at;
    if (at < s.size() && s[at] == '.') {
      ++at;
      if (at >= s.size() || !std::isdigit(static_cast<unsigned char>(s[at]))) return fail("expected a fraction");
      while (at < s.size() && std::isdigit(static_cast<unsigned char>(s[at]))) ++at;
    }
    if (at < s.size() && (s[at] == 'e' || s[at] == 'E')) {
      ++at;
      if (at < s.size() && (s[at] == '+' || s[at] == '-')) ++at;
      if (at >= s.size() || !std::isdigit(static_cast<unsigned char>(s[at]))) return fail("expected an exponent");
      while (at < s.size() && std::isdigit(static_cast<unsigned char>(s[at]))) ++at;
    }
    *out = std::strtod(std::string(s.substr(begin, at - begin)).c_str(), nullptr);
    return true;
  }
  bool value(JsonDoc* v, int depth) {
    if (depth > 64) return fail("nested too deep");
    blanks();
    if (at >= s.size()) return fail("expected a value");
    const char c = s[at];
    if (c == '{') {
      v->kind = JsonDoc::Kind::kObject;
      ++at;
      blanks();
      if (at < s.size() && s[at] == '}') return ++at, true;
      for (;;) {
        blanks();
        std::string key;
        if (!string(&key)) return false;
        blanks();
        if (at >= s.size() || s[at] != ':') return fail("expected ':'");
        ++at;
        if (v->object.count(key)) return fail("a duplicate key '" + key + "'");
        if (!value(&v->object[key], depth + 1)) return false;
        blanks();
        if (at < s.size() && s[at] == ',') {
          ++at;
          continue;
        }
        if (at < s.size() && s[at] == '}') return ++at, true;
        return fail("expected ',' or '}'");
      }
    }
    if (c == '[') {
      v->kind = JsonDoc::Kind::kArray;
      ++at;
      blanks();
      if (at < s.size() && s[at] == ']') return ++at, true;
      for (;;) {
        v->array.emplace_back();
        if (!value(&v->array.back(), depth + 1)) return false;
        blanks();
        if (at < s.size() && s[at] == ',') {
          ++at;
          continue;
        }
        if (at < s.size() && s[at] == ']') return ++at, true;
        return fail("expected ',' or ']'");
      }
    }
    if (c == '"') return v->kind = JsonDoc::Kind::kString, string(&v->string);
    if (c == 't') return v->kind = JsonDoc::Kind::kBool, v->boolean = true, literal("true");
    if (c == 'f') return v->kind = JsonDoc::Kind::kBool, v->boolean = false, literal("false");
    if (c == 'n') return v->kind = JsonDoc::Kind::kNull, literal("null");
    return v->kind = JsonDoc::Kind::kNumber, number(&v->number);
  }
};

}  // namespace json_detail

// text as exactly one JSON document; nullopt (and *error says where) if it
// is not.
inline std::optional<JsonDoc> parse_json(std::string_view text, std::string* error = nullptr) {
  json_detail::Parser p;
  p.s = text;
  JsonDoc doc;
  bool good = p.value(&doc, 0);
  if (good) {
    p.blanks();
    if (p.at != text.size()) good = p.fail("text after the document");
  }
  if (!good) {
    if (error) *error = p.error;
    return std::nullopt;
  }
  return doc;
}

}  // namespace terrane::testing_support
