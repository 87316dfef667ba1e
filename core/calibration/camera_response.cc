// Camera response function (thesis 3.2.1 eq. 3.38-3.44, 4.3.1 eq. 4.3-4.5): Debevec-Malik
// weighted least squares with a second-derivative smoothness term, solved through CHOLMOD.
#include "core/calibration/camera_response.h"

#include <Eigen/CholmodSupport>
#include <Eigen/Sparse>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

namespace inspection {

Status CameraResponseFunction::Validate() const {
  if (levels < 2) return Status::InvalidArgument("camera_response.levels must be >= 2");
  if (static_cast<int>(log_exposure.size()) != levels) {
    return Status::InvalidArgument("camera_response.log_exposure has " + std::to_string(log_exposure.size()) +
                                   " entries, expected " + std::to_string(levels));
  }
  for (int z = 0; z < levels; ++z) {
    if (!std::isfinite(log_exposure[z])) {
      return Status::InvalidArgument("camera_response.log_exposure[" + std::to_string(z) + "] is not finite");
    }
    if (z > 0 && log_exposure[z] < log_exposure[z - 1]) {
      return Status::InvalidArgument("camera_response.log_exposure decreases at grey " + std::to_string(z));
    }
  }
  return Status::Ok();
}

double CameraResponseFunction::LogExposure(double z) const {
  if (log_exposure.empty()) return 0.0;
  z = std::clamp(z, 0.0, static_cast<double>(levels - 1));
  const int z0 = std::min(static_cast<int>(z), levels - 2);
  const double t = z - z0;
  return (1.0 - t) * log_exposure[z0] + t * log_exposure[z0 + 1];
}

double CameraResponseFunction::GreyForLogExposure(double x) const {
  if (log_exposure.empty()) return 0.0;
  if (x <= log_exposure.front()) return 0.0;
  if (x >= log_exposure.back()) return levels - 1;
  // First level whose crf exceeds x; crf is non-decreasing.
  const auto it = std::upper_bound(log_exposure.begin(), log_exposure.end(), x);
  const int z1 = static_cast<int>(it - log_exposure.begin());
  const int z0 = z1 - 1;
  const double d = log_exposure[z1] - log_exposure[z0];
  return d > 0 ? z0 + (x - log_exposure[z0]) / d : z0;
}

cv::Mat CameraResponseFunction::Radiance(const cv::Mat& z, double exposure_us) const {
  // Lookup table exp(crf(z)) / dt, then one pass over the image.
  std::vector<float> lut(levels);
  for (int i = 0; i < levels; ++i) lut[i] = static_cast<float>(std::exp(log_exposure[i]) / exposure_us);
  cv::Mat out(z.size(), CV_32FC1);
  for (int y = 0; y < z.rows; ++y) {
    float* o = out.ptr<float>(y);
    if (z.depth() == CV_8U) {
      const uint8_t* p = z.ptr<uint8_t>(y);
      for (int x = 0; x < z.cols; ++x) o[x] = lut[std::min<int>(p[x], levels - 1)];
    } else {
      const uint16_t* p = z.ptr<uint16_t>(y);
      for (int x = 0; x < z.cols; ++x) o[x] = lut[std::min<int>(p[x], levels - 1)];
    }
  }
  return out;
}

double DebevecWeight(int z, int levels) {
  const int z_min = 0, z_max = levels - 1;
  return 2 * z <= z_min + z_max ? z - z_min : z_max - z;
}

Status CameraResponseOptions::Validate() const {
  if (!(smoothness_lambda >= 0.0)) return Status::InvalidArgument("smoothness_lambda must be >= 0");
  if (levels != 256 && levels != 1024 && levels != 4096 && levels != 65536) {
    return Status::InvalidArgument("levels must be 256, 1024, 4096 or 65536");
  }
  if (sample_pixel_count < 2) return Status::InvalidArgument("sample_pixel_count must be >= 2");
  return Status::Ok();
}

StatusOr<CameraResponseFunction> SolveCameraResponse(const std::vector<std::vector<int>>& z_in,
                                                     const std::vector<double>& exposure_us,
                                                     const CameraResponseOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  const int levels = options.levels;
  const int p = static_cast<int>(exposure_us.size());
  if (p < 2) return Status::InvalidArgument("exposure_us: need at least 2 images");
  for (int j = 0; j < p; ++j) {
    if (!(exposure_us[j] > 0)) {
      return Status::InvalidArgument("exposure_us[" + std::to_string(j) + "] must be > 0");
    }
  }
  // Samples whose every observation has zero weight (always black or saturated) carry no
  // information and would make the normal equations singular: drop them.
  std::vector<const std::vector<int>*> samples;
  for (size_t i = 0; i < z_in.size(); ++i) {
    if (static_cast<int>(z_in[i].size()) != p) {
      return Status::InvalidArgument("z[" + std::to_string(i) + "] has " + std::to_string(z_in[i].size()) +
                                     " values, expected " + std::to_string(p));
    }
    double wsum = 0;
    for (int v : z_in[i]) {
      if (v < 0 || v >= levels) {
        return Status::InvalidArgument("z[" + std::to_string(i) + "] holds grey " + std::to_string(v) + " outside 0.." +
                                       std::to_string(levels - 1));
      }
      wsum += DebevecWeight(v, levels);
    }
    if (wsum > 0) samples.push_back(&z_in[i]);
  }
  const int n = static_cast<int>(samples.size());
  if (n < 2) return Status::InvalidArgument("z: fewer than 2 sample pixels with usable grey values");

  // Unknowns: crf(0..levels-1), then ln E_i for every sample. Rows of eq. 4.4 (weighted):
  //   w(Z_ij) * (crf(Z_ij) - ln E_i) = w(Z_ij) * ln dt_j
  //   crf(levels/2) = 0                                        (gauge, eq. 3.40)
  //   lambda * w(z) * (crf(z-1) - 2 crf(z) + crf(z+1)) = 0     (smoothness, eq. 3.39)
  const int unknowns = levels + n;
  std::vector<Eigen::Triplet<double>> trip;
  std::vector<double> rhs;
  trip.reserve(static_cast<size_t>(n) * p * 2 + levels * 3);
  int row = 0;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < p; ++j) {
      const int zij = (*samples[i])[j];
      const double w = DebevecWeight(zij, levels);
      if (w <= 0) continue;
      trip.emplace_back(row, zij, w);
      trip.emplace_back(row, levels + i, -w);
      rhs.push_back(w * std::log(exposure_us[j]));
      ++row;
    }
  }
  const int data_rows = row;
  trip.emplace_back(row, levels / 2, 1.0);
  rhs.push_back(0.0);
  ++row;
  // lambda is defined on the 8-bit scale. With L levels, crf'' per level shrinks as (256/L)^2,
  // the weights grow as L/256 and there are L/256 times more smoothness rows, so the row weight
  // lambda (L/256)^1.5 keeps the balance of eq. 4.4 independent of the bit depth.
  const double lambda = options.smoothness_lambda * std::pow(levels / 256.0, 1.5);
  for (int zz = 1; zz < levels - 1; ++zz) {
    const double w = lambda * DebevecWeight(zz, levels);
    trip.emplace_back(row, zz - 1, w);
    trip.emplace_back(row, zz, -2 * w);
    trip.emplace_back(row, zz + 1, w);
    rhs.push_back(0.0);
    ++row;
  }
  Eigen::SparseMatrix<double> a(row, unknowns);
  a.setFromTriplets(trip.begin(), trip.end());
  const Eigen::Map<const Eigen::VectorXd> b(rhs.data(), row);
  Eigen::SparseMatrix<double> ata = a.transpose() * a;
  // Levels that no sample hit and no smoothness row constrains (lambda == 0) leave the system
  // singular; a tiny ridge keeps it solvable without moving constrained entries measurably.
  for (int k = 0; k < levels; ++k) ata.coeffRef(k, k) += 1e-10;
  const Eigen::VectorXd atb = a.transpose() * b;
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>> solver;
  solver.compute(ata);
  if (solver.info() != Eigen::Success) {
    return Status::InvalidArgument(
        "camera response: normal equations are singular (too few "
        "distinct grey values or exposures)");
  }
  const Eigen::VectorXd x = solver.solve(atb);
  if (solver.info() != Eigen::Success || !x.allFinite()) {
    return Status::Internal("camera response: CHOLMOD solve failed");
  }

  CameraResponseFunction r;
  r.levels = levels;
  r.smoothness_lambda = options.smoothness_lambda;
  r.sample_pixel_count = n;
  r.image_count = p;
  r.log_exposure.assign(x.data(), x.data() + levels);
  // Data residual (before the monotone clean-up below).
  const Eigen::VectorXd res = (a * x - b).head(data_rows);
  double wsum2 = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < p; ++j) wsum2 += std::pow(DebevecWeight((*samples[i])[j], levels), 2);
  r.fit_rms_residual = wsum2 > 0 ? std::sqrt(res.squaredNorm() / wsum2) : 0.0;
  // crf is monotonic by physics (thesis 3.2.1); noise in the barely weighted extremes can make
  // the fit dip by a fraction of a percent. A running maximum restores an invertible curve.
  for (int k = 1; k < levels; ++k) r.log_exposure[k] = std::max(r.log_exposure[k], r.log_exposure[k - 1]);
  // The gauge row is one equation among many; make it exact (a shift leaves eq. 4.4 unchanged).
  const double offset = r.log_exposure[levels / 2];
  for (double& v : r.log_exposure) v -= offset;
  return r;
}

