// inspectd's JSON log lines: one object per line with time, level, message and the job id of
// the thread's ScopedLogJob.
#include "server/logging/log_format.h"

#include <gtest/gtest.h>
#include <spdlog/logger.h>
#include <spdlog/sinks/ostream_sink.h>

#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>

namespace inspection {
namespace {

// ordered_json keeps the keys in the order of the line.
std::vector<nlohmann::ordered_json> Lines(const std::string& text) {
  std::vector<nlohmann::ordered_json> out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) out.push_back(nlohmann::ordered_json::parse(line));  // throws on a non-JSON line
  return out;
}

TEST(LogFormatTest, JsonLinesCarryTimeLevelMessageAndJob) {
  std::ostringstream out;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out);
  spdlog::logger logger("", sink);
  logger.set_formatter(std::make_unique<JsonLogFormatter>());
  logger.set_level(spdlog::level::info);
  logger.info("rig state {} -> {}", "READY", "BUSY");
  {
    ScopedLogJob job("scan-00ff");
    logger.warn("frame 3: \"quoted\"\nsecond line");
    {
      ScopedLogJob inner("rec-1");
      logger.error("inner");
    }
    logger.info("outer again");
  }
  logger.debug("below the level");
  logger.info("after");
  const auto lines = Lines(out.str());
  ASSERT_EQ(lines.size(), 5u) << out.str();
  EXPECT_EQ(lines[0]["level"], "info");
  EXPECT_EQ(lines[0]["message"], "rig state READY -> BUSY");
  EXPECT_FALSE(lines[0].contains("job_id"));
  EXPECT_TRUE(
      std::regex_match(lines[0]["time"].get<std::string>(), std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z)")))
      << lines[0]["time"];
  EXPECT_EQ(lines[1]["level"], "warning");
  EXPECT_EQ(lines[1]["message"], "frame 3: \"quoted\"\nsecond line");
  EXPECT_EQ(lines[1]["job_id"], "scan-00ff");
  EXPECT_EQ(lines[2]["job_id"], "rec-1");
  EXPECT_EQ(lines[3]["job_id"], "scan-00ff");
  EXPECT_FALSE(lines[4].contains("job_id"));
  EXPECT_EQ(std::vector<std::string>({"time", "level", "message"}), [&] {
    std::vector<std::string> keys;
    for (auto it = lines[4].begin(); it != lines[4].end(); ++it) keys.push_back(it.key());
    return keys;
  }()) << "key order is stable for people reading raw lines";
}

TEST(LogFormatTest, InvalidUtf8IsReplacedNotThrown) {
  std::ostringstream out;
  spdlog::logger logger("", std::make_shared<spdlog::sinks::ostream_sink_mt>(out));
  logger.set_formatter(std::make_unique<JsonLogFormatter>());
  logger.info("file '{}'", std::string("a\xff"
                                       "b"));
  const auto lines = Lines(out.str());
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0]["message"],
            "file 'a\xEF\xBF\xBD"
            "b'");
}

TEST(LogFormatTest, OnlyTextAndJsonAreFormats) {
  EXPECT_TRUE(CheckLogFormat("text").ok());
  EXPECT_TRUE(CheckLogFormat("json").ok());
  const Status s = CheckLogFormat("JSON");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("log_format"), std::string::npos);
}

}  // namespace
}  // namespace inspection
