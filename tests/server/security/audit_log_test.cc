// Audit log: one JSON object per line, read back; rotation by size; no secrets, cut free text.
#include "server/security/audit_log.h"

#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

namespace inspection {
namespace {
namespace fs = std::filesystem;

std::vector<nlohmann::json> ReadLines(const fs::path& p) {
  std::vector<nlohmann::json> out;
  std::ifstream in(p);
  std::string line;
  while (std::getline(in, line)) out.push_back(nlohmann::json::parse(line));
  return out;
}

class AuditLogTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("audit-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(AuditLogTest, RecordsReadBackAsJsonLines) {
  AuditLogOptions o;
  o.path = dir_ / "audit.jsonl";
  auto log = AuditLog::Open(o);
  ASSERT_TRUE(log.ok()) << log.status().ToString();
  (*log)->Append({"station-7", "operator", "ipv4:127.0.0.1:1", "Scan", "job-42", StatusCode::kOk, ""});
  (*log)->Append({"station-7", "operator", "ipv4:127.0.0.1:1", "ResetRig", "", StatusCode::kPermissionDenied,
                  "ResetRig needs role admin; 'station-7' has role operator"});
  auto lines = ReadLines(o.path);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0]["identity"], "station-7");
  EXPECT_EQ(lines[0]["method"], "Scan");
  EXPECT_EQ(lines[0]["target"], "job-42");
  EXPECT_EQ(lines[0]["code"], "OK");
  EXPECT_EQ(lines[0]["peer"], "ipv4:127.0.0.1:1");
  EXPECT_FALSE(lines[0].contains("message"));
  EXPECT_EQ(lines[1]["code"], "PERMISSION_DENIED");
  const std::string t = lines[1]["time"];
  EXPECT_EQ(t.size(), 24u);  // 2026-11-25T16:00:00.000Z
  EXPECT_EQ(t.back(), 'Z');
  EXPECT_EQ((*log)->failed_writes(), 0);
}

TEST_F(AuditLogTest, FreeTextIsCutAndInvalidUtf8Replaced) {
  AuditRecord r;
  r.identity = "x";
  r.method = "Scan";
  r.message = std::string(3 << 20, 'a');  // a 3 MB label echoed in an error must not reach the log
  r.target = "job\xff\xfe";
  const std::string line = AuditLog::Format(r, 0);
  EXPECT_LT(line.size(), 1000u);
  auto j = nlohmann::json::parse(line);
  EXPECT_EQ(j["message"].get<std::string>().size(), kMaxAuditTextBytes + 3);
  EXPECT_EQ(j["time"], "1970-01-01T00:00:00.000Z");
}

TEST_F(AuditLogTest, RotatesBySizeAndKeepsTheNewestFiles) {
  AuditLogOptions o;
  o.path = dir_ / "audit.jsonl";
  o.max_file_bytes = 1024;
  o.max_rotated_files = 2;
  auto log = AuditLog::Open(o);
  ASSERT_TRUE(log.ok());
  for (int i = 0; i < 100; ++i) {
    (*log)->Append({"op", "operator", "peer", "Scan", "job-" + std::to_string(i), StatusCode::kOk, ""});
  }
  ASSERT_TRUE(fs::exists(o.path));
  ASSERT_TRUE(fs::exists(dir_ / "audit.jsonl.1"));
  ASSERT_TRUE(fs::exists(dir_ / "audit.jsonl.2"));
  EXPECT_FALSE(fs::exists(dir_ / "audit.jsonl.3"));
  EXPECT_LE(fs::file_size(o.path), 1024u);
  EXPECT_LE(fs::file_size(dir_ / "audit.jsonl.1"), 1024u);
  // The newest record is the last line of the current file; the rotated ones hold older jobs.
  auto current = ReadLines(o.path);
  EXPECT_EQ(current.back()["target"], "job-99");
  auto older = ReadLines(dir_ / "audit.jsonl.1");
  ASSERT_FALSE(older.empty());
  EXPECT_EQ(older.back()["target"].get<std::string>(), "job-" + std::to_string(99 - static_cast<int>(current.size())));
}

TEST_F(AuditLogTest, BadOptionsAreRefused) {
  AuditLogOptions o;
  EXPECT_EQ(AuditLog::Open(o).status().code(), StatusCode::kInvalidArgument);
  o.path = dir_ / "a.jsonl";
  o.max_file_bytes = 10;
  EXPECT_EQ(AuditLog::Open(o).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
