// The server's log (server/base/log.h): a JSON line is one object whose
// message survives quotes, backslashes and control characters; the time
// carries its offset.
#include "server/base/log.h"

#include <gtest/gtest.h>

#include "tests/support/json_doc.h"

namespace terrane {
namespace {

TEST(ServerLog, AJsonLineIsOneObjectKeepingTheMessageExactly) {
  const std::string message = "player \"a\\b\" said:\n\tline two <b>";
  const std::string line =
      json_log_line(std::chrono::system_clock::time_point(std::chrono::milliseconds(1'795'000'000'123)),
                    spdlog::level::warn, "server", message);
  EXPECT_EQ(line.find('\n'), std::string::npos) << line;
  std::string why;
  const auto doc = testing_support::parse_json(line, &why);
  ASSERT_TRUE(doc.has_value()) << why << ": " << line;
  EXPECT_EQ((*doc)["message"].string, message);
  EXPECT_EQ((*doc)["level"].string, "warning");
  EXPECT_EQ((*doc)["logger"].string, "server");
  const std::string& time = (*doc)["time"].string;
  ASSERT_EQ(time.size(), 29u) << time;
  EXPECT_EQ(time.substr(19, 4), ".123") << time;
  EXPECT_TRUE(time[23] == '+' || time[23] == '-') << time;
  EXPECT_EQ(time[26], ':') << time;
}

}  // namespace
}  // namespace terrane
