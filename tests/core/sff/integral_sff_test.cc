// Integral SFF (thesis 5.4, 6.4): the integral image accumulated frame by frame, the noise
// estimate, the noise-adaptive IPSF restoration (eq. 5.23) against the plain one, and ISFF /
// ISFF-GT / ISFF-FAST end to end on a synthetic tilted stack, with the precondition errors.
#include "core/sff/integral_sff.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/metrology/depth_metrics.h"
#include "core/io/stack.h"
#include "core/io/stack_frame_decoder.h"

namespace inspection {
namespace {

cv::Mat Noise(cv::Size size, double sigma, uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat n(size, CV_32FC1);
  rng.fill(n, cv::RNG::NORMAL, 0.0, sigma);
  return n;
}

TEST(IntegralSffTest, AccumulatorIsTheMeanOfTheFrames) {
  IntegralImageAccumulator acc;
  EXPECT_EQ(acc.IntegralImage().status().code(), StatusCode::kFailedPrecondition);
  cv::Mat a(4, 5, CV_8UC1, cv::Scalar(10)), b(4, 5, CV_8UC1, cv::Scalar(30)), c(4, 5, CV_8UC1, cv::Scalar(200));
  c.at<uint8_t>(2, 3) = 0;
  ASSERT_TRUE(acc.Add(a).ok());
  ASSERT_TRUE(acc.Add(b).ok());
  ASSERT_TRUE(acc.Add(c).ok());
  auto m = acc.IntegralImage();
  ASSERT_TRUE(m.ok());
  EXPECT_FLOAT_EQ(m->at<float>(0, 0), 80.0f);
  EXPECT_FLOAT_EQ(m->at<float>(2, 3), 40.0f / 3.0f);
  const Status bad = acc.Add(cv::Mat(4, 6, CV_8UC1));
  EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.message().find("frame 3"), std::string::npos);
}

TEST(IntegralSffTest, NoiseEstimateIgnoresSmoothContent) {
  const cv::Size size(160, 120);
  // A smooth ramp plus a wide blob: the mask cancels both, only the noise remains.
  cv::Mat base(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      base.at<float>(y, x) =
          float(60 + 0.5 * x + 0.3 * y + 40 * std::exp(-((x - 80) * (x - 80) + (y - 60) * (y - 60)) / 800.0));
  for (double sigma : {0.5, 2.0, 5.0}) {
    const cv::Mat f = base + Noise(size, sigma, 3);
    EXPECT_NEAR(EstimateFrameNoiseSigma(f), sigma, 0.06 * sigma) << sigma;
    // 8-bit quantisation: the interpolated median keeps the estimate continuous.
    cv::Mat f8;
    f.convertTo(f8, CV_8U);
    const double expected = std::sqrt(sigma * sigma + 1.0 / 12.0);
    EXPECT_NEAR(EstimateFrameNoiseSigma(f8), expected, 0.1 * expected) << sigma;
  }
}

// A textured plane tilted through a stack of Gaussian-blurred frames (focus sigma grows by
// 0.2 px per um of |z - h(x)|, about the simulated rig's 0.21), in float grey values 0..255.
struct Synthetic {
  cv::Mat texture, truth_um;
  std::vector<cv::Mat> frames_f;
  std::vector<double> z;
};

Synthetic MakeSynthetic(cv::Size size, int n, double noise, uint64_t seed, double slope = 0.25) {
  Synthetic s;
  cv::RNG rng(seed);
  cv::Mat t(size, CV_32FC1);
  rng.fill(t, cv::RNG::UNIFORM, 40.0, 210.0);
  cv::GaussianBlur(t, s.texture, {0, 0}, 0.9);
  s.truth_um.create(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) s.truth_um.at<float>(y, x) = float(20.0 + slope * x);
  // Blurs at 0.25 px steps of sigma; each pixel takes the one of its own defocus.
  std::vector<cv::Mat> ladder;
  for (int i = 0; i <= 60; ++i) {
    cv::Mat b;
    const double sg = 0.25 * i;
    if (sg < 0.3)
      b = s.texture.clone();
    else
      cv::GaussianBlur(s.texture, b, {0, 0}, sg, sg, cv::BORDER_REFLECT_101);
    ladder.push_back(b);
  }
  for (int k = 0; k < n; ++k) {
    const double z = 5.0 * k;
    s.z.push_back(z);
    cv::Mat f(size, CV_32FC1);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const double sg = 0.2 * std::abs(z - s.truth_um.at<float>(y, x));
        const int i = std::min(60, int(std::lround(sg / 0.25)));
        f.at<float>(y, x) = ladder[i].at<float>(y, x);
      }
    if (noise > 0) f += Noise(size, noise, seed * 100 + k);
    s.frames_f.push_back(f);
  }
  return s;
}

std::vector<cv::Mat> To8U(const std::vector<cv::Mat>& f) {
  std::vector<cv::Mat> out;
  for (const cv::Mat& m : f) {
    cv::Mat o;
    m.convertTo(o, CV_8U);
    out.push_back(o);
  }
  return out;
}

double Rms(const cv::Mat& a, const cv::Mat& b, int border) {
  const cv::Rect r(border, border, a.cols - 2 * border, a.rows - 2 * border);
  return std::sqrt(cv::norm(a(r), b(r), cv::NORM_L2SQR) / r.area());
}

IntegralPsf Calibrate(const Synthetic& s, IpsfRegularisation reg, int radius_px, double weight) {
  auto integral = IntegralImage(s.frames_f);
  EXPECT_TRUE(integral.ok());
  IntegralPsfOptions o;
  o.radius_px = radius_px;
  o.regularisation = reg;
  o.regularisation_weight = weight;
  o.tv_reweight_iterations = 3;
  auto k = EstimateIntegralPsf(*integral, s.texture, o);
  EXPECT_TRUE(k.ok()) << k.status().ToString();
  return *k;
}

IntegralPsf Calibrate(const Synthetic& s) { return Calibrate(s, IpsfRegularisation::kTotalVariationL1, 6, 1e-4); }

// A plane normal to the axis (one integral PSF for the whole image, as the IPSF assumes), in the
// middle of 9 frames; a nearly unregularised kernel, so eq. 5.23 alone amplifies the noise.
TEST(IntegralSffTest, NoiseAdaptiveRestorationBeatsPlainUnderNoise) {
  const Synthetic clean = MakeSynthetic({96, 80}, 9, 0.0, 11, 0.0);
  IntegralPsf ipsf = Calibrate(clean, IpsfRegularisation::kGradientL2, 8, 1e-6);
  auto restore = [&](const Synthetic& s, IpsfRestoration method, double* noise_estimate) {
    IntegralImageAccumulator acc;
    for (const cv::Mat& f : s.frames_f) EXPECT_TRUE(acc.Add(f).ok());
    auto integral = acc.IntegralImage();
    EXPECT_TRUE(integral.ok());
    *noise_estimate = acc.FrameNoiseSigma();
    IpsfRestorationOptions o;
    o.method = method;
    auto r = RestoreFocusedImage(*integral, acc.frame_count(), acc.FrameNoiseSigma(), ipsf, o);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return *r;
  };
  double est = 0;
  {
    const Synthetic s = MakeSynthetic({96, 80}, 9, 0.0, 12, 0.0);
    auto integral = IntegralImage(s.frames_f);
    const cv::Mat plain = restore(s, IpsfRestoration::kPlain, &est);
    EXPECT_LT(Rms(plain, s.texture, 8), 0.2 * Rms(*integral, s.texture, 8));  // eq. 5.23 restores
    // Without noise the adaptive restoration is eq. 5.23 exactly.
    EXPECT_LT(cv::norm(restore(s, IpsfRestoration::kNoiseAdaptive, &est), plain, cv::NORM_INF), 0.05);
    EXPECT_LT(est, 0.05);
  }
  const Synthetic noisy = MakeSynthetic({96, 80}, 9, 4.0, 12, 0.0);
  const double e_plain = Rms(restore(noisy, IpsfRestoration::kPlain, &est), noisy.texture, 8);
  EXPECT_NEAR(est, 4.0, 0.3);
  const double e_adapt = Rms(restore(noisy, IpsfRestoration::kNoiseAdaptive, &est), noisy.texture, 8);
  EXPECT_LT(e_adapt, 0.85 * e_plain) << "plain " << e_plain << " adaptive " << e_adapt;
  // A kernel calibrated at this noise has damped it already: nothing more is taken away.
  ipsf.integral_noise_sigma = est / 3.0;  // frame noise / sqrt(9 frames)
  EXPECT_EQ(cv::norm(restore(noisy, IpsfRestoration::kNoiseAdaptive, &est),
                     restore(noisy, IpsfRestoration::kPlain, &est), cv::NORM_INF),
            0.0);
}

TEST(IntegralSffTest, IsffFollowsTheTiltedPlaneAndFastSkipsWork) {
  const Synthetic cal = MakeSynthetic({128, 64}, 16, 0.0, 21, 0.0);
  const IntegralPsf ipsf = Calibrate(cal, IpsfRegularisation::kGradientL2, 8, 1e-6);
  const Synthetic s = MakeSynthetic({128, 64}, 16, 1.0, 22);
  const std::vector<cv::Mat> frames = To8U(s.frames_f);
  IsffOptions o;
  auto isff = ReconstructIntegralSff(frames, s.z, &ipsf, o);
  ASSERT_TRUE(isff.ok()) << isff.status().ToString();
  auto gt = ReconstructIntegralSffWithTemplate(frames, s.z, s.texture, o);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  const DepthErrorStats e_isff = CompareDepth(isff->depth.depth_um, s.truth_um, 10.0, 8);
  const DepthErrorStats e_gt = CompareDepth(gt->depth.depth_um, s.truth_um, 10.0, 8);
  EXPECT_GT(e_isff.valid_percent, 95.0);
  EXPECT_LT(e_isff.rmse_um, 1.0);  // a fifth of the 5 um step
  EXPECT_LT(e_gt.rmse_um, 1.0);
  EXPECT_NEAR(isff->frame_noise_sigma, std::sqrt(1.0 + 1.0 / 12.0), 0.3);
  EXPECT_EQ(isff->focused_template.size(), frames[0].size());

  IsffOptions fast = o;
  fast.ncc.stop_at_first_maximum = true;
  auto f = ReconstructIntegralSff(frames, s.z, &ipsf, fast);
  ASSERT_TRUE(f.ok());
  // The plane rises through the stack: the pixels stop one frame after their focus, so about
  // half of the stack's tile-frames are never computed.
  EXPECT_LT(double(f->work.computed_pixel_frames), 0.75 * double(f->work.computed_pixel_frames_full));
  const double wrong = 100.0 * cv::countNonZero(f->max_index != isff->max_index) / double(frames[0].total());
  EXPECT_LT(wrong, 2.0);
  const DepthErrorStats e_fast = CompareDepth(f->depth.depth_um, s.truth_um, 10.0, 8);
  EXPECT_LT(e_fast.stddev_error_um, 1.1 * e_isff.stddev_error_um + 0.02);
}

TEST(IntegralSffTest, StackFolderTwoPassesMatchInMemory) {
  const Synthetic cal = MakeSynthetic({64, 48}, 8, 0.0, 31);
  const IntegralPsf ipsf = Calibrate(cal);
  const Synthetic s = MakeSynthetic({64, 48}, 8, 1.0, 32);
  const std::vector<cv::Mat> frames = To8U(s.frames_f);
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("isff_stack_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  StackManifest m;
  m.pixel_size_um = 0.74;
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string name = "frame_" + std::to_string(i) + ".png";
    ASSERT_TRUE(cv::imwrite((dir / name).string(), frames[i]));
    m.frames.push_back({name, s.z[i], 0.0, ""});
  }
  ASSERT_TRUE(WriteStackManifest(dir, m).ok());
  auto a = ReconstructIntegralSffStack(dir, &ipsf, {});
  auto b = ReconstructIntegralSff(frames, s.z, &ipsf, {});
  // From a decoder that keeps nothing (budget 0): every frame decoded again for each pass.
  StackFrameDecoderOptions none;
  none.max_kept_bytes = 0;
  StackFrameDecoder decoder(dir, m, none);
  ASSERT_TRUE(decoder.Finish().ok());
  const StackFrameSource source{[&](int i) { return decoder.Frame(i); }, [&](int i) { decoder.Release(i); }, {}};
  auto c = ReconstructIntegralSffFrames(m, source, &ipsf, {});
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok());
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(decoder.decoded_frames(), 3 * int(frames.size()));  // the check, pass 1, pass 2
  EXPECT_EQ(cv::norm(a->focused_template, c->focused_template, cv::NORM_INF), 0.0);
  EXPECT_EQ(0, std::memcmp(a->depth.depth_um.data, c->depth.depth_um.data, a->depth.depth_um.total() * sizeof(float)));
  EXPECT_EQ(cv::norm(a->depth.depth_um == a->depth.depth_um, b->depth.depth_um == b->depth.depth_um, cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(a->focused_template, b->focused_template, cv::NORM_INF), 0.0);
  cv::Mat da = a->depth.depth_um.clone(), db = b->depth.depth_um.clone();
  cv::patchNaNs(da, 0);
  cv::patchNaNs(db, 0);
  EXPECT_EQ(cv::norm(da, db, cv::NORM_INF), 0.0);
}

TEST(IntegralSffTest, PreconditionsAndBadInputAreNamed) {
  const Synthetic s = MakeSynthetic({32, 32}, 4, 0.0, 41);
  const std::vector<cv::Mat> frames = To8U(s.frames_f);
  IsffOptions o;
  auto no_ipsf = ReconstructIntegralSff(frames, s.z, nullptr, o);
  EXPECT_EQ(no_ipsf.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(no_ipsf.status().message().find("integral_psf"), std::string::npos);
  EXPECT_EQ(ReconstructIntegralSffStack("/nonexistent", nullptr, o).status().code(), StatusCode::kFailedPrecondition);
  CalibrationBundle without;
  EXPECT_EQ(CheckIntegralPsfFor(&without).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(CheckIntegralPsfFor(nullptr).code(), StatusCode::kFailedPrecondition);
  CalibrationBundle with;
  with.integral_psf = IntegralPsf{};
  with.integral_psf->kernel = cv::Mat::zeros(3, 3, CV_32FC1);
  with.integral_psf->kernel.at<float>(1, 1) = 1.f;
  EXPECT_TRUE(CheckIntegralPsfFor(&with).ok());

  o.ncc.stop_at_first_maximum = true;
  o.ncc.stop_threshold = 1.2;
  auto bad = ReconstructIntegralSff(frames, s.z, &*with.integral_psf, o);
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("fast_threshold"), std::string::npos);
  o = {};
  auto short_z = ReconstructIntegralSff(frames, {0.0, 1.0}, &*with.integral_psf, o);
  EXPECT_EQ(short_z.status().code(), StatusCode::kInvalidArgument);
  auto bad_template = ReconstructIntegralSffWithTemplate(frames, s.z, cv::Mat(8, 8, CV_32FC1), o);
  EXPECT_EQ(bad_template.status().code(), StatusCode::kInvalidArgument);
  o.restoration.frame_noise_sigma = -1;
  EXPECT_NE(o.Validate().message().find("restoration.frame_noise_sigma"), std::string::npos);
}

}  // namespace
}  // namespace inspection
