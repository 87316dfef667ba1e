// The temporary stack folder of `reconstruct --images` (client_cli/image_folder.h): one left by an
// inspectctl that was killed (its destructor never ran) is removed by the next one; a live
// process's folder, an older inspectctl's folder without an owner file and anything else in
// $TMPDIR are kept; the user's images are never touched.
#include "client_cli/image_folder.h"

#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace inspection::client::cli {
namespace {

namespace fs = std::filesystem;

pid_t DeadPid() {  // a child that has exited and been reaped: kill(pid, 0) answers ESRCH
  const pid_t child = fork();
  if (child == 0) _exit(0);
  int status = 0;
  waitpid(child, &status, 0);
  return child;
}

TEST(StackFolderTest, ATemporaryFolderOfAKilledInspectctlIsRemovedByTheNextOne) {
  const fs::path tmp = fs::temp_directory_path() / ("image-folder-test-" + std::to_string(::getpid()));
  fs::remove_all(tmp);
  fs::create_directories(tmp / "images");
  std::ofstream(tmp / "images" / "f0.png") << "not really a png";
  const char* old_tmpdir = std::getenv("TMPDIR");
  const std::string saved = old_tmpdir ? old_tmpdir : "";
  setenv("TMPDIR", tmp.c_str(), 1);

  auto folder = [&](const std::string& name, long pid) {
    fs::create_directories(tmp / name);
    fs::create_hard_link(tmp / "images" / "f0.png", tmp / name / "f0.png");
    if (pid > 0) std::ofstream(tmp / name / ".inspectctl-owner") << pid << "\n";
  };
  folder("inspectctl-stack-dead01", DeadPid());
  folder("inspectctl-stack-live01", ::getpid());
  folder("inspectctl-stack-older1", 0);  // an older inspectctl's: no owner file
  fs::create_directories(tmp / "other-stack-dead");
  std::ofstream(tmp / "other-stack-dead" / ".inspectctl-owner") << DeadPid() << "\n";

  {
    StackFolder made;
    ImageFrame frame;
    frame.source = tmp / "images" / "f0.png";
    frame.file = "f0.png";
    frame.z_um = 0.0;
    grpc::Status s = made.Create({frame}, "{}\n");
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(made.path().parent_path(), tmp);
    std::ifstream owner(made.path() / ".inspectctl-owner");
    long pid = 0;
    owner >> pid;
    EXPECT_EQ(pid, ::getpid());
    EXPECT_FALSE(fs::exists(tmp / "inspectctl-stack-dead01"));
    EXPECT_TRUE(fs::exists(tmp / "inspectctl-stack-live01" / "f0.png"));
    EXPECT_TRUE(fs::exists(tmp / "inspectctl-stack-older1" / "f0.png"));
    EXPECT_TRUE(fs::exists(tmp / "other-stack-dead"));
    EXPECT_TRUE(fs::exists(tmp / "images" / "f0.png"));  // what the links pointed to stays
  }
  if (saved.empty()) {
    unsetenv("TMPDIR");
  } else {
    setenv("TMPDIR", saved.c_str(), 1);
  }
  fs::remove_all(tmp);
}

}  // namespace
}  // namespace inspection::client::cli
