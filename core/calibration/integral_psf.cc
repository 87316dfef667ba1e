// Integral PSF (thesis 5.4.1, eq. 5.22-5.23) by conjugate gradients on the regularised normal
// equations; total variation and the L1 data term (TV-L1) through iteratively reweighted least
// squares.
#include "core/calibration/integral_psf.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <string>

namespace inspection {

Status IntegralPsf::Validate() const {
  if (kernel.type() != CV_32FC1 || kernel.rows != kernel.cols || kernel.rows % 2 != 1) {
    return Status::InvalidArgument("integral_psf.kernel must be an odd square CV_32FC1");
  }
  if (!cv::checkRange(kernel)) return Status::InvalidArgument("integral_psf.kernel is not finite");
  return Status::Ok();
}

cv::Mat IntegralPsf::Apply(const cv::Mat& integral_image) const {
  cv::Mat f, flipped, out;
  integral_image.convertTo(f, CV_32F);
  cv::flip(kernel, flipped, -1);  // filter2D correlates; eq. 5.23 convolves
  cv::filter2D(f, out, CV_32F, flipped, cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
  return out;
}

const char* IpsfRegularisationName(IpsfRegularisation r) {
  switch (r) {
    case IpsfRegularisation::kGradientL2:
      return "gradient_l2";
    case IpsfRegularisation::kTotalVariation:
      return "total_variation";
    case IpsfRegularisation::kTotalVariationL1:
      return "tv_l1";
  }
  return "gradient_l2";
}

StatusOr<IpsfRegularisation> ParseIpsfRegularisation(const std::string& name) {
  for (IpsfRegularisation r :
       {IpsfRegularisation::kGradientL2, IpsfRegularisation::kTotalVariation, IpsfRegularisation::kTotalVariationL1}) {
    if (name == IpsfRegularisationName(r)) return r;
  }
  if (name == "tv_l2") return IpsfRegularisation::kTotalVariation;
  return Status::InvalidArgument("unknown IPSF regularisation '" + name +
                                 "' (gradient_l2, total_variation or tv_l2, tv_l1)");
}

Status IntegralPsfOptions::Validate() const {
  if (radius_px < 1 || radius_px > 64) return Status::InvalidArgument("radius_px must be 1..64");
  if (!(regularisation_weight >= 0)) return Status::InvalidArgument("regularisation_weight must be >= 0");
  if (max_cg_iterations < 1) return Status::InvalidArgument("max_cg_iterations must be >= 1");
  if (tv_reweight_iterations < 1) return Status::InvalidArgument("tv_reweight_iterations must be >= 1");
  if (!(tv_epsilon > 0)) return Status::InvalidArgument("tv_epsilon must be > 0");
  if (!(l1_epsilon > 0)) return Status::InvalidArgument("l1_epsilon must be > 0");
  if (!(integral_noise_sigma >= 0) || !std::isfinite(integral_noise_sigma)) {
    return Status::InvalidArgument("integral_noise_sigma must be finite and >= 0");
  }
  return Status::Ok();
}

StatusOr<cv::Mat> IntegralImage(const std::vector<cv::Mat>& frames) {
  if (frames.empty()) return Status::InvalidArgument("integral image: no frames");
  cv::Mat acc = cv::Mat::zeros(frames[0].size(), CV_64FC1);
  for (size_t i = 0; i < frames.size(); ++i) {
    if (frames[i].size() != frames[0].size() || frames[i].channels() != 1) {
      return Status::InvalidArgument("integral image: frame " + std::to_string(i) + " differs in size or channels");
    }
    cv::Mat f;
    frames[i].convertTo(f, CV_64F);
    acc += f;
  }
  cv::Mat out;
  acc.convertTo(out, CV_32F, 1.0 / frames.size());
  return out;
}

namespace {

// The linear operator of eq. 5.22 restricted to the valid region V (every kernel tap inside).
class IpsfProblem {
 public:
  IpsfProblem(const cv::Mat& integral, int r) : i_(integral), r_(r) {
    valid_ = cv::Rect(r, r, integral.cols - 2 * r, integral.rows - 2 * r);
  }
  const cv::Rect& valid() const { return valid_; }

  // A k: (I * k) on V.
  cv::Mat Forward(const cv::Mat& k) const {
    cv::Mat flipped, out;
    cv::flip(k, flipped, -1);
    cv::filter2D(i_, out, CV_32F, flipped, cv::Point(-1, -1), 0, cv::BORDER_CONSTANT);
    return out(valid_).clone();
  }
  // A^T r: c(d) = sum_{x in V} r(x) I(x - d), via one correlation of I with r.
  cv::Mat Adjoint(const cv::Mat& residual) const {
    cv::Mat res, out;
    cv::matchTemplate(i_, residual, res, cv::TM_CCORR);
    cv::flip(res, out, -1);
    return out;
  }

 private:
  cv::Mat i_;
  int r_;
  cv::Rect valid_;
};

// D^T W D k for forward differences on the kernel grid (Neumann border), W per-pixel weights
// for the x and y differences.
cv::Mat GradientNormal(const cv::Mat& k, const cv::Mat& wx, const cv::Mat& wy) {
  const int n = k.rows;
  cv::Mat out = cv::Mat::zeros(k.size(), CV_32F);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      if (x + 1 < n) {
        const float d = wx.at<float>(y, x) * (k.at<float>(y, x + 1) - k.at<float>(y, x));
        out.at<float>(y, x + 1) += d;
        out.at<float>(y, x) -= d;
      }
      if (y + 1 < n) {
        const float d = wy.at<float>(y, x) * (k.at<float>(y + 1, x) - k.at<float>(y, x));
        out.at<float>(y + 1, x) += d;
        out.at<float>(y, x) -= d;
      }
    }
  return out;
}

double Dot(const cv::Mat& a, const cv::Mat& b) { return a.dot(b); }

// Conjugate gradients on (A^T Wd A + mu D^T W D) k = A^T Wd t, starting from k. wd: per-pixel
// data weights on V (empty = all 1, the L2 data term).
void SolveCg(const IpsfProblem& p, const cv::Mat& t_valid, const cv::Mat& wd, double mu, const cv::Mat& wx,
             const cv::Mat& wy, int max_iter, double tol, cv::Mat& k) {
  auto weigh = [&](const cv::Mat& r) -> cv::Mat { return wd.empty() ? r : r.mul(wd); };
  auto apply = [&](const cv::Mat& v) -> cv::Mat {
    cv::Mat out = p.Adjoint(weigh(p.Forward(v)));
    if (mu > 0) out += mu * GradientNormal(v, wx, wy);
    return out;
  };
  const cv::Mat b = p.Adjoint(weigh(t_valid));
  cv::Mat r = b - apply(k);
  cv::Mat d = r.clone();
  double rr = Dot(r, r);
  const double bb = std::max(Dot(b, b), 1e-300);
  for (int it = 0; it < max_iter && rr / bb > tol * tol; ++it) {
    const cv::Mat ad = apply(d);
    const double dad = Dot(d, ad);
    if (!(dad > 0)) break;
    const double alpha = rr / dad;
    k += alpha * d;
    r -= alpha * ad;
    const double rr_next = Dot(r, r);
    d = r + (rr_next / rr) * d;
    rr = rr_next;
  }
}

double RmsDiff(const cv::Mat& a, const cv::Mat& b) {
  const double n = static_cast<double>(a.total());
  return std::sqrt(cv::norm(a, b, cv::NORM_L2SQR) / n);
}

}  // namespace

StatusOr<IntegralPsf> EstimateIntegralPsf(const cv::Mat& integral_image, const cv::Mat& focused_image,
                                          const IntegralPsfOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (integral_image.empty() || integral_image.channels() != 1 || focused_image.channels() != 1 ||
      integral_image.size() != focused_image.size()) {
    return Status::InvalidArgument("integral_image and focused_image must be single-channel images of one size");
  }
  const int r = options.radius_px;
  if (integral_image.cols < 4 * r + 2 || integral_image.rows < 4 * r + 2) {
    return Status::InvalidArgument("images are too small for a kernel of radius " + std::to_string(r));
  }
  cv::Mat i_int, i_t;
  integral_image.convertTo(i_int, CV_32F);
  focused_image.convertTo(i_t, CV_32F);
  const IpsfProblem problem(i_int, r);
  const cv::Mat t_valid = i_t(problem.valid()).clone();
  const int n = 2 * r + 1;
  // mu relative to the mean diagonal of A^T A (= sum of I^2 over V-shifted windows).
  const double diag = cv::norm(i_int(problem.valid()), cv::NORM_L2SQR);
  const double mu = options.regularisation_weight * diag;

  cv::Mat k = cv::Mat::zeros(n, n, CV_32F);
  k.at<float>(r, r) = 1.0f;  // start from the identity: I_int is already close to I_t
  cv::Mat wx = cv::Mat::ones(n, n, CV_32F), wy = cv::Mat::ones(n, n, CV_32F);
  cv::Mat wd;  // L2 data term until TV-L1 reweighs it
  SolveCg(problem, t_valid, wd, mu, wx, wy, options.max_cg_iterations, options.cg_tolerance, k);
  const bool l1 = options.regularisation == IpsfRegularisation::kTotalVariationL1;
  if (options.regularisation != IpsfRegularisation::kGradientL2) {
    // IRLS: |grad k| ~ (grad k)^2 / |grad k|, weights from the previous solution. The kernel's
    // scale sets epsilon's meaning, so epsilon is relative to its peak. TV-L1 reweighs the
    // data term the same way: |r| ~ r^2 / |r|.
    for (int outer = 0; outer < options.tv_reweight_iterations; ++outer) {
      if (l1) {
        const cv::Mat res = problem.Forward(k) - t_valid;
        const double rms = std::sqrt(cv::norm(res, cv::NORM_L2SQR) / std::max<double>(1.0, double(res.total())));
        const double eps_r = options.l1_epsilon * std::max(rms, 1e-12);
        cv::Mat mag;
        cv::sqrt(res.mul(res) + eps_r * eps_r, mag);
        wd = 1.0 / mag;
        // Mean 1: mu keeps its meaning relative to the L2 data term.
        wd *= 1.0 / std::max(cv::mean(wd)[0], 1e-300);
      }
      double peak = 0;
      cv::minMaxLoc(cv::abs(k), nullptr, &peak);
      const double eps = options.tv_epsilon * std::max(peak, 1e-12);
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          const float gx = x + 1 < n ? k.at<float>(y, x + 1) - k.at<float>(y, x) : 0.0f;
          const float gy = y + 1 < n ? k.at<float>(y + 1, x) - k.at<float>(y, x) : 0.0f;
          const double w = 1.0 / std::sqrt(double(gx) * gx + double(gy) * gy + eps * eps);
          // Scaled so the weights average to 1 at the current solution: mu keeps its meaning.
          wx.at<float>(y, x) = wy.at<float>(y, x) = static_cast<float>(w * peak);
        }
      // Warm-started from the previous iterate, which the reweighting only nudges: a quarter of
      // the iterations of the first solve is enough and keeps TV / TV-L1 calibrations within a
      // few times the Tikhonov one.
      SolveCg(problem, t_valid, wd, mu, wx, wy, std::max(25, options.max_cg_iterations / 4), options.cg_tolerance, k);
    }
  }
  if (!cv::checkRange(k)) return Status::Internal("integral psf: solver diverged");
  IntegralPsf out;
  out.kernel = k;
  out.regularisation = options.regularisation;
  out.regularisation_weight = options.regularisation_weight;
  out.integral_noise_sigma = options.integral_noise_sigma;
  out.integral_rms_error = RmsDiff(i_int(problem.valid()), t_valid);
  out.restored_rms_error = RmsDiff(problem.Forward(k), t_valid);
  return out;
}

}  // namespace inspection