namespace {

int PixelAt(const cv::Mat& m, int idx) { return m.depth() == CV_8U ? m.ptr<uint8_t>()[idx] : m.ptr<uint16_t>()[idx]; }

Status CheckSeries(const std::vector<cv::Mat>& images, const std::vector<double>& exposure_us) {
  if (images.size() != exposure_us.size()) {
    return Status::InvalidArgument("images and exposure_us differ in length");
  }
  if (images.size() < 2) return Status::InvalidArgument("images: need at least 2");
  for (size_t j = 0; j < images.size(); ++j) {
    const cv::Mat& m = images[j];
    if (m.empty() || m.channels() != 1 || (m.depth() != CV_8U && m.depth() != CV_16U)) {
      return Status::InvalidArgument("images[" + std::to_string(j) + "] must be CV_8UC1 or CV_16UC1");
    }
    if (m.size() != images[0].size() || m.depth() != images[0].depth()) {
      return Status::InvalidArgument("images[" + std::to_string(j) + "] differs in size or depth from images[0]");
    }
    if (!m.isContinuous()) return Status::InvalidArgument("images[" + std::to_string(j) + "] is not continuous");
    if (!(exposure_us[j] > 0)) return Status::InvalidArgument("exposure_us[" + std::to_string(j) + "] must be > 0");
  }
  return Status::Ok();
}

}  // namespace

