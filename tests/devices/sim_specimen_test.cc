// Specimen library and rig-level behaviour of the simulated rig: built-in geometry (ground
// truth), user scenes from scene.json with errors naming the key, specimen switching,
// determinism, stage repeatability and option validation.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <thread>

#include "devices/sim/simulated_rig.h"
#include "devices/sim/specimen.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

constexpr double kDeg = CV_PI / 180.0;
const SpecimenGrid kGrid{{256, 192}, 0.74, 1};

std::pair<double, double> Range(const cv::Mat& m) {
  double lo, hi;
  cv::minMaxLoc(m, &lo, &hi);
  return {lo, hi};
}

TEST(SpecimenTest, EveryBuiltinHasConsistentMaps) {
  for (const std::string& name : BuiltinSpecimenNames()) {
    auto s = MakeSpecimen(name, kGrid);
    ASSERT_TRUE(s.ok()) << name << ": " << s.status().ToString();
    EXPECT_EQ(s->name, name);
    for (const cv::Mat* m : {&s->height_um, &s->reflectance, &s->texture}) {
      EXPECT_EQ(m->type(), CV_32FC1) << name;
      EXPECT_EQ(m->size(), kGrid.camera_size) << name;
      EXPECT_TRUE(cv::checkRange(*m)) << name;
    }
    EXPECT_GE(Range(s->reflectance).first, 0.0) << name;
    EXPECT_GT(Range(s->texture).first, 0.0) << name;
    EXPECT_GE(Range(s->height_um).first, 200.0 - 1e-3) << name;
  }
}

TEST(SpecimenTest, BuiltinHeightsFollowTheirGeometry) {
  const double w = 256 * 0.74;
  // Tilted planes: the height range is the field width times tan(tilt).
  for (const auto& [name, deg] :
       std::vector<std::pair<std::string, double>>{{"plane", 0}, {"skew5", 5}, {"skew10", 10}}) {
    auto s = MakeSpecimen(name, kGrid);
    ASSERT_TRUE(s.ok());
    const auto r = Range(s->height_um);
    EXPECT_NEAR(r.second - r.first, 255 * 0.74 * std::tan(deg * kDeg), 1e-3) << name;
    // Along a row, each pixel rises by pixel size * tan(tilt).
    EXPECT_NEAR(s->height_um.at<float>(10, 101) - s->height_um.at<float>(10, 100), 0.74 * std::tan(deg * kDeg), 1e-4);
  }
  auto step = MakeSpecimen("step1um", kGrid);
  ASSERT_TRUE(step.ok());
  EXPECT_FLOAT_EQ(step->height_um.at<float>(50, 200) - step->height_um.at<float>(50, 50), 1.0f);
  // Wedge: a 120 degree ridge, both flanks at 30 degrees.
  auto wedge = MakeSpecimen("wedge", kGrid);
  ASSERT_TRUE(wedge.ok());
  EXPECT_NEAR((wedge->height_um.at<float>(5, 30) - wedge->height_um.at<float>(5, 20)) / (10 * 0.74),
              std::tan(30 * kDeg), 1e-3);
  EXPECT_NEAR((wedge->height_um.at<float>(5, 220) - wedge->height_um.at<float>(5, 230)) / (10 * 0.74),
              std::tan(30 * kDeg), 1e-3);
  // Chamfer: P2 falls at 60 degrees between the flat P1 and P3.
  auto chamfer = MakeSpecimen("chamfer", kGrid);
  ASSERT_TRUE(chamfer.ok());
  EXPECT_NEAR((chamfer->height_um.at<float>(5, 124) - chamfer->height_um.at<float>(5, 132)) / (8 * 0.74),
              std::tan(60 * kDeg), 1e-3);
  EXPECT_FLOAT_EQ(chamfer->height_um.at<float>(5, 10), chamfer->height_um.at<float>(5, 80));
  EXPECT_NEAR(Range(chamfer->height_um).second - 200.0, 0.1 * w * std::tan(60 * kDeg), 1e-3);
  // Lens: a cylinder of radius 3 field widths, apex at the centre.
  auto lens = MakeSpecimen("lens", kGrid);
  ASSERT_TRUE(lens.ok());
  const double rc = 3 * w, x = 100 * 0.74;
  EXPECT_NEAR(lens->height_um.at<float>(7, 128 + 100) - lens->height_um.at<float>(7, 128),
              std::sqrt(rc * rc - (x + 0.37) * (x + 0.37)) - std::sqrt(rc * rc - 0.37 * 0.37), 1e-3);
}

