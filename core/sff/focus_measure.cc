// Focus measure maps of thesis 3.1.3 with OpenCV filters, BORDER_REFLECT_101 at every stage.
// Derivative measures accumulate in float (sums of non-negative terms), the variance and
// moment measures in double (they subtract large, nearly equal sums).
#include "core/sff/focus_measure.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <string>

namespace inspection {
namespace {

constexpr int kBorder = cv::BORDER_REFLECT_101;

// Sum (not mean) over the window_px x window_px window U.
cv::Mat WindowSum(const cv::Mat& m, int window_px) {
  cv::Mat out;
  cv::boxFilter(m, out, -1, cv::Size(window_px, window_px), cv::Point(-1, -1), /*normalize=*/false, kBorder);
  return out;
}

cv::Mat WindowMean(const cv::Mat& m, int window_px) {
  cv::Mat out;
  cv::boxFilter(m, out, -1, cv::Size(window_px, window_px), cv::Point(-1, -1), /*normalize=*/true, kBorder);
  return out;
}

// Second derivatives of eq. 3.9-3.11: 2 I(x) - I(x - 1) - I(x + 1) along x and along y.
void SecondDerivatives(const cv::Mat& f32, cv::Mat* ixx, cv::Mat* iyy) {
  const cv::Mat h = (cv::Mat_<float>(1, 3) << -1.f, 2.f, -1.f);
  const cv::Mat one = (cv::Mat_<float>(1, 1) << 1.f);
  cv::sepFilter2D(f32, *ixx, CV_32F, h, one, cv::Point(-1, -1), 0, kBorder);
  cv::sepFilter2D(f32, *iyy, CV_32F, one, h.t(), cv::Point(-1, -1), 0, kBorder);
}

// The input checks every whole-frame map shares: a grey frame of a supported type, an odd
// window of 3..31.
Status CheckFrameAndWindow(const cv::Mat& frame, int window_px) {
  if (frame.empty()) return Status::InvalidArgument("frame is empty");
  if (frame.type() != CV_8UC1 && frame.type() != CV_16UC1 && frame.type() != CV_32FC1) {
    return Status::InvalidArgument("frame must be CV_8UC1, CV_16UC1 or CV_32FC1");
  }
  if (window_px < 3 || window_px > 31 || window_px % 2 == 0) {
    return Status::InvalidArgument("window_px " + std::to_string(window_px) + " must be odd and between 3 and 31");
  }
  return Status::Ok();
}

}  // namespace

double ChebyshevNorm(int m, int n_points) {
  // (2m)! * C(N + m, 2m + 1), accumulated in double (exact for the sizes used here).
  double fact = 1.0;
  for (int i = 2; i <= 2 * m; ++i) fact *= i;
  double binom = 1.0;
  const int k = 2 * m + 1, n = n_points + m;
  for (int i = 1; i <= k; ++i) binom = binom * double(n - k + i) / double(i);
  return fact * binom;
}

std::vector<double> ChebyshevPolynomial(int m, int n_points) {
  const int N = n_points;
  std::vector<double> t_prev2(N, 1.0), t_prev(N), t(N);
  for (int x = 0; x < N; ++x) t_prev[x] = 1.0 - N + 2.0 * x;  // t_1
  if (m == 0)
    t = t_prev2;
  else if (m == 1)
    t = t_prev;
  for (int n = 2; n <= m; ++n) {  // three-term recurrence, eq. 3.21-3.22
    for (int x = 0; x < N; ++x) {
      t[x] = ((2.0 * n - 1.0) * (2.0 * x - N + 1.0) * t_prev[x] -
              (n - 1.0) * (double(N) * N - (n - 1.0) * (n - 1.0)) * t_prev2[x]) /
             n;
    }
    t_prev2 = t_prev;
    t_prev = t;
  }
  const double s = 1.0 / std::sqrt(ChebyshevNorm(m, N));
  for (double& v : t) v *= s;
  return t;
}

bool FocusMeasureIsRowLocal(FocusMeasure measure) {
  switch (measure) {
    case FocusMeasure::kTenengrad:
    case FocusMeasure::kModifiedLaplacian:
    case FocusMeasure::kSumModifiedLaplacian:
    case FocusMeasure::kGreyLevelVariance:
      return true;
    case FocusMeasure::kHelmliMean:
    case FocusMeasure::kChebyshevMoments:
    case FocusMeasure::kGreyLevelLocalVariance:
      break;
  }
  return false;
}

int IlluminationPower(FocusMeasure measure) {
  switch (measure) {
    case FocusMeasure::kModifiedLaplacian:
      return 1;
    case FocusMeasure::kHelmliMean:
    case FocusMeasure::kChebyshevMoments:
      return 0;
    case FocusMeasure::kSumModifiedLaplacian:
    case FocusMeasure::kTenengrad:
    case FocusMeasure::kGreyLevelVariance:
    case FocusMeasure::kGreyLevelLocalVariance:
      break;
  }
  return 2;
}

Status NormaliseFocusByIllumination(const cv::Mat& frame, FocusMeasure measure, int window_px, cv::Mat* focus) {
  INSPECT_RETURN_IF_ERROR(CheckFrameAndWindow(frame, window_px));
  if (focus == nullptr || focus->type() != CV_32FC1 || focus->size() != frame.size()) {
    return Status::InvalidArgument("focus map must be CV_32FC1 of the frame's size");
  }
  const int power = IlluminationPower(measure);
  if (power == 0) return Status::Ok();
  const double full_scale = frame.depth() == CV_8U ? 255.0 : frame.depth() == CV_16U ? 65535.0 : 1.0;
  const float floor_grey = static_cast<float>(full_scale / 256.0);
  cv::Mat f32;
  frame.convertTo(f32, CV_32F);
  const cv::Mat mu = WindowMean(f32, window_px);
  for (int y = 0; y < frame.rows; ++y) {
    const float* m = mu.ptr<float>(y);
    float* f = focus->ptr<float>(y);
    for (int x = 0; x < frame.cols; ++x) {
      const float light = std::max(m[x], floor_grey);
      f[x] /= power == 1 ? light : light * light;
    }
  }
  return Status::Ok();
}

Status ComputeFocusMeasure(const cv::Mat& frame, FocusMeasure measure, int window_px, cv::Mat* focus) {
  INSPECT_RETURN_IF_ERROR(CheckFrameAndWindow(frame, window_px));
  if (frame.rows < 2 || frame.cols < 2) return Status::InvalidArgument("frame must be at least 2x2");
  const int w = window_px;
  const double n_window = double(w) * w;
  try {
    switch (measure) {
      case FocusMeasure::kModifiedLaplacian:
      case FocusMeasure::kSumModifiedLaplacian: {
        cv::Mat f32, ixx, iyy, e;
        frame.convertTo(f32, CV_32F);
        SecondDerivatives(f32, &ixx, &iyy);
        if (measure == FocusMeasure::kModifiedLaplacian)
          e = cv::abs(ixx) + cv::abs(iyy);
        else
          e = ixx.mul(ixx) + iyy.mul(iyy);
        *focus = WindowSum(e, w);
        return Status::Ok();
      }
      case FocusMeasure::kTenengrad: {
        cv::Mat f32, gx, gy;
        frame.convertTo(f32, CV_32F);
        cv::Sobel(f32, gx, CV_32F, 1, 0, 3, 1, 0, kBorder);
        cv::Sobel(f32, gy, CV_32F, 0, 1, 3, 1, 0, kBorder);
        *focus = WindowSum(gx.mul(gx) + gy.mul(gy), w);
        return Status::Ok();
      }
      case FocusMeasure::kGreyLevelVariance: {
        cv::Mat f64;
        frame.convertTo(f64, CV_64F);
        const cv::Mat s1 = WindowSum(f64, w), s2 = WindowSum(f64.mul(f64), w);
        cv::Mat var = (s2 - s1.mul(s1) / n_window) / (n_window - 1.0);
        var = cv::max(var, 0.0);  // rounding of the difference of sums
        var.convertTo(*focus, CV_32F);
        return Status::Ok();
      }
      case FocusMeasure::kHelmliMean: {
        cv::Mat f64;
        frame.convertTo(f64, CV_64F);
        double min_grey = 0.0;
        cv::minMaxLoc(f64, &min_grey, nullptr);
        if (!(min_grey >= 0.0)) {  // also NaN
          return Status::InvalidArgument("helmli-mean needs grey values >= 0 (a ratio of intensities)");
        }
        // A floor relative to the frame's own scale (not an absolute grey level) keeps the
        // measure scale-free: float frames in [0, 1] would otherwise see every ratio clamped
        // to 1 and a constant map. The floor only matters near black, where the ratio of
        // noise-level grey values would explode.
        const double floor_grey = kHelmliFloorOfMean * cv::mean(f64)[0];
        const cv::Mat mu = WindowMean(f64, w);
        cv::Mat ratio(frame.size(), CV_64F);
        for (int y = 0; y < frame.rows; ++y) {
          const double* i = f64.ptr<double>(y);
          const double* m = mu.ptr<double>(y);
          double* r = ratio.ptr<double>(y);
          for (int x = 0; x < frame.cols; ++x) {
            const double hi = std::max(std::max(i[x], m[x]), floor_grey);
            const double lo = std::max(std::min(i[x], m[x]), floor_grey);
            r[x] = hi > 0.0 ? hi / lo : 1.0;  // hi = 0: an all-black frame
          }
        }
        WindowSum(ratio, w).convertTo(*focus, CV_32F);
        return Status::Ok();
      }
      case FocusMeasure::kChebyshevMoments: {
        cv::Mat f64;
        frame.convertTo(f64, CV_64F);
        std::vector<cv::Mat> t(3);
        for (int m = 0; m < 3; ++m) t[m] = cv::Mat(ChebyshevPolynomial(m, w), true);  // w x 1 column
        cv::Mat low(frame.size(), CV_64F, cv::Scalar(0));
        for (int m = 0; m <= 2; ++m) {
          for (int n = 0; m + n <= 2; ++n) {
            cv::Mat tmn;
            // Correlation: kernelX weights columns (x, order m), kernelY rows (y, order n).
            cv::sepFilter2D(f64, tmn, CV_64F, t[m], t[n], cv::Point(-1, -1), 0, kBorder);
            low += tmn.mul(tmn);
          }
        }
        const cv::Mat energy = WindowSum(f64.mul(f64), w);
        cv::Mat out(frame.size(), CV_32F);
        for (int y = 0; y < frame.rows; ++y) {
          const double* l = low.ptr<double>(y);
          const double* e = energy.ptr<double>(y);
          float* o = out.ptr<float>(y);
          for (int x = 0; x < frame.cols; ++x) {
            // Relative floor: the subtraction leaves rounding noise of ~1e-13 * energy.
            const double high = e[x] - l[x];
            o[x] = (l[x] > 0.0 && high > 1e-12 * e[x]) ? float(std::sqrt(high / l[x])) : 0.f;
          }
        }
        *focus = out;
        return Status::Ok();
      }
      case FocusMeasure::kGreyLevelLocalVariance: {
        cv::Mat f64;
        frame.convertTo(f64, CV_64F);
        cv::Mat d = f64 - WindowMean(f64, w);
        WindowMean(d.mul(d), w).convertTo(*focus, CV_32F);
        return Status::Ok();
      }
    }
  } catch (const cv::Exception& e) {
    return Status::Internal(std::string("focus measure failed: ") + e.what());
  }
  return Status::InvalidArgument("focus_measure is unknown");
}

}  // namespace inspection
