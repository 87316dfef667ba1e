// Rig configuration: parsing with key-naming errors, the simulated default, real-driver configs,
// and CreateRig's start-up policy for absent devices (fail, or start degraded and say why).
#include "devices/rig_config.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

namespace inspection {
namespace {
namespace fs = std::filesystem;
using ::testing::HasSubstr;

// A real rig whose camera and stage are absent here, and whose projector is a file stand-in.
std::string RealConfig(const std::string& fb_path) {
  return R"({
    "name": "bench-1",
    "pixel_size_um": 0.74,
    "camera": {"driver": "aravis", "device_id": "Aravis-Fake-ABSENT42", "pixel_format": "Mono12",
               "exposure_us": 8000, "gain_db": 2.5, "frame_timeout_ms": 1500,
               "region": {"x": 16, "y": 8, "width": 1280, "height": 960}},
    "stage": {"driver": "apt-usb", "serial": "27999999", "stage_type": "MTS25-Z8",
              "min_z_um": 100, "max_z_um": 20000, "move_timeout_ms": 5000, "settle_ms": 30,
              "vendor_id": "0x0403", "product_id": "0xfaf0"},
    "projector": {"driver": "framebuffer", "device": ")" +
         fb_path + R"(",
                  "mode": {"width": 8, "height": 4, "bits_per_pixel": 16},
                  "region": {"x": 2, "y": 0, "width": 4, "height": 4}, "flip_horizontal": true},
    "scan_defaults": {"z_start_um": 200, "z_end_um": 400, "z_step_um": 2.5, "focus_search_step_um": 12}
  })";
}

Status ParseError(const std::string& text) {
  StatusOr<RigConfig> c = ParseRigConfig(text);
  return c.ok() ? Status::Ok() : c.status();
}

TEST(RigConfigTest, EmptyConfigIsTheDefaultSimulatedRig) {
  StatusOr<RigConfig> c = ParseRigConfig("{}");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_TRUE(c->simulated);
  EXPECT_EQ(c->simulation.specimen, "skew5");
  EXPECT_EQ(c->simulation.camera_size, cv::Size(1024, 768));
}

TEST(RigConfigTest, SimulatedOptions) {
  StatusOr<RigConfig> c = ParseRigConfig(R"({"camera": {"driver": "simulated"}, "stage": {"driver": "simulated"},
      "projector": {"driver": "simulated"},
      "simulation": {"specimen": "wedge", "seed": 7, "camera_width": 320, "camera_height": 240,
                     "camera_bit_depth": 12, "shot_noise": false}})");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_TRUE(c->simulated);
  EXPECT_EQ(c->simulation.specimen, "wedge");
  EXPECT_EQ(c->simulation.seed, 7u);
  EXPECT_EQ(c->simulation.camera_size, cv::Size(320, 240));
  EXPECT_EQ(c->simulation.camera_bit_depth, 12);
  EXPECT_FALSE(c->simulation.shot_noise);
}

TEST(RigConfigTest, CreateRigBuildsTheSimulatedRig) {
  StatusOr<RigConfig> c = ParseRigConfig(R"({"simulation": {"camera_width": 64, "camera_height": 48}})");
  ASSERT_TRUE(c.ok());
  StatusOr<std::unique_ptr<Rig>> rig = CreateRig(*c, {});
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  EXPECT_NE((*rig)->simulation(), nullptr);
  EXPECT_EQ((*rig)->camera().frame_size(), cv::Size(64, 48));
  EXPECT_TRUE((*rig)->CheckDevices().ok());
}

TEST(RigConfigTest, RealDriverConfigIsParsed) {
  StatusOr<RigConfig> c = ParseRigConfig(RealConfig("/tmp/fb-stand-in"));
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_FALSE(c->simulated);
  EXPECT_EQ(c->name, "bench-1");
  EXPECT_DOUBLE_EQ(c->pixel_size_um, 0.74);
  EXPECT_EQ(c->camera.device_id, "Aravis-Fake-ABSENT42");
  EXPECT_EQ(c->camera.pixel_format, "Mono12");
  EXPECT_DOUBLE_EQ(c->camera.gain_db, 2.5);
  EXPECT_EQ(c->camera.region_width, 1280);
  EXPECT_EQ(c->stage.stage_type, "MTS25-Z8");
  EXPECT_DOUBLE_EQ(c->stage.min_z_um, 100.0);
  EXPECT_DOUBLE_EQ(c->stage.settle_ms, 30.0);
  EXPECT_EQ(c->stage_usb.serial, "27999999");
  EXPECT_EQ(c->stage_usb.vendor_id, 0x0403);
  EXPECT_EQ(c->stage_usb.product_id, 0xFAF0);
  ASSERT_TRUE(c->projector.mode.has_value());
  EXPECT_EQ(c->projector.mode->bits_per_pixel, 16);
  EXPECT_EQ(c->projector.mode->red.offset, 11);  // RGB565 unless stated
  EXPECT_TRUE(c->projector.flip_horizontal);
  EXPECT_DOUBLE_EQ(c->scan_defaults.z_step_um, 2.5);
  EXPECT_DOUBLE_EQ(c->scan_defaults.exposure_us, 8000.0);  // from the camera unless stated
  EXPECT_DOUBLE_EQ(c->scan_defaults.focus_search_step_um, 12.0);
}