TEST(SpecimenTest, CutterAndCoinHaveAHighDynamicRange) {
  for (const std::string name : {"cutter", "coin"}) {
    auto s = MakeSpecimen(name, kGrid);
    ASSERT_TRUE(s.ok());
    cv::Mat r = s->reflectance.reshape(1, 1).clone();
    cv::sort(r, r, cv::SORT_ASCENDING);
    const float p10 = r.at<float>(0, r.cols / 10), p95 = r.at<float>(0, r.cols * 95 / 100);
    EXPECT_GT(p95 / p10, 10.0f) << name;
  }
}

TEST(SpecimenTest, UnknownNameListsBuiltins) {
  auto s = MakeSpecimen("teapot", kGrid);
  EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
  EXPECT_NE(s.status().message().find("skew5"), std::string::npos);
}

class SceneFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("sim_scene_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    height_ = cv::Mat(48, 64, CV_16UC1);
    for (int r = 0; r < 48; ++r) {
      for (int c = 0; c < 64; ++c) height_.at<uint16_t>(r, c) = static_cast<uint16_t>(100 * c);
    }
    ASSERT_TRUE(cv::imwrite((dir_ / "height.png").string(), height_));
    cv::Mat refl(48, 64, CV_8UC1, cv::Scalar(51));
    ASSERT_TRUE(cv::imwrite((dir_ / "refl.png").string(), refl));
    cv::Mat tex(48, 64, CV_8UC1);
    cv::randu(tex, 50, 150);
    ASSERT_TRUE(cv::imwrite((dir_ / "tex.png").string(), tex));
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Write(const std::string& json) {
    const fs::path p = dir_ / "scene.json";
    std::ofstream(p) << json;
    return p.string();
  }

  fs::path dir_;
  cv::Mat height_;
};

TEST_F(SceneFileTest, LoadsHeightReflectanceAndTexture) {
  const std::string path = Write(R"({"height": "height.png", "height_scale_um": 0.01, "height_offset_um": 150,
                                     "reflectance": "refl.png", "texture": "tex.png"})");
  const SpecimenGrid grid{{64, 48}, 0.74, 1};
  auto s = MakeSpecimen("file:" + path, grid);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ(s->name, "file:" + path);
  EXPECT_FLOAT_EQ(s->height_um.at<float>(3, 0), 150.0f);
  EXPECT_FLOAT_EQ(s->height_um.at<float>(3, 63), 150.0f + 63.0f);
  EXPECT_NEAR(s->reflectance.at<float>(10, 10), 0.2, 1e-6);  // 51 / 255
  EXPECT_NEAR(cv::mean(s->texture)[0], 1.0, 1e-5);
  // Resampled to another camera size.
  auto big = MakeSpecimen("file:" + path, SpecimenGrid{{128, 96}, 0.74, 1});
  ASSERT_TRUE(big.ok());
  EXPECT_EQ(big->height_um.size(), cv::Size(128, 96));
}

