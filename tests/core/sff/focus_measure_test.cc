// Focus measures against values worked out by hand on small images (impulse on a background),
// and against an independent brute-force evaluation for the Chebyshev moment ratio.
#include "core/sff/focus_measure.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <opencv2/imgproc.hpp>
#include <random>

namespace inspection {
namespace {

// 9x9 image, background `bg`, one pixel at (4, 4) set to `peak`.
cv::Mat Impulse(int type, double bg, double peak) {
  cv::Mat m(9, 9, type, cv::Scalar(bg));
  cv::Mat f;
  m.convertTo(f, CV_64F);
  f.at<double>(4, 4) = peak;
  f.convertTo(m, type);
  return m;
}

float At(FocusMeasure fm, const cv::Mat& img, int window, int y, int x) {
  cv::Mat out;
  Status st = ComputeFocusMeasure(img, fm, window, &out);
  EXPECT_TRUE(st.ok()) << st.ToString();
  EXPECT_EQ(out.type(), CV_32FC1);
  EXPECT_EQ(out.size(), img.size());
  return out.at<float>(y, x);
}

TEST(FocusMeasureTest, ModifiedLaplacianByHand) {
  // Impulse 10 on 0. |Ixx| + |Iyy|: centre 20 + 20 = 40; the 4 edge neighbours |0 - 10| = 10;
  // diagonals 0. Window 3 at the centre: 40 + 4 * 10 = 80. Window 3 at (4, 5): its window holds
  // the centre (40), (4,6) (0), (3,5), (5,5) (0), (3,4), (5,4) (10 each), itself (10): 70.
  const cv::Mat img = Impulse(CV_8U, 0, 10);
  EXPECT_FLOAT_EQ(At(FocusMeasure::kModifiedLaplacian, img, 3, 4, 4), 80.f);
  EXPECT_FLOAT_EQ(At(FocusMeasure::kModifiedLaplacian, img, 3, 4, 5), 70.f);
  // Window 5 at the centre holds every non-zero value: 40 + 4 * 10 = 80; far away: 0.
  EXPECT_FLOAT_EQ(At(FocusMeasure::kModifiedLaplacian, img, 5, 4, 4), 80.f);
  EXPECT_FLOAT_EQ(At(FocusMeasure::kModifiedLaplacian, img, 3, 0, 0), 0.f);
}

TEST(FocusMeasureTest, SumModifiedLaplacianByHand) {
  // Ixx^2 + Iyy^2: centre 400 + 400 = 800; edge neighbours 100; window 3: 800 + 400 = 1200.
  const cv::Mat img = Impulse(CV_8U, 0, 10);
  EXPECT_FLOAT_EQ(At(FocusMeasure::kSumModifiedLaplacian, img, 3, 4, 4), 1200.f);
  // At (3, 3) the window holds the centre (800) and its neighbours (3, 4), (4, 3) (100 each).
  EXPECT_FLOAT_EQ(At(FocusMeasure::kSumModifiedLaplacian, img, 3, 3, 3), 1000.f);
  // Adding a constant changes no derivative.
  EXPECT_FLOAT_EQ(At(FocusMeasure::kSumModifiedLaplacian, Impulse(CV_8U, 50, 60), 3, 4, 4), 1200.f);
}

TEST(FocusMeasureTest, TenengradByHand) {
  // Sobel on an impulse of 10: edge neighbours see the mask weight 2 in one direction and 0 in
  // the other: (2*10)^2 = 400; diagonal neighbours weight 1 in both: 100 + 100 = 200; centre 0.
  // Window 3 at the centre: 4 * 400 + 4 * 200 = 2400. At (4, 5): centre 0, (4,6) 0, (3,5), (5,5)
  // 200 each, itself 400, (3,4), (5,4) 400 each, (3,6), (5,6) 0: 1600.
  const cv::Mat img = Impulse(CV_8U, 0, 10);
  EXPECT_FLOAT_EQ(At(FocusMeasure::kTenengrad, img, 3, 4, 4), 2400.f);
  EXPECT_FLOAT_EQ(At(FocusMeasure::kTenengrad, img, 3, 4, 5), 1600.f);
  EXPECT_FLOAT_EQ(At(FocusMeasure::kTenengrad, img, 7, 4, 4), 2400.f);
  // 16-bit frames use the stored grey values.
  EXPECT_FLOAT_EQ(At(FocusMeasure::kTenengrad, Impulse(CV_16U, 1000, 1010), 3, 4, 4), 2400.f);
}

TEST(FocusMeasureTest, GreyLevelVarianceByHand) {
  // Window 3 at the centre: values {10, 0 x 8}, mean 10/9; sum of squares about the mean
  // 100 - 9 * (10/9)^2 = 800/9; divided by N - 1 = 8: 100/9.
  const cv::Mat img = Impulse(CV_8U, 0, 10);
  EXPECT_NEAR(At(FocusMeasure::kGreyLevelVariance, img, 3, 4, 4), 100.0 / 9.0, 1e-5);
  // Window 5: {10, 0 x 24}: (100 - 100/25) / 24 = 4.
  EXPECT_NEAR(At(FocusMeasure::kGreyLevelVariance, img, 5, 4, 4), 4.0, 1e-5);
  EXPECT_NEAR(At(FocusMeasure::kGreyLevelVariance, Impulse(CV_16U, 40000, 40010), 5, 4, 4), 4.0, 1e-5);
}

TEST(FocusMeasureTest, HelmliMeanByHand) {
  // Impulse 190 on 100, window 3. At the centre, mu = 100 + 90/9 = 110 and I = 190: R = 190/110.
  // Each of the 8 neighbours has the centre in its window: mu = 110 > I = 100: R = 1.1.
  // FM(centre) = 190/110 + 8 * 1.1.
  const cv::Mat img = Impulse(CV_8U, 100, 190);
  EXPECT_NEAR(At(FocusMeasure::kHelmliMean, img, 3, 4, 4), 190.0 / 110.0 + 8 * 1.1, 1e-5);
  // A constant image gives R = 1 everywhere: FM = N.
  EXPECT_NEAR(At(FocusMeasure::kHelmliMean, cv::Mat(9, 9, CV_8U, cv::Scalar(77)), 5, 4, 4), 25.0, 1e-5);
  // Zero grey values: both terms are floored at mean / 128 = (9 / 81) / 128. Impulse 9 on 0:
  // centre mu = 1, I = 9 -> 9; neighbours mu = 1, I = 0 -> 1 / floor = 1152. FM = 9 + 8 * 1152.
  EXPECT_NEAR(At(FocusMeasure::kHelmliMean, Impulse(CV_8U, 0, 9), 3, 4, 4), 9.0 + 8 * 1152.0, 1e-2);
  // All zero: 1 everywhere (no division by zero).
  EXPECT_NEAR(At(FocusMeasure::kHelmliMean, cv::Mat(9, 9, CV_8U, cv::Scalar(0)), 3, 4, 4), 9.0, 1e-5);
}

TEST(FocusMeasureTest, HelmliMeanIsScaleFree) {
  // The same texture as 8-bit grey levels, as 16-bit (x 257) and as float in [0, 1] (/ 255):
  // the ratios of eq. 3.16 do not depend on the unit, so the maps agree. With the former floor of
  // one absolute grey level every ratio of the float frame was 1 and its map the constant N.
  cv::Mat u8(24, 24, CV_8U);
  std::mt19937 rng(5);
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 24; ++x) u8.at<uint8_t>(y, x) = uint8_t(rng() % 200);  // includes 0
  cv::Mat u16, f32;
  u8.convertTo(u16, CV_16U, 257.0);
  u8.convertTo(f32, CV_32F, 1.0 / 255.0);
  cv::Mat m8, m16, m32;
  ASSERT_TRUE(ComputeFocusMeasure(u8, FocusMeasure::kHelmliMean, 5, &m8).ok());
  ASSERT_TRUE(ComputeFocusMeasure(u16, FocusMeasure::kHelmliMean, 5, &m16).ok());
  ASSERT_TRUE(ComputeFocusMeasure(f32, FocusMeasure::kHelmliMean, 5, &m32).ok());
  double lo = 0, hi = 0;
  cv::minMaxLoc(m32, &lo, &hi);
  EXPECT_GT(hi, 1.5 * 25.0);  // far from the constant N = 25 of the clamped float frame
  EXPECT_LT(cv::norm(m8, m16, cv::NORM_INF), 1e-5 * hi);
  EXPECT_LT(cv::norm(m8, m32, cv::NORM_INF), 1e-4 * hi);  // float frame: rounded to float first