TEST(RigConfigTest, ErrorsNameTheKey) {
  const std::string base = R"("pixel_size_um": 1, "stage": {"driver": "apt-usb"}, "projector": {"driver": "none"})";
  EXPECT_EQ(ParseError(R"({"camera": {"driver": "aravis", "exposure_us": -5}, )" + base + "}").message(),
            "rig config: camera.exposure_us must be > 0");
  EXPECT_EQ(ParseError(R"({"camera": {"driver": "aravis", "exposure": 5}, )" + base + "}").message(),
            "rig config: camera.exposure is not a known key");
  EXPECT_EQ(ParseError(R"({"camera": {"driver": "aravis", "exposure_us": "fast"}, )" + base + "}").message(),
            "rig config: camera.exposure_us must be a number");
  EXPECT_THAT(ParseError(R"({"camera": {"driver": "aravis", "pixel_format": "RGB8"}, )" + base + "}").message(),
              HasSubstr("camera.pixel_format"));
  EXPECT_THAT(ParseError(R"({"camera": {"driver": "gige"}})").message(), HasSubstr("camera.driver 'gige' is unknown"));
  EXPECT_THAT(
      ParseError(R"({"camera": {"driver": "aravis"}, "stage": {"driver": "apt-usb"}, "projector": {"driver": "none"}})")
          .message(),
      HasSubstr("pixel_size_um is required"));
  EXPECT_THAT(ParseError(R"({"camera": {"driver": "aravis"}})").message(), HasSubstr("mixing simulated and real"));
  EXPECT_THAT(ParseError(R"({"camera": {"driver": "aravis"}, "pixel_size_um": 1, "stage": {"driver": "apt-usb",
      "stage_type": "Z806", "max_z_um": 9000}, "projector": {"driver": "none"}})")
                  .message(),
              HasSubstr("stage.max_z_um must be <= the Z806 travel (6000 µm)"));
  EXPECT_THAT(ParseError(R"({"camera": {"driver": "aravis"}, "pixel_size_um": 1, "stage": {"driver": "apt-usb",
      "vendor_id": "FTDI"}, "projector": {"driver": "none"}})")
                  .message(),
              HasSubstr("stage.vendor_id"));
  EXPECT_THAT(ParseError(R"({"camera": {"driver": "aravis"}, "pixel_size_um": 1, "stage": {"driver": "apt-usb"},
      "projector": {"driver": "framebuffer", "mode": {"width": 8, "height": 4, "bits_per_pixel": 12}}})")
                  .message(),
              HasSubstr("projector.mode.bits_per_pixel"));
  EXPECT_THAT(ParseError(R"({"simulation": {"camera_bit_depth": 10}})").message(),
              HasSubstr("simulation.camera_bit_depth must be 8 or 12"));
  EXPECT_THAT(ParseError(R"({"simulation": {"specimen": "skew5"}, "cameras": {}})").message(),
              HasSubstr("rig config: cameras is not a known key"));
  EXPECT_EQ(ParseError(R"({"camera": {"driver": "aravis"}, )" + base +
                       R"(, "scan_defaults": {"focus_search_step_um": -1}})")
                .message(),
            "rig config: scan_defaults.focus_search_step_um must be >= 0 (0: 4 z steps)");
  EXPECT_THAT(ParseError("{ not json").message(), HasSubstr("not valid JSON"));
  EXPECT_EQ(ParseError("[1, 2]").code(), StatusCode::kInvalidArgument);
}