TEST_F(SceneFileTest, ErrorsNameTheKey) {
  const SpecimenGrid grid{{64, 48}, 0.74, 1};
  struct Case {
    std::string json, key;
    StatusCode code;
  };
  for (const Case& c : std::vector<Case>{
           {R"({"reflectance": "refl.png"})", "'height'", StatusCode::kInvalidArgument},
           {R"({"height": "nope.png"})", "'height'", StatusCode::kNotFound},
           {R"({"height": 3})", "'height'", StatusCode::kInvalidArgument},
           {R"({"height": "height.png", "height_scale_um": "big"})", "'height_scale_um'", StatusCode::kInvalidArgument},
           {R"({"height": "height.png", "height_scale_um": -1})", "'height_scale_um'", StatusCode::kInvalidArgument},
           {R"({"height": "height.png", "reflectance": "missing.png"})", "'reflectance'", StatusCode::kNotFound},
           {R"({"height": "height.png", "texture": "scene.json"})", "'texture'", StatusCode::kInvalidArgument},
           {R"([1, 2])", "JSON object", StatusCode::kInvalidArgument},
       }) {
    auto s = MakeSpecimen("file:" + Write(c.json), grid);
    EXPECT_EQ(s.status().code(), c.code) << c.json << " -> " << s.status().ToString();
    EXPECT_NE(s.status().message().find(c.key), std::string::npos) << s.status().ToString();
  }
  EXPECT_EQ(MakeSpecimen("file:" + (dir_ / "absent.json").string(), grid).status().code(), StatusCode::kNotFound);
}

TEST_F(SceneFileTest, RigSwitchesToAUserSceneAtRunTime) {
  SimulatedRigOptions o;
  o.camera_size = {64, 48};
  auto rig = CreateSimulatedRig(o);
  ASSERT_TRUE(rig.ok());
  SimulationControl* sim = (*rig)->simulation();
  ASSERT_NE(sim, nullptr);
  EXPECT_EQ(sim->specimen(), "skew5");
  const std::string path = Write(R"({"height": "height.png", "height_scale_um": 0.01, "height_offset_um": 150})");
  ASSERT_TRUE(sim->SetSpecimen("file:" + path).ok());
  EXPECT_EQ(sim->specimen(), "file:" + path);
  EXPECT_NEAR(sim->SpecimenZRangeUm().first, 150.0, 1e-4);
  EXPECT_NEAR(sim->SpecimenZRangeUm().second, 213.0, 1e-4);
  EXPECT_FLOAT_EQ(sim->GroundTruthDepthUm().at<float>(0, 63), 213.0f);
  const ScanDefaults d = (*rig)->scan_defaults();
  EXPECT_DOUBLE_EQ(d.z_start_um, 130.0);
  EXPECT_DOUBLE_EQ(d.z_end_um, 235.0);  // 213 + 20 rounded up to the 5 um grid from 130
  // A failed switch keeps the current specimen.
  EXPECT_FALSE(sim->SetSpecimen("nothing").ok());
  EXPECT_EQ(sim->specimen(), "file:" + path);
}

TEST(SimulatedRigBehaviourTest, SeededFramesAreRepeatable) {
  SimulatedRigOptions o;
  o.camera_size = {96, 64};
  auto a = CreateSimulatedRig(o), b = CreateSimulatedRig(o);
  o.seed = 2;
  auto c = CreateSimulatedRig(o);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  for (auto* rig : {&a, &b, &c}) ASSERT_TRUE((**rig)->stage().MoveTo(210).ok());
  auto fa = (*a)->camera().Capture(), fb = (*b)->camera().Capture(), fc = (*c)->camera().Capture();
  ASSERT_TRUE(fa.ok() && fb.ok() && fc.ok());
  EXPECT_EQ(cv::countNonZero(*fa != *fb), 0);
  EXPECT_GT(cv::countNonZero(*fa != *fc), 1000);
  // The next frame has fresh noise.
  auto fa2 = (*a)->camera().Capture();
  EXPECT_GT(cv::countNonZero(*fa != *fa2), 100);
}