  // On a float frame, a sharp texture scores higher than its blurred copy, pixel by pixel on
  // average: the measure sees focus, not the unit.
  cv::Mat blurred;
  cv::GaussianBlur(f32, blurred, cv::Size(0, 0), 1.5, 1.5, cv::BORDER_REFLECT_101);
  cv::Mat mb;
  ASSERT_TRUE(ComputeFocusMeasure(blurred, FocusMeasure::kHelmliMean, 5, &mb).ok());
  EXPECT_GT(cv::mean(m32)[0], 1.2 * cv::mean(mb)[0]);

  // Negative grey values have no intensity ratio.
  cv::Mat neg = f32 - 0.5;
  cv::Mat out;
  EXPECT_EQ(ComputeFocusMeasure(neg, FocusMeasure::kHelmliMean, 5, &out).code(), StatusCode::kInvalidArgument);
}

TEST(FocusMeasureTest, GreyLevelLocalVarianceByHand) {
  // Impulse 190 on 100, window 3, at the centre: the centre deviates 190 - 110 = 80 from its own
  // window mean, each neighbour 100 - 110 = -10: (6400 + 8 * 100) / 9 = 800.
  const cv::Mat img = Impulse(CV_8U, 100, 190);
  EXPECT_NEAR(At(FocusMeasure::kGreyLevelLocalVariance, img, 3, 4, 4), 800.0, 1e-4);
  // Eq. 3.15 uses the centre window's mean 110 for all: (80^2 + 8 * 10^2) / (N - 1) = 7200 / 8.
  EXPECT_NEAR(At(FocusMeasure::kGreyLevelVariance, img, 3, 4, 4), 900.0, 1e-3);
}

TEST(FocusMeasureTest, BorderIsReflect101) {
  // Impulse 10 at the corner (0, 0). Mirroring without repeating the edge: the window 3 around
  // (0, 0) covers rows/cols {1, 0, 1}. ML values: (0,0) 40, (0,1) and (1,0) 10, (1,1) 0.
  // Sum: 40 + 2 * 10 + 2 * 10 + 4 * 0 = 80.
  cv::Mat img(6, 6, CV_8U, cv::Scalar(0));
  img.at<uint8_t>(0, 0) = 10;
  EXPECT_FLOAT_EQ(At(FocusMeasure::kModifiedLaplacian, img, 3, 0, 0), 80.f);
  // SML: 800 + 4 * 100 = 1200 (each of the two edge neighbours appears twice).
  EXPECT_FLOAT_EQ(At(FocusMeasure::kSumModifiedLaplacian, img, 3, 0, 0), 1200.f);
  // Tenengrad: the corner's own Sobel responses vanish by symmetry (0); (0,1) and (1,0) see the
  // impulse with weight 2 (400), (1,1) with weight 1 in both directions (200). The window covers
  // {1,0,1} x {1,0,1}: 0 + 2 * 400 + 2 * 400 + 4 * 200 = 2400. Cross-checked on the explicitly
  // padded image:
  cv::Mat padded;
  cv::copyMakeBorder(img, padded, 1, 1, 1, 1, cv::BORDER_REFLECT_101);
  auto sobel_energy = [&](int y, int x) {                  // at image pixel (y, x), |y|,|x| <= 1 beyond the edge
    const int py = std::abs(y) + 1, px = std::abs(x) + 1;  // reflect then shift into padded
    double gx = 0, gy = 0;
    const int sx[3][3] = {{1, 0, -1}, {2, 0, -2}, {1, 0, -1}}, sy[3][3] = {{1, 2, 1}, {0, 0, 0}, {-1, -2, -1}};
    for (int j = -1; j <= 1; ++j)
      for (int i = -1; i <= 1; ++i) {
        const double v = padded.at<uint8_t>(py + j, px + i);
        gx += sx[j + 1][i + 1] * v;
        gy += sy[j + 1][i + 1] * v;
      }
    return gx * gx + gy * gy;
  };
  double expected = 0;
  for (int j = -1; j <= 1; ++j)
    for (int i = -1; i <= 1; ++i) expected += sobel_energy(j, i);
  EXPECT_FLOAT_EQ(At(FocusMeasure::kTenengrad, img, 3, 0, 0), float(expected));
  EXPECT_FLOAT_EQ(float(expected), 2400.f);
}

TEST(FocusMeasureTest, ChebyshevPolynomialsAreOrthonormalAndMatchRho) {
  for (int n : {3, 7, 31}) {
    for (int m = 0; m < std::min(n, 6); ++m) {
      const auto tm = ChebyshevPolynomial(m, n);
      for (int k = 0; k <= m; ++k) {
        const auto tk = ChebyshevPolynomial(k, n);
        const double dot = std::inner_product(tm.begin(), tm.end(), tk.begin(), 0.0);
        EXPECT_NEAR(dot, m == k ? 1.0 : 0.0, 1e-9) << "N=" << n << " m=" << m << " k=" << k;
      }
    }
  }
  EXPECT_DOUBLE_EQ(ChebyshevNorm(0, 5), 5.0);               // sum of 1^2
  EXPECT_DOUBLE_EQ(ChebyshevNorm(1, 3), 8.0);               // (-2)^2 + 0 + 2^2
  EXPECT_DOUBLE_EQ(ChebyshevNorm(1, 7), 7.0 * 48.0 / 3.0);  // N (N^2 - 1) / 3
}

// Brute force, independent of the implementation: Gram-Schmidt on 1, x, x^2, ... gives the
// orthonormal basis; all w*w moments by direct summation; ratio of the norms.
double ChebyshevBruteForce(const cv::Mat& img64, int y0, int x0, int w) {
  std::vector<std::vector<double>> basis;
  for (int m = 0; m < w; ++m) {
    std::vector<double> v(w);
    for (int x = 0; x < w; ++x) v[x] = std::pow(double(x) - (w - 1) / 2.0, m);
    for (const auto& b : basis) {
      const double d = std::inner_product(v.begin(), v.end(), b.begin(), 0.0);
      for (int x = 0; x < w; ++x) v[x] -= d * b[x];
    }
    const double norm = std::sqrt(std::inner_product(v.begin(), v.end(), v.begin(), 0.0));
    for (double& x : v) x /= norm;
    basis.push_back(v);
  }
  const int r = w / 2;
  double low = 0, high = 0;
  for (int m = 0; m < w; ++m)
    for (int n = 0; n < w; ++n) {
      double t = 0;
      for (int j = 0; j < w; ++j)
        for (int i = 0; i < w; ++i) t += basis[m][i] * basis[n][j] * img64.at<double>(y0 - r + j, x0 - r + i);
      (m + n <= 2 ? low : high) += t * t;
    }
  return std::sqrt(high / low);
}

TEST(FocusMeasureTest, ChebyshevRatioMatchesBruteForce) {
  cv::Mat img(20, 20, CV_8U);
  std::mt19937 rng(7);
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 20; ++x) img.at<uint8_t>(y, x) = uint8_t(60 + rng() % 120);
  cv::Mat img64;
  img.convertTo(img64, CV_64F);
  for (int w : {3, 5, 7}) {
    const double expected = ChebyshevBruteForce(img64, 10, 9, w);
    EXPECT_NEAR(At(FocusMeasure::kChebyshevMoments, img, w, 10, 9), expected, 1e-5 * expected) << "w=" << w;
  }
  // Gram-Schmidt polynomials are the Chebyshev ones up to sign, so the ratio is the same. A ramp
  // (orders 0 and 1 only) has no high-order energy; a constant neither.
  cv::Mat ramp(9, 9, CV_8U);
  for (int y = 0; y < 9; ++y)
    for (int x = 0; x < 9; ++x) ramp.at<uint8_t>(y, x) = uint8_t(10 + 3 * x + 5 * y);
  EXPECT_NEAR(At(FocusMeasure::kChebyshevMoments, ramp, 5, 4, 4), 0.0, 1e-4);
  EXPECT_EQ(At(FocusMeasure::kChebyshevMoments, cv::Mat(9, 9, CV_8U, cv::Scalar(0)), 3, 4, 4), 0.f);
}

