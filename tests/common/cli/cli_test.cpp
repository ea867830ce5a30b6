#include "common/cli/cli.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

namespace terrane {
namespace {

namespace fs = std::filesystem;

class CliFileTest : public ::testing::Test {
 protected:
  void write(const std::string& text) { std::ofstream(path_) << text; }
  void TearDown() override { fs::remove(path_); }
  fs::path path_ = fs::temp_directory_path() / ("terrane-cli-" + std::to_string(::getpid()) + ".conf");
};

TEST_F(CliFileTest, FileOptionsFillInAndTheCommandLineWins) {
  write("# server\nport = 7000\ntick-hz 30\n--bind=ignored-form-is-fine\nopen = true\n\n");
  CommandLine cl({"port", "tick-hz", "bind"}, {"open", "help"});
  char a0[] = "prog", a1[] = "--port", a2[] = "8000";
  char* argv[] = {a0, a1, a2};
  ASSERT_EQ(cl.parse(3, argv, 1), "");
  ASSERT_EQ(cl.load_file(path_.string()), "");
  std::string err;
  EXPECT_EQ(cl.get_int("port", 0, 0, 65535, &err), 8000);  // command line
  EXPECT_EQ(cl.get_int("tick-hz", 0, 0, 1000, &err), 30);  // file
  EXPECT_EQ(cl.get("bind"), "ignored-form-is-fine");
  EXPECT_TRUE(cl.flag("open"));
  EXPECT_TRUE(err.empty());
}

TEST_F(CliFileTest, QuotedValuesLoseTheirQuotesAndMayHoldAHash) {
  write("world = \"/srv/my world\"  # restored\nbind = '0.0.0.0'\nauth-token = \"a#b\" # comment\nname = plain # c\n");
  CommandLine cl({"world", "bind", "auth-token", "name"}, {});
  ASSERT_EQ(cl.load_file(path_.string()), "");
  EXPECT_EQ(cl.get("world"), "/srv/my world");
  EXPECT_EQ(cl.get("bind"), "0.0.0.0");
  EXPECT_EQ(cl.get("auth-token"), "a#b");
  EXPECT_EQ(cl.get("name"), "plain");
  write("world = \"/srv/unclosed\n");
  CommandLine c2({"world"}, {});
  EXPECT_EQ(c2.load_file(path_.string()), path_.string() + ":1: world: a quote opened and not closed");
  write("world = \"/a\" trailing\n");
  CommandLine c3({"world"}, {});
  EXPECT_EQ(c3.load_file(path_.string()), path_.string() + ":1: world: text after the closing quote");
}

TEST_F(CliFileTest, AQuoteInsideAnUnquotedValueLeavesTheCommentAComment) {
  write("name = it's here # a note\nworld = /srv/a\"b # another\n");
  CommandLine cl({"name", "world"}, {});
  ASSERT_EQ(cl.load_file(path_.string()), "");
  EXPECT_EQ(cl.get("name"), "it's here");
  EXPECT_EQ(cl.get("world"), "/srv/a\"b");
}

TEST_F(CliFileTest, ErrorsNameTheFileAndLine) {
  write("port = 1\nbogus = 2\n");
  CommandLine cl({"port"}, {"open"});
  EXPECT_EQ(cl.load_file(path_.string()), path_.string() + ":2: unknown option 'bogus'");
  write("open = maybe\n");
  CommandLine c2({"port"}, {"open"});
  EXPECT_NE(c2.load_file(path_.string()).find(":1: open is a flag"), std::string::npos);
  write("port\n");
  CommandLine c3({"port"}, {"open"});
  EXPECT_NE(c3.load_file(path_.string()).find(":1: port needs a value"), std::string::npos);
  CommandLine c4({"port"}, {});
  EXPECT_EQ(c4.load_file("/nonexistent/terrane.conf"), "cannot read /nonexistent/terrane.conf");
}

TEST(TrimBlanks, DropsSpacesTabsAndCarriageReturnsAroundOnly) {
  EXPECT_EQ(trim_blanks(" \t key = a b \r"), "key = a b");
  EXPECT_EQ(trim_blanks("fanout_p99<100"), "fanout_p99<100");
  EXPECT_EQ(trim_blanks(" \t\r "), "");
  EXPECT_EQ(trim_blanks(""), "");
}

}  // namespace
}  // namespace terrane
