// inspectctl as a user runs it, for the CLI tests: the built binary in a child process against the
// real server on loopback (tests/server/server_fixture.h), with its exit code, stdout and stderr.
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "tests/server/server_fixture.h"

extern char** environ;

namespace inspection::testing {
namespace fs = std::filesystem;
using nlohmann::json;

inline fs::path InspectctlPath() {
#ifdef INSPECTCTL_PATH
  return INSPECTCTL_PATH;
#else
  return fs::read_symlink("/proc/self/exe").parent_path() / "inspectctl";
#endif
}

inline std::string ReadAll(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

struct CliResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};

// One inspectctl process: stdout through a pipe (read by the test), stderr to a file. The
// environment is the test's without INSPECT_* variables, so only the arguments count.
class CliProcess {
 public:
  CliProcess(const std::vector<std::string>& args, const fs::path& stderr_file) : stderr_file_(stderr_file) {
    int fds[2];
    EXPECT_EQ(pipe(fds), 0);
    read_fd_ = fds[0];
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[1], STDOUT_FILENO);
    posix_spawn_file_actions_addclose(&actions, fds[0]);
    posix_spawn_file_actions_addclose(&actions, fds[1]);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, stderr_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const std::string exe = InspectctlPath().string();
    std::vector<std::string> storage{exe};
    storage.insert(storage.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& s : storage) argv.push_back(s.data());
    argv.push_back(nullptr);
    std::vector<char*> envp;
    for (char** e = environ; *e != nullptr; ++e) {
      if (std::strncmp(*e, "INSPECT_", 8) != 0) envp.push_back(*e);
    }
    envp.push_back(nullptr);
    const int rc = posix_spawn(&pid_, exe.c_str(), &actions, nullptr, argv.data(), envp.data());
    EXPECT_EQ(rc, 0) << "cannot start " << exe << ": " << std::strerror(rc);
    posix_spawn_file_actions_destroy(&actions);
    close(fds[1]);
  }
  ~CliProcess() {
    if (read_fd_ >= 0) close(read_fd_);
    if (pid_ > 0 && !waited_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }

  // Reads stdout up to and including the next newline; false at end of output.
  bool ReadLine(std::string* line) {
    line->clear();
    char c;
    while (read(read_fd_, &c, 1) == 1) {
      out_ += c;
      if (c == '\n') return true;
      *line += c;
    }
    return false;
  }

  void Signal(int sig) { kill(pid_, sig); }

  // Reads stdout to its end, waits for the exit, collects everything.
  CliResult Finish() {
    char buf[4096];
    ssize_t n;
    while ((n = read(read_fd_, buf, sizeof buf)) > 0) out_.append(buf, static_cast<size_t>(n));
    int status = 0;
    waitpid(pid_, &status, 0);
    waited_ = true;
    CliResult r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    r.out = out_;
    r.err = ReadAll(stderr_file_);
    return r;
  }

 private:
  fs::path stderr_file_;
  pid_t pid_ = -1;
  int read_fd_ = -1;
  bool waited_ = false;
  std::string out_;
};

// Parses JSON Lines; a line that is not JSON fails the test.
inline std::vector<json> JsonLines(const std::string& text) {
  std::vector<json> lines;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    json j = json::parse(line, nullptr, false);
    EXPECT_FALSE(j.is_discarded()) << "not JSON: " << line;
    lines.push_back(j);
  }
  return lines;
}

inline int CountLines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }

class CliTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    work_ = UniqueTempDir("cli");
  }
  void TearDown() override {
    fs::remove_all(work_);
    ServerTest::TearDown();
  }

  std::vector<std::string> WithServer(std::vector<std::string> args) {
    args.insert(args.begin(), {"--server", server_->address(), "--connect-timeout", "5"});
    return args;
  }
  std::unique_ptr<CliProcess> Start(const std::vector<std::string>& args) {
    return std::make_unique<CliProcess>(WithServer(args), work_ / ("stderr_" + std::to_string(++runs_) + ".txt"));
  }
  CliResult Run(const std::vector<std::string>& args) { return Start(args)->Finish(); }

  // A scan with the rig's defaults, results into work_/name; returns the --json result object.
  json JsonScan(const std::string& name, std::vector<std::string> extra = {}) {
    std::vector<std::string> args{"--json", "scan", "--out", (work_ / name).string()};
    args.insert(args.end(), extra.begin(), extra.end());
    CliResult r = Run(args);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    auto lines = JsonLines(r.out);
    if (lines.empty()) return json::object();
    return lines.back();
  }

  // The newest job's id, found through the API (the CLI's output is what is under test).
  std::string NewestJobId() {
    v1::ListJobsRequest req;
    req.set_page_size(1);
    v1::ListJobsResponse resp;
    EXPECT_TRUE(client_->ListJobs(req, &resp).ok());
    return resp.jobs_size() > 0 ? resp.jobs(0).job_id() : "";
  }

  fs::path work_;
  int runs_ = 0;
};

}  // namespace inspection::testing