TEST(RigConfigTest, LoadRigConfigNamesTheFile) {
  EXPECT_EQ(LoadRigConfig("/nonexistent/rig.json").status().code(), StatusCode::kNotFound);
  const fs::path path = fs::temp_directory_path() / ("rig_config_test_" + std::to_string(::getpid()) + ".json");
  std::ofstream(path) << R"({"simulation": {"seed": -1}})";
  StatusOr<RigConfig> c = LoadRigConfig(path);
  fs::remove(path);
  EXPECT_EQ(c.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(c.status().message(), HasSubstr(path.string()));
  EXPECT_THAT(c.status().message(), HasSubstr("simulation.seed"));
}

#if INSPECT_HAVE_DRIVERS
class RealRigTest : public ::testing::Test {
 protected:
  void SetUp() override {
    fb_ = fs::temp_directory_path() / ("rig_config_fb_" + std::to_string(::getpid()));
    std::ofstream(fb_).close();
  }
  void TearDown() override { fs::remove(fb_); }
  fs::path fb_;
};

TEST_F(RealRigTest, AbsentDevicesStopStartUpNamingThem) {
  StatusOr<RigConfig> c = ParseRigConfig(RealConfig(fb_.string()));
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  StatusOr<std::unique_ptr<Rig>> rig = CreateRig(*c, RigStartOptions{});
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(rig.status().message(), HasSubstr("bench-1"));
  EXPECT_THAT(rig.status().message(), HasSubstr("Aravis-Fake-ABSENT42"));
  EXPECT_THAT(rig.status().message(), HasSubstr("27999999"));
  EXPECT_THAT(rig.status().message(), HasSubstr("degraded"));
}

TEST_F(RealRigTest, DegradedStartReportsWhyAndRefusesOperations) {
  StatusOr<RigConfig> c = ParseRigConfig(RealConfig(fb_.string()));
  ASSERT_TRUE(c.ok());
  StatusOr<std::unique_ptr<Rig>> rig = CreateRig(*c, RigStartOptions{.allow_degraded = true});
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  Rig& r = **rig;
  EXPECT_EQ(r.simulation(), nullptr);
  EXPECT_DOUBLE_EQ(r.pixel_size_um(), 0.74);
  EXPECT_DOUBLE_EQ(r.scan_defaults().z_start_um, 200.0);
  Status check = r.CheckDevices();
  EXPECT_EQ(check.code(), StatusCode::kUnavailable);
  EXPECT_THAT(check.message(), HasSubstr("camera (aravis"));
  EXPECT_FALSE(r.camera().info().connected);
  EXPECT_FALSE(r.stage().info().connected);
  EXPECT_THAT(r.stage().info().detail, HasSubstr("0403:faf0"));
  EXPECT_EQ(r.camera().Capture().status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(r.stage().MoveTo(300.0).code(), StatusCode::kUnavailable);
  EXPECT_EQ(r.stage().MoveTo(50.0).code(), StatusCode::kOutOfRange);  // below min_z_um 100
  // The projector stand-in is there: 4x4 region, RGB565, mirrored.
  EXPECT_TRUE(r.projector().info().connected);
  EXPECT_EQ(r.projector().resolution(), cv::Size(4, 4));
  EXPECT_TRUE(r.projector().ShowUniform(255).ok());
  Status reset = r.Reset();
  EXPECT_EQ(reset.code(), StatusCode::kUnavailable);
  EXPECT_THAT(reset.message(), HasSubstr("27999999"));
}

TEST_F(RealRigTest, ProjectorNoneAcceptsOnlyUniformPatterns) {
  std::string text = RealConfig(fb_.string());
  const size_t from = text.find("\"projector\"");
  const size_t to = text.find("\"scan_defaults\"");
  text.replace(from, to - from, R"("projector": {"driver": "none", "width": 8, "height": 6}, )");
  StatusOr<RigConfig> c = ParseRigConfig(text);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  StatusOr<std::unique_ptr<Rig>> rig = CreateRig(*c, RigStartOptions{.allow_degraded = true});
  ASSERT_TRUE(rig.ok());
  Projector& p = (*rig)->projector();
  EXPECT_EQ(p.info().driver, "none");
  EXPECT_EQ(p.resolution(), cv::Size(8, 6));
  EXPECT_TRUE(p.ShowUniform(128).ok());
  cv::Mat stripes(6, 8, CV_8UC1, cv::Scalar(0));
  stripes.col(3).setTo(255);
  EXPECT_EQ(p.Show(stripes).code(), StatusCode::kFailedPrecondition);
}
#endif

}  // namespace
}  // namespace inspection

namespace inspection {
namespace {

// Found by fuzz_rig_config (tests/fuzz/regressions/fuzz_rig_config/): a number that overflows a
// double made nlohmann throw out_of_range, which ParseRigConfig did not catch (terminate).
TEST(RigConfigRegressionTest, NumberOverflowIsInvalidArgumentNotACrash) {
  StatusOr<RigConfig> c = ParseRigConfig(R"({"m": 0.755545555555e55555555 "x"})");
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(c.status().message(),
            "rig config: not valid JSON: [json.exception.out_of_range.406] number overflow parsing "
            "'0.755545555555e55555555'");
}

}  // namespace
}  // namespace inspection
