// The tokens file's format (protocol/tokens_file.h): entries in order,
// comments, roles, and errors that name the file and line.
#include "protocol/tokens_file.h"

#include <gtest/gtest.h>

#include <string>

namespace terrane {
namespace {

TEST(TokensFile, EntriesKeepTheFilesOrderRolesAndLines) {
  const auto r = parse_tokens_file(
      "# players\n\nops secret-0 admin\nalice a#1 # a '#' inside a token is part of it\n  bob   b2   player\n", "t");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->size(), 3u);
  EXPECT_EQ((*r)[0].name, "ops");
  EXPECT_TRUE((*r)[0].admin);
  EXPECT_EQ((*r)[0].line, 3);
  EXPECT_EQ((*r)[1].name, "alice");
  EXPECT_EQ((*r)[1].token, "a#1");
  EXPECT_FALSE((*r)[1].admin);
  EXPECT_EQ((*r)[2].name, "bob");
  EXPECT_EQ((*r)[2].token, "b2");
  EXPECT_EQ((*r)[2].line, 5);
}

TEST(TokensFile, ErrorsNameTheSourceAndLine) {
  const auto error = [](const std::string& text) {
    const auto r = parse_tokens_file(text, "tokens.txt");
    return r.ok() ? std::string("ok") : r.error().message;
  };
  EXPECT_EQ(error("a 1\nlonely\n"), "tokens.txt:2: player 'lonely' has no token");
  EXPECT_EQ(error("a 1 god\n"), "tokens.txt:1: role 'god' is neither player nor admin");
  EXPECT_EQ(error("a 1 admin extra\n"), "tokens.txt:1: expected 'NAME TOKEN [player|admin]', found more");
  EXPECT_EQ(error("a 1\nb 2\na 3\n"), "tokens.txt:3: player 'a' listed twice");
  EXPECT_EQ(error(std::string(65, 'n') + " t\n"), "tokens.txt:1: name longer than 64 bytes");
  EXPECT_EQ(error("n " + std::string(257, 't') + "\n"), "tokens.txt:1: token longer than 256 bytes");
  EXPECT_EQ(read_tokens_file("/nonexistent/tokens").error().message, "cannot read tokens file /nonexistent/tokens");
}

}  // namespace
}  // namespace terrane
