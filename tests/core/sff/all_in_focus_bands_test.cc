// The colour all-in-focus composer fed its score band by band (AllInFocusComposer::
// PushFrameInBands with FocusScoreRows, as ReconstructStackFrames does so that no whole-frame
// score exists) against the same frames pushed with the whole frame's FocusScore: the same image
// and frame index bit for bit, for integer (8-bit Tenengrad) and float (16-bit SML) scores, bands
// of one row up to more than the frame.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

#include "core/sff/all_in_focus.h"
#include "core/sff/focus_measure.h"

namespace inspection {
namespace {

// Frames of noise blurred by a per-frame, per-column-band amount: every frame wins somewhere.
std::vector<cv::Mat> ColourFrames(cv::Size size, int type, int frames) {
  std::mt19937 rng(35);
  cv::Mat noise(size, CV_32FC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      for (int c = 0; c < 3; ++c) noise.at<cv::Vec3f>(y, x)[c] = float(rng() % 1000) / 1000.f;
  const double full = type == CV_8UC3 ? 255.0 : 65535.0;
  std::vector<cv::Mat> out;
  for (int k = 0; k < frames; ++k) {
    cv::Mat f(size, CV_32FC3);
    for (int b = 0; b < frames; ++b) {
      const cv::Range cols(size.width * b / frames, size.width * (b + 1) / frames);
      cv::Mat blurred;
      cv::GaussianBlur(noise, blurred, cv::Size(0, 0), 0.4 + 0.9 * std::abs(k - b));
      blurred.colRange(cols).copyTo(f.colRange(cols));
    }
    cv::Mat m;
    f.convertTo(m, type, full);
    out.push_back(m);
  }
  return out;
}

cv::Mat GreyOf(const cv::Mat& bgr) {
  std::vector<cv::Mat> ch;
  cv::split(bgr, ch);
  return ch[1];  // any grey image of the frame will do: both paths score the same one
}

void ExpectSameBytes(const cv::Mat& a, const cv::Mat& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  ASSERT_EQ(a.type(), b.type()) << what;
  EXPECT_EQ(std::memcmp(a.data, b.data, a.total() * a.elemSize()), 0) << what;
}

TEST(AllInFocusBandsTest, BandsGiveTheWholeScoresResultBitForBit) {
  const cv::Size size(45, 67);
  struct Case {
    int type;
    FocusMeasure measure;
    int window;
  } cases[] = {{CV_8UC3, FocusMeasure::kTenengrad, 7},
               {CV_16UC3, FocusMeasure::kSumModifiedLaplacian, 9},
               {CV_8UC3, FocusMeasure::kHelmliMean, 5}};  // not row-local: whole-frame score per band
  for (const Case& c : cases) {
    const std::vector<cv::Mat> frames = ColourFrames(size, c.type, 5);
    auto whole = AllInFocusComposer::Create(size, c.type);
    ASSERT_TRUE(whole.ok());
    for (const cv::Mat& f : frames) {
      cv::Mat score;
      ASSERT_TRUE(FocusScore(GreyOf(f), c.measure, c.window, &score).ok());
      ASSERT_TRUE(whole->PushFrame(f, score).ok());
    }
    for (int band_rows : {1, 6, 64, 67, 500}) {
      auto banded = AllInFocusComposer::Create(size, c.type);
      ASSERT_TRUE(banded.ok());
      for (const cv::Mat& f : frames) {
        const cv::Mat grey = GreyOf(f);
        Status st = banded->PushFrameInBands(
            f, [&](int y0, int y1, cv::Mat* rows) { return FocusScoreRows(grey, c.measure, c.window, y0, y1, rows); },
            band_rows);
        ASSERT_TRUE(st.ok()) << st.ToString();
      }
      const std::string what = std::string(FocusMeasureName(c.measure)) + " band_rows " + std::to_string(band_rows);
      ExpectSameBytes(banded->all_in_focus(), whole->all_in_focus(), what + " image");
      ExpectSameBytes(banded->frame_index(), whole->frame_index(), what + " index");
    }
    // The frames do not all win in the same place (the comparison is not of a constant image).
    double lo = 0, hi = 0;
    cv::minMaxLoc(whole->frame_index(), &lo, &hi);
    EXPECT_EQ(lo, 0.0);
    EXPECT_EQ(hi, 4.0);
  }
}

TEST(AllInFocusBandsTest, BadBandsAndRowsAreNamed) {
  const cv::Size size(8, 10);
  auto c = AllInFocusComposer::Create(size, CV_8UC1);
  ASSERT_TRUE(c.ok());
  const cv::Mat frame(size, CV_8UC1, cv::Scalar(3));
  auto short_rows = [&](int y0, int y1, cv::Mat* rows) {
    *rows = cv::Mat(y1 - y0 + 1, size.width, CV_32SC1, cv::Scalar(1));
    return Status::Ok();
  };
  Status st = c->PushFrameInBands(frame, short_rows, 4);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("frame 0"), std::string::npos) << st.message();
  EXPECT_EQ(c->frames_pushed(), 0);
  EXPECT_EQ(c->PushFrameInBands(frame, short_rows, 0).code(), StatusCode::kInvalidArgument);
  // A wrong frame fails before any score is asked for.
  bool asked = false;
  st = c->PushFrameInBands(
      cv::Mat(size, CV_16UC1),
      [&](int, int, cv::Mat*) {
        asked = true;
        return Status::Ok();
      },
      4);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(asked);
  cv::Mat rows;
  EXPECT_EQ(FocusScoreRows(frame, FocusMeasure::kTenengrad, 3, 5, 11, &rows).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(FocusScoreRows(frame, FocusMeasure::kTenengrad, 3, 4, 4, &rows).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