StatusOr<CameraResponseFunction> EstimateCameraResponse(const std::vector<cv::Mat>& images,
                                                        const std::vector<double>& exposure_us,
                                                        const CameraResponseOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  INSPECT_RETURN_IF_ERROR(CheckSeries(images, exposure_us));
  // Reference: the image of median exposure. Candidates on a regular grid (at most ~40000),
  // sorted by reference grey; samples are taken at evenly spaced grey targets (thesis 3.2.1:
  // "evenly distributed between Zmin and Zmax"), falling back to evenly spaced ranks.
  std::vector<size_t> order(exposure_us.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return exposure_us[a] < exposure_us[b]; });
  const cv::Mat& ref = images[order[order.size() / 2]];
  const int total = ref.rows * ref.cols;
  const int stride = std::max(1, static_cast<int>(std::sqrt(total / 40000.0)));
  std::vector<std::pair<int, int>> cand;  // (grey, index)
  for (int y = stride / 2; y < ref.rows; y += stride)
    for (int x = stride / 2; x < ref.cols; x += stride) {
      const int idx = y * ref.cols + x;
      cand.emplace_back(PixelAt(ref, idx), idx);
    }
  std::sort(cand.begin(), cand.end());
  const int want = std::min<int>(options.sample_pixel_count, static_cast<int>(cand.size()));
  std::vector<int> picked;
  std::vector<char> used(cand.size(), 0);
  const double g0 = cand.front().first, g1 = cand.back().first;
  for (int k = 0; k < want; ++k) {
    size_t pos;
    if (g1 > g0) {
      const double target = g0 + (g1 - g0) * (k + 0.5) / want;
      pos = std::lower_bound(cand.begin(), cand.end(), std::make_pair(static_cast<int>(std::lround(target)), -1)) -
            cand.begin();
      pos = std::min(pos, cand.size() - 1);
      // Distinct pixels: walk to the next unused candidate.
      size_t q = pos;
      while (q < cand.size() && used[q]) ++q;
      if (q == cand.size()) {
        q = pos;
        while (q > 0 && used[q]) --q;
      }
      pos = q;
    } else {
      pos = static_cast<size_t>((k + 0.5) * cand.size() / want);
    }
    if (used[pos]) continue;
    used[pos] = 1;
    picked.push_back(cand[pos].second);
  }
  std::vector<std::vector<int>> z(picked.size(), std::vector<int>(images.size()));
  for (size_t i = 0; i < picked.size(); ++i)
    for (size_t j = 0; j < images.size(); ++j) z[i][j] = PixelAt(images[j], picked[i]);
  return SolveCameraResponse(z, exposure_us, options);
}

StatusOr<cv::Mat> MergeRadiance(const std::vector<cv::Mat>& images, const std::vector<double>& exposure_us,
                                const CameraResponseFunction& response) {
  INSPECT_RETURN_IF_ERROR(CheckSeries(images, exposure_us));
  INSPECT_RETURN_IF_ERROR(response.Validate());
  const int levels = response.levels;
  const int total = images[0].rows * images[0].cols;
  cv::Mat out(images[0].size(), CV_32FC1);
  float* o = out.ptr<float>();
  for (int idx = 0; idx < total; ++idx) {
    double num = 0, den = 0;
    int best = 0;
    double best_dist = 1e30;
    for (size_t j = 0; j < images.size(); ++j) {
      const int z = std::min(PixelAt(images[j], idx), levels - 1);
      const double w = DebevecWeight(z, levels);
      const double le = response.log_exposure[z] - std::log(exposure_us[j]);
      num += w * le;
      den += w;
      const double dist = std::abs(z - levels / 2.0);
      if (dist < best_dist) {
        best_dist = dist;
        best = static_cast<int>(j);
      }
    }
    if (den > 0) {
      o[idx] = static_cast<float>(std::exp(num / den));
    } else {
      const int z = std::min(PixelAt(images[best], idx), levels - 1);
      o[idx] = static_cast<float>(std::exp(response.log_exposure[z]) / exposure_us[best]);
    }
  }
  return out;
}

}  // namespace inspection