TEST(FocusMeasureTest, SharperImageScoresHigherForEveryMeasure) {
  cv::Mat sharp(32, 32, CV_8U);
  std::mt19937 rng(3);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) sharp.at<uint8_t>(y, x) = uint8_t(40 + rng() % 160);
  cv::Mat blurred;
  cv::GaussianBlur(sharp, blurred, cv::Size(0, 0), 1.5, 1.5, cv::BORDER_REFLECT_101);
  for (FocusMeasure fm : {FocusMeasure::kModifiedLaplacian, FocusMeasure::kSumModifiedLaplacian,
                          FocusMeasure::kTenengrad, FocusMeasure::kGreyLevelVariance, FocusMeasure::kHelmliMean,
                          FocusMeasure::kChebyshevMoments, FocusMeasure::kGreyLevelLocalVariance}) {
    EXPECT_GT(At(fm, sharp, 7, 16, 16), At(fm, blurred, 7, 16, 16)) << FocusMeasureName(fm);
  }
}

// A frame lit s times brighter (the ADAPT family changes the light at every z): every measure
// divided by the window mean to its illumination power gives the map of the unlit-scaled frame,
// while the raw measure grows as s^power. Float frames, so no quantisation enters.
TEST(FocusMeasureTest, NormalisedByIlluminationIsTheSameForAnyLight) {
  cv::Mat base(40, 40, CV_32F);
  std::mt19937 rng(9);
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 40; ++x) base.at<float>(y, x) = float(60 + rng() % 100);
  cv::GaussianBlur(base, base, cv::Size(0, 0), 0.8, 0.8, cv::BORDER_REFLECT_101);
  const double s = 1.7;
  const cv::Mat brighter = base * s;
  const std::pair<FocusMeasure, int> expected_power[] = {
      {FocusMeasure::kModifiedLaplacian, 1}, {FocusMeasure::kSumModifiedLaplacian, 2},   {FocusMeasure::kTenengrad, 2},
      {FocusMeasure::kGreyLevelVariance, 2}, {FocusMeasure::kGreyLevelLocalVariance, 2}, {FocusMeasure::kHelmliMean, 0},
      {FocusMeasure::kChebyshevMoments, 0}};
  for (const auto& [fm, power] : expected_power) {
    EXPECT_EQ(IlluminationPower(fm), power) << FocusMeasureName(fm);
    cv::Mat a, b;
    ASSERT_TRUE(ComputeFocusMeasure(base, fm, 7, &a).ok());
    ASSERT_TRUE(ComputeFocusMeasure(brighter, fm, 7, &b).ok());
    // Raw: the light's power shows (checked at the centre).
    EXPECT_NEAR(b.at<float>(20, 20) / a.at<float>(20, 20), std::pow(s, power), 1e-3 * std::pow(s, power))
        << FocusMeasureName(fm);
    const cv::Mat raw_a = a.clone();
    ASSERT_TRUE(NormaliseFocusByIllumination(base, fm, 7, &a).ok());
    ASSERT_TRUE(NormaliseFocusByIllumination(brighter, fm, 7, &b).ok());
    double hi = 0;
    cv::minMaxLoc(a, nullptr, &hi);
    EXPECT_LT(cv::norm(a, b, cv::NORM_INF), 1e-4 * hi) << FocusMeasureName(fm);
    if (power == 0) {
      EXPECT_EQ(cv::norm(a, raw_a, cv::NORM_INF), 0.0) << FocusMeasureName(fm);
    }
  }
  // Tenengrad by hand at one pixel: the raw value over the 7x7 mean squared.
  cv::Mat t, mean;
  ASSERT_TRUE(ComputeFocusMeasure(base, FocusMeasure::kTenengrad, 7, &t).ok());
  const float raw = t.at<float>(20, 20);
  const double mu = cv::mean(base(cv::Rect(17, 17, 7, 7)))[0];
  ASSERT_TRUE(NormaliseFocusByIllumination(base, FocusMeasure::kTenengrad, 7, &t).ok());
  EXPECT_NEAR(t.at<float>(20, 20), raw / (mu * mu), 1e-5 * raw / (mu * mu));
  // A black frame: the floor (one grey level of 8 bit) keeps the ratio finite.
  const cv::Mat black(12, 12, CV_8U, cv::Scalar(0));
  cv::Mat fb;
  ASSERT_TRUE(ComputeFocusMeasure(black, FocusMeasure::kTenengrad, 3, &fb).ok());
  ASSERT_TRUE(NormaliseFocusByIllumination(black, FocusMeasure::kTenengrad, 3, &fb).ok());
  EXPECT_EQ(cv::norm(fb, cv::NORM_INF), 0.0);
  // Bad input names what is wrong.
  cv::Mat wrong(5, 5, CV_32F, cv::Scalar(1));
  EXPECT_EQ(NormaliseFocusByIllumination(base, FocusMeasure::kTenengrad, 7, &wrong).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(NormaliseFocusByIllumination(base, FocusMeasure::kTenengrad, 8, &t).code(), StatusCode::kInvalidArgument);
}