TEST(SimulatedRigBehaviourTest, RendererAloneReproducesTheRigsFrames) {
  SimulatedRigOptions o;
  o.camera_size = {96, 64};
  o.specimen = "cutter";
  o.stage_repeatability_um = 0.0;
  auto rig = CreateSimulatedRig(o);
  auto renderer = CreateSimulatedRenderer(o);
  ASSERT_TRUE(rig.ok() && renderer.ok());
  cv::Mat pattern(o.projector_size, CV_8UC1);
  cv::randu(pattern, 0, 256);
  ASSERT_TRUE((*rig)->projector().Show(pattern).ok());
  ASSERT_TRUE((*rig)->stage().MoveTo(230.0).ok());
  const double exposure = (*rig)->camera().exposure_us();
  for (uint64_t n = 1; n <= 2; ++n) {
    auto from_rig = (*rig)->camera().Capture();
    auto alone = (*renderer)->Render(pattern, 230.0, exposure, 0.0, SimulatedFrameNoiseSeed(o.seed, n));
    ASSERT_TRUE(from_rig.ok() && alone.ok());
    EXPECT_EQ(cv::countNonZero(*from_rig != *alone), 0) << "frame " << n;
  }
}

TEST(SimulatedRigBehaviourTest, SpecimenSwitchWhileCapturingFromAnotherThread) {
  SimulatedRigOptions o;
  o.camera_size = {64, 48};
  auto rig = CreateSimulatedRig(o);
  ASSERT_TRUE(rig.ok());
  int captured = 0;
  std::thread worker([&] {
    for (int i = 0; i < 20; ++i) {
      auto frame = (*rig)->camera().Capture();
      if (frame.ok() && frame->size() == cv::Size(64, 48)) ++captured;
    }
  });
  int switched = 0;
  for (const std::string name : {"plane", "cutter", "lens", "skew10"})
    switched += (*rig)->simulation()->SetSpecimen(name).ok();
  worker.join();
  EXPECT_EQ(captured, 20);
  EXPECT_EQ(switched, 4);
  EXPECT_EQ((*rig)->simulation()->specimen(), "skew10");
}

TEST(SimulatedRigBehaviourTest, StageRepeatabilityAndTravel) {
  SimulatedRigOptions o;
  o.camera_size = {32, 32};
  auto rig = CreateSimulatedRig(o);
  ASSERT_TRUE(rig.ok());
  Stage& stage = (*rig)->stage();
  double lo = 1e9, hi = -1e9;
  for (int i = 0; i < 200; ++i) {
    ASSERT_TRUE(stage.MoveTo(500.0).ok());
    const double z = *stage.position_um();
    lo = std::min(lo, z);
    hi = std::max(hi, z);
  }
  EXPECT_GE(lo, 499.9);
  EXPECT_LE(hi, 500.1);
  EXPECT_GT(hi - lo, 0.15);  // uniform in +-0.1: 200 draws span most of it
  EXPECT_EQ(stage.MoveTo(-1.0).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(stage.MoveTo(30000.0).code(), StatusCode::kOutOfRange);
  ASSERT_TRUE(stage.Home().ok());
  EXPECT_DOUBLE_EQ(*stage.position_um(), 0.0);
}

TEST(SimulatedRigBehaviourTest, TwelveBitCameraAndDeviceChecks) {
  SimulatedRigOptions o;
  o.camera_size = {64, 48};
  o.camera_bit_depth = 12;
  auto rig = CreateSimulatedRig(o);
  ASSERT_TRUE(rig.ok());
  EXPECT_TRUE((*rig)->CheckDevices().ok());
  EXPECT_EQ((*rig)->camera().bit_depth(), 12);
  ASSERT_TRUE((*rig)->stage().MoveTo(210).ok());
  auto frame = (*rig)->camera().Capture();
  ASSERT_TRUE(frame.ok());
  EXPECT_EQ(frame->type(), CV_16UC1);
  double lo, hi;
  cv::minMaxLoc(*frame, &lo, &hi);
  EXPECT_GT(hi, 255.0);
  EXPECT_LE(hi, 4095.0);
  EXPECT_NEAR(cv::mean(*frame)[0], 128.0 * 4095.0 / 255.0, 300.0);
  EXPECT_EQ((*rig)->projector().Show(cv::Mat(10, 10, CV_8UC1)).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*rig)->camera().SetExposure(0.0).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*rig)->pixel_size_um(), 0.74);
}

