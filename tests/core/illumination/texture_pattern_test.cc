// Texture patterns of thesis 5.2-5.3: period choice of eq. 5.15 with the thesis's own figures,
// checkerboard grey levels of eq. 5.16 and the modified addition of eq. 5.17-5.18 (in grey levels
// and mean-preserving for an adapted irradiance).
#include "core/illumination/texture_pattern.h"

#include <gtest/gtest.h>

namespace inspection {
namespace {

TEST(TexturePatternTest, PeriodFromThesisFigures) {
  // Thesis 5.2.1: ratio 3.4, 2 sigma_p = 8.4, window 9 -> t/2 = 10.2 (3 projector px).
  auto p = ChooseTexturePeriod(4.2, 3.4, 9);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ(p->cell_projector_px, 3);
  EXPECT_NEAR(p->half_period_camera_px, 10.2, 1e-9);
  // A 7 px window cannot hold it (t/2 must be < 9).
  auto q = ChooseTexturePeriod(4.2, 3.4, 7);
  EXPECT_EQ(q.status().code(), StatusCode::kFailedPrecondition);
  // A sharper projector allows a finer pattern: 2 sigma_p = 3 -> one projector px (3.4 > 3).
  auto r = ChooseTexturePeriod(1.5, 3.4, 7);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->cell_projector_px, 1);
  EXPECT_EQ(ChooseTexturePeriod(0, 3.4, 9).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ChooseTexturePeriod(4.2, 3.4, 8).status().code(), StatusCode::kInvalidArgument);
}

TEST(TexturePatternTest, CheckerboardGreyLevels) {
  auto hf = MakeHfPattern({12, 6}, 3, 0.2);
  ASSERT_TRUE(hf.ok());
  // Cell (0,0) is CB = 1 -> 255 * 0.2 = 51; cell (1,0) is CB = 0 -> 204.
  EXPECT_EQ(hf->at<uint8_t>(0, 0), 51);
  EXPECT_EQ(hf->at<uint8_t>(2, 2), 51);
  EXPECT_EQ(hf->at<uint8_t>(0, 3), 204);
  EXPECT_EQ(hf->at<uint8_t>(3, 0), 204);
  EXPECT_EQ(hf->at<uint8_t>(3, 3), 51);
  EXPECT_NEAR(cv::mean(*hf)[0], (51 + 204) / 2.0, 1e-9);
  auto full = MakeHfPattern({4, 4}, 1, 0.0);
  ASSERT_TRUE(full.ok());
  EXPECT_EQ(full->at<uint8_t>(0, 0), 0);
  EXPECT_EQ(full->at<uint8_t>(0, 1), 255);
  EXPECT_EQ(MakeHfPattern({4, 4}, 1, 0.6).status().code(), StatusCode::kInvalidArgument);
}

TEST(TexturePatternTest, AddedHfPatternIsClamped) {
  cv::Mat adapted(2, 4, CV_8UC1);
  adapted.at<uint8_t>(0, 0) = 100;  // CB = 1: + 0.25 * 255 = 163.75 -> 164
  adapted.at<uint8_t>(0, 1) = 100;  // CB = 0: - 63.75 -> 36
  adapted.at<uint8_t>(0, 2) = 240;  // CB = 1: clamps to 255
  adapted.at<uint8_t>(0, 3) = 30;   // CB = 0: clamps to 0
  adapted.row(1).setTo(128);
  const cv::Mat cb = CheckerboardMask(adapted.size(), 1);
  auto out = AddHfPattern(adapted, cb, 0.25);
  ASSERT_TRUE(out.ok());
  EXPECT_EQ(out->at<uint8_t>(0, 0), 164);
  EXPECT_EQ(out->at<uint8_t>(0, 1), 36);
  EXPECT_EQ(out->at<uint8_t>(0, 2), 255);
  EXPECT_EQ(out->at<uint8_t>(0, 3), 0);
  EXPECT_EQ(out->at<uint8_t>(1, 0), 64);  // row 1 starts with CB = 0
  EXPECT_EQ(out->at<uint8_t>(1, 1), 192);
}

TEST(TexturePatternTest, AddedHfPatternKeepsTheAdaptedMeanIrradiance) {
  ProjectorResponseFunction prf;  // prf(i) = 0.002 + 0.998 (i / 255)^2
  for (int i = 0; i < 256; ++i) prf.relative_irradiance.push_back(0.002 + 0.998 * (i / 255.0) * (i / 255.0));
  const cv::Size size(8, 4);
  const cv::Mat cb = CheckerboardMask(size, 1);
  for (float e : {0.05f, 0.3f, 0.6f}) {
    const cv::Mat adapted(size, CV_32FC1, cv::Scalar(e));
    auto out = AddHfPatternToIrradiance(adapted, cb, 0.25, prf);
    ASSERT_TRUE(out.ok()) << out.status().ToString();
    const int hi = out->at<uint8_t>(0, 0), lo = out->at<uint8_t>(0, 1);  // CB = 1, CB = 0
    if (lo > 0 && hi < 255) {
      EXPECT_EQ(hi - lo, 2 * 64) << e;  // 255 psi = 63.75 -> 64
    }
    // One grey step of g changes the pair mean by at most ~0.008 here: nearest within half of it.
    EXPECT_NEAR(0.5 * (prf.Irradiance(hi) + prf.Irradiance(lo)), e, 0.004) << e;
    EXPECT_NEAR(cv::mean(prf.IrradianceImage(*out))[0], e, 0.004) << e;
    // The grey-level addition of eq. 5.18 to prf^-1(e) adds light through the convex prf.
    const cv::Mat grey(size, CV_8UC1, cv::Scalar(prf.GreyForIrradiance(e)));
    auto plain = AddHfPattern(grey, cb, 0.25);
    ASSERT_TRUE(plain.ok());
    if (e == 0.3f) {
      EXPECT_GT(cv::mean(prf.IrradianceImage(*plain))[0], e + 0.05);
    }
  }
  // Asking for more light than the brightest full-swing pair (g = 255 - 64: 255 / 127, mean
  // irradiance 0.625) keeps that pair rather than clamping 255 + 64 (255 / 191 would shrink the
  // texture's irradiance swing: 0.44 instead of 0.75 of full scale).
  const double brightest = 0.5 * (prf.Irradiance(255) + prf.Irradiance(127));
  EXPECT_NEAR(brightest, 0.625, 0.001);
  for (float e : {0.64f, 0.8f, 1.0f}) {
    auto top = AddHfPatternToIrradiance(cv::Mat(size, CV_32FC1, cv::Scalar(e)), cb, 0.25, prf);
    ASSERT_TRUE(top.ok());
    EXPECT_EQ(top->at<uint8_t>(0, 0), 255) << e;
    EXPECT_EQ(top->at<uint8_t>(0, 1), 127) << e;
  }
  // Just below it the pair follows the request with its full swing.
  auto below = AddHfPatternToIrradiance(cv::Mat(size, CV_32FC1, cv::Scalar(float(brightest - 0.02))), cb, 0.25, prf);
  ASSERT_TRUE(below.ok());
  EXPECT_EQ(below->at<uint8_t>(0, 0) - below->at<uint8_t>(0, 1), 128);
  EXPECT_LT(below->at<uint8_t>(0, 0), 255);
  EXPECT_NEAR(0.5 * (prf.Irradiance(below->at<uint8_t>(0, 0)) + prf.Irradiance(below->at<uint8_t>(0, 1))),
              brightest - 0.02, 0.004);
  EXPECT_EQ(AddHfPatternToIrradiance(cv::Mat(size, CV_8UC1), cb, 0.25, prf).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(AddHfPatternToIrradiance(cv::Mat(size, CV_32FC1, cv::Scalar(0.3f)), cb, 1.5, prf).status().code(),
            StatusCode::kInvalidArgument);
}

TEST(TexturePatternTest, CameraCheckerboardPeriod) {
  const cv::Mat c = CameraCheckerboard({40, 20}, 10.2, 60, 190);
  EXPECT_EQ(c.at<float>(0, 0), 190.0f);
  EXPECT_EQ(c.at<float>(0, 10), 190.0f);  // 10 < 10.2
  EXPECT_EQ(c.at<float>(0, 11), 60.0f);
  EXPECT_EQ(c.at<float>(11, 11), 190.0f);
}

}  // namespace
}  // namespace inspection
