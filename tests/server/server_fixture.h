// Starts the real server (InspectionServer) on a free loopback port with a temporary data dir,
// and connects the real client library to it.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "client_cli/inspection_client.h"
#include "server/storage/artifact_files.h"
#include "server/app/inspection_server.h"
#include "tests/server/test_rig.h"

namespace inspection::testing {

namespace v1 = ::inspection::v1;

// The folders UniqueTempDir made since the last RemoveUniqueTempDirs (ServerTest's TearDown
// removes them, so a test's extracted stacks and outputs do not pile up in /tmp).
inline std::vector<std::filesystem::path>& UniqueTempDirsMade() {
  static std::vector<std::filesystem::path> dirs;
  return dirs;
}

inline std::filesystem::path UniqueTempDir(const std::string& tag) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::filesystem::path p = std::filesystem::temp_directory_path() /
                            ("inspect_" + tag + "_" + std::to_string(::getpid()) + "_" +
                             (info ? std::string(info->test_suite_name()) + "_" + info->name() : std::string("x")));
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  UniqueTempDirsMade().push_back(p);
  return p;
}

inline void RemoveUniqueTempDirs() {
  std::error_code ec;
  for (const auto& p : UniqueTempDirsMade()) std::filesystem::remove_all(p, ec);
  UniqueTempDirsMade().clear();
}

// A stored scan's stack folder as a user would upload it: the server keeps the stack only as the
// scan's stack.zip artifact (artifacts/<scan id>/stack.zip), so this extracts that into `dest`.
inline std::filesystem::path ExtractStoredStack(const std::filesystem::path& data_dir, const std::string& scan_id,
                                                const std::filesystem::path& dest) {
  const Status s = UnzipToFolder(data_dir / "artifacts" / scan_id / "stack.zip", dest);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return dest;
}

// The integral SFF tests' rig (tests/server/procedures/isff_rig_test.cc): 256 x 192 camera, a projector
// that lights the whole field, seed 5; SKEW5.
inline SimulatedRigOptions IsffRig() {
  SimulatedRigOptions o;
  o.specimen = "skew5";
  o.seed = 5;
  o.camera_size = {256, 192};
  o.projector_size = {72, 92};
  return o;
}

class ServerTest : public ::testing::Test {
 protected:
  void SetUp() override { data_dir_ = UniqueTempDir("data"); }
  void TearDown() override {
    if (control_) control_->Release();  // never leave a held capture behind
    client_.reset();
    server_.reset();
    RemoveUniqueTempDirs();  // data_dir_ among them
  }

  // Small camera: physics identical to the default, frames fast to render.
  virtual SimulatedRigOptions SimOptions() {
    SimulatedRigOptions o;
    o.specimen = "skew5";
    o.seed = 7;
    o.camera_size = {320, 240};
    return o;
  }

  void StartServer(int queue_capacity = 4) {
    ServerOptions opt;
    opt.listen_address = "127.0.0.1:0";
    opt.data_dir = data_dir_;
    opt.rig_queue_capacity = queue_capacity;
    opt.simulation = SimOptions();
    opt.reconstruct = pipeline_;
    if (!control_) control_ = std::make_shared<RigControl>();
    auto sim = CreateSimulatedRig(opt.simulation);
    ASSERT_TRUE(sim.ok()) << sim.status().ToString();
    auto server = InspectionServer::Start(opt, std::make_unique<ControlledRig>(std::move(*sim), control_));
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    client_ = NewClient();
  }

  void StopServer() {
    client_.reset();
    server_.reset();
  }

  std::unique_ptr<client::InspectionClient> NewClient() {
    client::ClientOptions co;
    co.target = server_->address();
    auto c = std::make_unique<client::InspectionClient>(co);
    EXPECT_TRUE(c->WaitConnected().ok());
    return c;
  }

  std::filesystem::path data_dir_;
  ReconstructPipelineOptions pipeline_;  // for the next StartServer
  std::shared_ptr<RigControl> control_;
  std::unique_ptr<InspectionServer> server_;
  std::unique_ptr<client::InspectionClient> client_;
};

}  // namespace inspection::testing