TEST(SimulatedRigBehaviourTest, InjectedFaultsReachTheCaller) {
  SimulatedRigOptions o;
  o.camera_size = {32, 32};
  auto created = CreateSimulatedRig(o);
  ASSERT_TRUE(created.ok());
  Rig& rig = **created;
  SimulatedFaults f;
  f.camera_unplugged = true;
  ASSERT_TRUE(SetSimulatedFaults(rig, f).ok());
  EXPECT_EQ(rig.camera().Capture().status().code(), StatusCode::kUnavailable);
  EXPECT_FALSE(rig.camera().info().connected);
  const Status check = rig.CheckDevices();
  EXPECT_EQ(check.code(), StatusCode::kUnavailable);
  EXPECT_NE(check.message().find("camera"), std::string::npos);
  EXPECT_EQ(rig.Reset().code(), StatusCode::kUnavailable);  // still unplugged
  // Plugged back in: Reset succeeds and frames flow again.
  ASSERT_TRUE(SetSimulatedFaults(rig, {}).ok());
  EXPECT_TRUE(rig.Reset().ok());
  EXPECT_TRUE(rig.camera().Capture().ok());
  // Two lost frames, then normal.
  f = {};
  f.camera_frame_timeouts = 2;
  f.stage_move_timeouts = 1;
  ASSERT_TRUE(SetSimulatedFaults(rig, f).ok());
  EXPECT_EQ(rig.camera().Capture().status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_EQ(rig.camera().Capture().status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_TRUE(rig.camera().Capture().ok());
  ASSERT_TRUE(rig.stage().MoveTo(100.0).code() == StatusCode::kDeadlineExceeded);
  EXPECT_NEAR(*rig.stage().position_um(), 0.0, 1e-12);  // did not move
  EXPECT_TRUE(rig.stage().MoveTo(100.0).ok());
  f = {};
  f.stage_unplugged = true;
  f.projector_unplugged = true;
  ASSERT_TRUE(SetSimulatedFaults(rig, f).ok());
  EXPECT_EQ(rig.stage().MoveTo(10.0).code(), StatusCode::kUnavailable);
  EXPECT_EQ(rig.projector().ShowUniform(10).code(), StatusCode::kUnavailable);
  f.camera_frame_timeouts = -1;
  EXPECT_EQ(SetSimulatedFaults(rig, f).code(), StatusCode::kInvalidArgument);
}

TEST(SimulatedRigOptionsTest, ValidateNamesTheField) {
  struct Case {
    std::function<void(SimulatedRigOptions&)> change;
    std::string field;
  };
  for (const Case& c : std::vector<Case>{
           {[](SimulatedRigOptions& o) { o.camera_bit_depth = 10; }, "camera_bit_depth"},
           {[](SimulatedRigOptions& o) {
              o.camera_size = {8, 8};
            },
            "camera_size"},
           {[](SimulatedRigOptions& o) {
              o.projector_size = {0, 720};
            },
            "projector_size"},
           {[](SimulatedRigOptions& o) { o.pixel_size_um = 0; }, "pixel_size_um"},
           {[](SimulatedRigOptions& o) { o.stage_repeatability_um = -1; }, "stage_repeatability_um"},
           {[](SimulatedRigOptions& o) { o.numerical_aperture = 1.2; }, "numerical_aperture"},
           {[](SimulatedRigOptions& o) { o.read_noise_dn = 100; }, "read_noise_dn"},
           {[](SimulatedRigOptions& o) { o.specimen = ""; }, "specimen"},
       }) {
    SimulatedRigOptions o;
    c.change(o);
    const Status st = o.Validate();
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << c.field;
    EXPECT_NE(st.message().find(c.field), std::string::npos) << st.ToString();
    EXPECT_EQ(CreateSimulatedRig(o).status().code(), StatusCode::kInvalidArgument);
  }
  SimulatedRigOptions o;
  o.specimen = "teapot";
  auto rig = CreateSimulatedRig(o);
  EXPECT_EQ(rig.status().code(), StatusCode::kNotFound);
  EXPECT_NE(rig.status().message().find("specimen"), std::string::npos);
}

}  // namespace
}  // namespace inspection
