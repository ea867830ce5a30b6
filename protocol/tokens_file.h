// The tokens file: who may join a server and with which token, one player a
// line ("NAME TOKEN [player|admin]"). The server admits by it
// (server/net/limits.h) and terrane-bots joins by it (--tokens-file), so
// both read it here, with the names and tokens a Hello may carry.
//
// Thread-safety: pure functions.
#pragma once

#include <string>
#include <vector>

#include "common/codec/decode_error.h"

namespace terrane {

// One player of a tokens file, as written.
struct TokensFileEntry {
  std::string name;
  std::string token;
  bool admin = false;  // role admin (else player, the default)
  int line = 0;        // 1-based line number in the file
};

// Parses a tokens file's text, entries in the file's order. Words are
// separated by whitespace; a word opening with '#' ends the line (a comment,
// also after the words; a '#' inside a token is part of it); blank lines
// are skipped. Errors name source:line: a line without a token, an unknown
// role, more than three words, a name or token over the protocol's limits
// (kMaxClientNameBytes, kMaxAuthTokenBytes), a name listed twice.
FileResult<std::vector<TokensFileEntry>> parse_tokens_file(const std::string& text, const std::string& source);

// Reads and parses the file at path ("cannot read tokens file PATH" when it
// cannot be opened).
FileResult<std::vector<TokensFileEntry>> read_tokens_file(const std::string& path);

}  // namespace terrane
