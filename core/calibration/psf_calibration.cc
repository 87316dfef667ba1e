// PSF at several defocus steps (thesis 4.3.3) and the projector influence radius sigma_p
// (thesis 5.2.1, Fig. 5.9): averaged sub-pixel-aligned dot patches, moments, radial profile.
#include "core/calibration/psf_calibration.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <string>

namespace inspection {

Status PsfCalibration::Validate() const {
  if (steps.empty()) return Status::InvalidArgument("psf: no defocus step");
  for (size_t i = 0; i < steps.size(); ++i) {
    const auto& s = steps[i];
    const std::string name = "psf.steps[" + std::to_string(i) + "]";
    if (s.psf.type() != CV_32FC1 || s.psf.rows != s.psf.cols || s.psf.rows % 2 != 1) {
      return Status::InvalidArgument(name + ".psf must be an odd square CV_32FC1");
    }
    if (!std::isfinite(s.sigma_px) || !std::isfinite(s.defocus_um)) {
      return Status::InvalidArgument(name + ": sigma_px and defocus_um must be finite");
    }
    if (i > 0 && s.defocus_um <= steps[i - 1].defocus_um) {
      return Status::InvalidArgument(name + ".defocus_um must increase");
    }
  }
  if (!(influence_radius_px > 0)) return Status::InvalidArgument("psf.influence_radius_px must be > 0");
  return Status::Ok();
}

const PsfAtDefocus* PsfCalibration::Focused() const {
  const PsfAtDefocus* best = nullptr;
  for (const auto& s : steps)
    if (!best || std::abs(s.defocus_um) < std::abs(best->defocus_um)) best = &s;
  return best;
}

Status PsfOptions::Validate() const {
  if (patch_radius_px < 2) return Status::InvalidArgument("patch_radius_px must be >= 2");
  if (!(influence_fraction > 0 && influence_fraction < 1)) {
    return Status::InvalidArgument("influence_fraction must lie in (0, 1)");
  }
  return Status::Ok();
}

double PsfSigmaPx(const cv::Mat& psf) {
  const int r = psf.rows / 2;
  double window = r;
  double sigma = 0;
  for (int it = 0; it < 8; ++it) {
    double m0 = 0, m2 = 0;
    for (int y = 0; y < psf.rows; ++y)
      for (int x = 0; x < psf.cols; ++x) {
        const double d2 = double(x - r) * (x - r) + double(y - r) * (y - r);
        if (d2 > window * window) continue;
        const double v = std::max(0.0f, psf.at<float>(y, x));
        m0 += v;
        m2 += v * d2;
      }
    if (m0 <= 0) return 0.0;
    const double s = std::sqrt(m2 / (2 * m0));
    const double next = std::clamp(4.0 * s, 2.0, static_cast<double>(r));
    sigma = s;
    if (std::abs(next - window) < 1e-3) break;
    window = next;
  }
  return sigma;
}

StatusOr<PsfCalibration> EstimatePsf(const std::vector<PsfCapture>& captures, const PsfOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (captures.empty()) return Status::InvalidArgument("psf: no captures");
  const int r = options.patch_radius_px;
  const cv::Size patch_size(2 * r + 1, 2 * r + 1);
  PsfCalibration out;
  std::vector<double> radial_influence;  // per capture, in capture order
  for (size_t k = 0; k < captures.size(); ++k) {
    const PsfCapture& c = captures[k];
    if (c.signal.type() != CV_32FC1) {
      return Status::InvalidArgument("psf: captures[" + std::to_string(k) + "].signal must be CV_32FC1");
    }
    cv::Mat acc = cv::Mat::zeros(patch_size, CV_64FC1);
    int n = 0;
    // getRectSubPix interpolates bilinearly; at fraction t that is a [1-t, t] kernel of
    // variance t(1-t) per axis, added to the PSF's. Collected to correct sigma below.
    double resample_var = 0;
    std::vector<cv::Point2d> used;
    for (const cv::Point2d& p : c.dot_centres) {
      if (p.x < r + 1 || p.y < r + 1 || p.x > c.signal.cols - r - 2 || p.y > c.signal.rows - r - 2) continue;
      cv::Mat patch;
      cv::getRectSubPix(c.signal, patch_size, cv::Point2f(float(p.x), float(p.y)), patch, CV_32F);
      cv::Mat p64;
      patch.convertTo(p64, CV_64F);
      acc += p64;
      const double tx = p.x - std::floor(p.x), ty = p.y - std::floor(p.y);
      resample_var += 0.5 * (tx * (1 - tx) + ty * (1 - ty));
      used.push_back(p);
      ++n;
    }
    if (n == 0) {
      return Status::FailedPrecondition("psf: no dot fits inside the frame at defocus " + std::to_string(c.defocus_um) +
                                        " um");
    }
    acc /= n;
    resample_var /= n;
    // Residual background: median of the border ring.
    std::vector<double> ring;
    for (int i = 0; i < patch_size.width; ++i) {
      ring.push_back(acc.at<double>(0, i));
      ring.push_back(acc.at<double>(patch_size.height - 1, i));
      ring.push_back(acc.at<double>(i, 0));
      ring.push_back(acc.at<double>(i, patch_size.width - 1));
    }
    std::nth_element(ring.begin(), ring.begin() + ring.size() / 2, ring.end());
    const double background = ring[ring.size() / 2];
    acc -= background;
    const double total = cv::sum(acc)[0];
    if (!(total > 0)) {
      return Status::FailedPrecondition("psf: no light in the dot patches at defocus " + std::to_string(c.defocus_um) +
                                        " um");
    }
    PsfAtDefocus s;
    s.defocus_um = c.defocus_um;
    acc.convertTo(s.psf, CV_32F, 1.0 / total);
    const double sigma = PsfSigmaPx(s.psf);
    s.sigma_px = std::sqrt(std::max(sigma * sigma - resample_var, 0.0));
    s.dot_count = n;
    // Radial profile at exact sub-pixel distances from every dot centre (no resampling blur),
    // for sigma_p of the focused step.
    {
      const double bin = 0.25;
      const int nb = static_cast<int>(r / bin) + 1;
      std::vector<double> sum(nb, 0.0), cnt(nb, 0.0);
      for (const cv::Point2d& p : used) {
        const int cx = static_cast<int>(std::lround(p.x)), cy = static_cast<int>(std::lround(p.y));
        for (int y = cy - r; y <= cy + r; ++y)
          for (int x = cx - r; x <= cx + r; ++x) {
            const double d = std::hypot(x - p.x, y - p.y);
            const int b = static_cast<int>(d / bin);
            if (b >= nb) continue;
            sum[b] += c.signal.at<float>(y, x) - background;
            cnt[b] += 1;
          }
      }
      double peak_sum = 0, peak_cnt = 0;
      for (int b = 0; b < 2; ++b) {
        peak_sum += sum[b];
        peak_cnt += cnt[b];
      }
      radial_influence.push_back(0.0);
      if (peak_cnt > 0 && peak_sum > 0) {
        const double limit = options.influence_fraction * peak_sum / peak_cnt;
        double prev_r = 0.25, prev_v = peak_sum / peak_cnt;
        radial_influence.back() = r;
        for (int b = 2; b < nb; ++b) {
          if (cnt[b] == 0) continue;
          const double rr = (b + 0.5) * bin, v = sum[b] / cnt[b];
          if (v <= limit) {
            radial_influence.back() = prev_v > v ? prev_r + (rr - prev_r) * (prev_v - limit) / (prev_v - v) : rr;
            break;
          }
          prev_r = rr;
          prev_v = v;
        }
      }
    }
    out.steps.push_back(std::move(s));
  }
  // sigma_p from the capture closest to focus (before sorting, indices match captures).
  size_t focused = 0;
  for (size_t k = 1; k < out.steps.size(); ++k)
    if (std::abs(out.steps[k].defocus_um) < std::abs(out.steps[focused].defocus_um)) focused = k;
  out.influence_radius_px = radial_influence[focused];
  std::sort(out.steps.begin(), out.steps.end(),
            [](const PsfAtDefocus& a, const PsfAtDefocus& b) { return a.defocus_um < b.defocus_um; });
  for (size_t i = 1; i < out.steps.size(); ++i) {
    if (out.steps[i].defocus_um == out.steps[i - 1].defocus_um) {
      return Status::InvalidArgument("psf: two captures share defocus " + std::to_string(out.steps[i].defocus_um));
    }
  }
  return out;
}

}  // namespace inspection