// The streaming engine computes the focus map in row bands (core/sff/sff_exact_engine.cc): for
// the row-local measures, rows [y0, y1) of a band's map computed from frame rows widened by
// FocusMeasureHaloRows must equal the whole frame's rows bit for bit, raw and normalised by the
// light, for 8- and 16-bit frames of full-range noise (the largest sums), bands touching the top,
// the bottom or neither, and windows up to the widest. One row less of halo must show.
TEST(FocusMeasureTest, RowLocalMeasuresInBandsEqualTheWholeFrameBitForBit) {
  const cv::Size size(61, 97);  // odd width: the filters' vector tails
  std::mt19937 rng(35);
  const std::pair<int, int> bands[] = {{0, 1}, {0, 20}, {13, 14}, {20, 57}, {60, 97}, {96, 97}, {0, 97}};
  for (int type : {CV_8UC1, CV_16UC1}) {
    cv::Mat frame(size, type);
    const uint32_t full = type == CV_8UC1 ? 256 : 65536;
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        if (type == CV_8UC1)
          frame.at<uint8_t>(y, x) = uint8_t(rng() % full);
        else
          frame.at<uint16_t>(y, x) = uint16_t(rng() % full);
      }
    for (FocusMeasure fm : {FocusMeasure::kTenengrad, FocusMeasure::kModifiedLaplacian,
                            FocusMeasure::kSumModifiedLaplacian, FocusMeasure::kGreyLevelVariance}) {
      ASSERT_TRUE(FocusMeasureIsRowLocal(fm)) << FocusMeasureName(fm);
      for (int w : {3, 9, 31}) {
        cv::Mat whole, whole_lit;
        ASSERT_TRUE(ComputeFocusMeasure(frame, fm, w, &whole).ok());
        whole_lit = whole.clone();
        ASSERT_TRUE(NormaliseFocusByIllumination(frame, fm, w, &whole_lit).ok());
        const int halo = FocusMeasureHaloRows(w);
        for (const auto& [y0, y1] : bands) {
          const int h0 = std::max(0, y0 - halo), h1 = std::min(size.height, y1 + halo);
          cv::Mat band;
          ASSERT_TRUE(ComputeFocusMeasure(frame.rowRange(h0, h1), fm, w, &band).ok());
          cv::Mat band_lit = band.clone();
          ASSERT_TRUE(NormaliseFocusByIllumination(frame.rowRange(h0, h1), fm, w, &band_lit).ok());
          const size_t row_bytes = size_t(size.width) * sizeof(float);
          for (int y = y0; y < y1; ++y) {
            ASSERT_EQ(std::memcmp(whole.ptr<float>(y), band.ptr<float>(y - h0), row_bytes), 0)
                << FocusMeasureName(fm) << " type " << type << " window " << w << " row " << y;
            ASSERT_EQ(std::memcmp(whole_lit.ptr<float>(y), band_lit.ptr<float>(y - h0), row_bytes), 0)
                << FocusMeasureName(fm) << " normalised, type " << type << " window " << w << " row " << y;
          }
        }
      }
    }
    // One row of halo less: Tenengrad's band edge row differs (the halo is not oversized).
    const int w = 9, halo = FocusMeasureHaloRows(w) - 1, y0 = 40, y1 = 50;
    cv::Mat whole, band;
    ASSERT_TRUE(ComputeFocusMeasure(frame, FocusMeasure::kTenengrad, w, &whole).ok());
    ASSERT_TRUE(ComputeFocusMeasure(frame.rowRange(y0 - halo, y1 + halo), FocusMeasure::kTenengrad, w, &band).ok());
    EXPECT_NE(std::memcmp(whole.ptr<float>(y0), band.ptr<float>(halo), size_t(size.width) * sizeof(float)), 0);
  }
  // Not row-local: the Helmli mean's floor is the whole frame's mean; the local variance's and the
  // Chebyshev moments' sums are not exact.
  EXPECT_FALSE(FocusMeasureIsRowLocal(FocusMeasure::kHelmliMean));
  EXPECT_FALSE(FocusMeasureIsRowLocal(FocusMeasure::kGreyLevelLocalVariance));
  EXPECT_FALSE(FocusMeasureIsRowLocal(FocusMeasure::kChebyshevMoments));
}

TEST(FocusMeasureTest, RejectsBadWindowAndType) {
  cv::Mat out;
  const cv::Mat img(9, 9, CV_8U, cv::Scalar(1));
  for (int w : {1, 2, 4, 33, 0, -3}) {
    Status st = ComputeFocusMeasure(img, FocusMeasure::kTenengrad, w, &out);
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << w;
    EXPECT_NE(st.message().find("window_px"), std::string::npos);
  }
  EXPECT_EQ(ComputeFocusMeasure(cv::Mat(9, 9, CV_8UC3), FocusMeasure::kTenengrad, 3, &out).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputeFocusMeasure(cv::Mat(), FocusMeasure::kTenengrad, 3, &out).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(ComputeFocusMeasure(img, FocusMeasure::kTenengrad, 31, &out).ok());
}

}  // namespace
}  // namespace inspection
