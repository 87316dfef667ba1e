// Radiometric compensation (thesis 5.1, eq. 5.5-5.6, 5.11, 5.12): reflectance estimate (ratio of
// local means), desired scene radiance and the projector irradiance solved with LSCG on A U.
#include "core/illumination/compensation.h"

#include <Eigen/IterativeLinearSolvers>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

namespace inspection {

Status CompensationOptions::Validate() const {
  if (pattern_cell_px < 1 || pattern_cell_px > 32) return Status::InvalidArgument("pattern_cell_px must be in [1, 32]");
  if (camera_bin_px < 1 || camera_bin_px > 16) return Status::InvalidArgument("camera_bin_px must be in [1, 16]");
  if (solver_iterations < 1 || solver_iterations > 1000) {
    return Status::InvalidArgument("solver_iterations must be in [1, 1000]");
  }
  if (!(solver_tolerance > 0 && solver_tolerance < 1))
    return Status::InvalidArgument("solver_tolerance must be in (0, 1)");
  if (!(min_lit_fraction >= 0 && min_lit_fraction < 1))
    return Status::InvalidArgument("min_lit_fraction must be in [0, 1)");
  if (!(saturated_reflectance_factor >= 1)) return Status::InvalidArgument("saturated_reflectance_factor must be >= 1");
  if (reflectance_window_px < 0 || reflectance_window_px > 63 ||
      (reflectance_window_px > 0 && reflectance_window_px % 2 == 0)) {
    return Status::InvalidArgument("reflectance_window_px must be 0 (automatic) or odd in [1, 63]");
  }
  if (!(texture_period_camera_px >= 0 && texture_period_camera_px <= 63)) {
    return Status::InvalidArgument("texture_period_camera_px must be in [0, 63]");
  }
  return Status::Ok();
}

namespace {
// Bilinear weights of fine coordinate x on a coarse grid with spacing s and n nodes.
inline void Bilinear(int x, int s, int n, int& i0, int& i1, float& w1) {
  const float t = float(x) / float(s);
  i0 = std::min(int(t), n - 1);
  i1 = std::min(i0 + 1, n - 1);
  w1 = (i1 == i0) ? 0.0f : t - float(i0);
}

// The odd number nearest to x (ties go down), at least 1 and at most 63.
int NearestOdd(double x) {
  const int n = int(std::lround(x));
  const int odd = n % 2 != 0 ? n : (x > double(n) ? n + 1 : n - 1);
  return std::clamp(odd, 1, 63);
}
}  // namespace

double CameraPxPerProjectorPx(const ScatterMatrix& scatter) {
  const Eigen::SparseMatrix<float, Eigen::ColMajor, int>& a = scatter.a;
  std::vector<char> lit(size_t(a.rows()), 0);
  long projector_px = 0;
  for (int k = 0; k < a.outerSize(); ++k) {
    bool any = false;
    for (Eigen::SparseMatrix<float, Eigen::ColMajor, int>::InnerIterator it(a, k); it; ++it) {
      if (it.value() > 0) {
        lit[size_t(it.row())] = 1;
        any = true;
      }
    }
    projector_px += any;
  }
  const long camera_px = long(std::count(lit.begin(), lit.end(), 1));
  return projector_px > 0 ? std::sqrt(double(camera_px) / double(projector_px)) : 0.0;
}

StatusOr<std::unique_ptr<Compensator>> Compensator::Create(const CameraResponseFunction& crf,
                                                           const ProjectorResponseFunction& prf,
                                                           const ScatterMatrix& scatter,
                                                           const CompensationOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  INSPECT_RETURN_IF_ERROR(crf.Validate().WithContext("camera response"));
  INSPECT_RETURN_IF_ERROR(prf.Validate().WithContext("projector response"));
  if (scatter.a.rows() != scatter.camera_size.area() || scatter.a.cols() != scatter.projector_size.area() ||
      scatter.black_radiance.size() != scatter.camera_size || scatter.black_radiance.type() != CV_32FC1) {
    return Status::InvalidArgument("scatter matrix sizes disagree with its camera/projector size");
  }
  std::unique_ptr<Compensator> c(new Compensator());
  c->crf_ = &crf;
  c->prf_ = &prf;
  c->scatter_ = &scatter;
  c->options_ = options;
  const int s = options.pattern_cell_px;
  const cv::Size p = scatter.projector_size;
  c->coarse_size_ = cv::Size((p.width - 1) / s + 1 + ((p.width - 1) % s ? 1 : 0),
                             (p.height - 1) / s + 1 + ((p.height - 1) % s ? 1 : 0));
  // U: projector px x coarse nodes, 4 bilinear weights per row.
  const cv::Size cs = c->coarse_size_;
  std::vector<Eigen::Triplet<float, int>> t;
  t.reserve(size_t(p.area()) * 4);
  for (int v = 0; v < p.height; ++v) {
    int y0, y1;
    float wy;
    Bilinear(v, s, cs.height, y0, y1, wy);
    for (int u = 0; u < p.width; ++u) {
      int x0, x1;
      float wx;
      Bilinear(u, s, cs.width, x0, x1, wx);
      const int row = v * p.width + u;
      const float w[4] = {(1 - wx) * (1 - wy), wx * (1 - wy), (1 - wx) * wy, wx * wy};
      const int col[4] = {y0 * cs.width + x0, y0 * cs.width + x1, y1 * cs.width + x0, y1 * cs.width + x1};
      for (int k = 0; k < 4; ++k) {
        if (w[k] > 0) t.emplace_back(row, col[k], w[k]);
      }
    }
  }
  Eigen::SparseMatrix<float, Eigen::ColMajor, int> u(p.area(), cs.area());
  u.setFromTriplets(t.begin(), t.end());  // duplicates (clamped edges) are summed
  // B: binned camera rows x camera pixels (sums).
  const int bin = options.camera_bin_px;
  const cv::Size cam = scatter.camera_size;
  c->bin_size_ = cv::Size((cam.width + bin - 1) / bin, (cam.height + bin - 1) / bin);
  std::vector<Eigen::Triplet<float, int>> tb;
  tb.reserve(size_t(cam.area()));
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x)
      tb.emplace_back((y / bin) * c->bin_size_.width + x / bin, y * cam.width + x, 1.0f);
  }
  Eigen::SparseMatrix<float, Eigen::ColMajor, int> bm(c->bin_size_.area(), cam.area());
  bm.setFromTriplets(tb.begin(), tb.end());
  Eigen::SparseMatrix<float, Eigen::ColMajor, int> ba = bm * scatter.a;
  c->au_ = (ba * u).pruned();
  c->solver_ = std::make_unique<Eigen::LeastSquaresConjugateGradient<Sparse>>();
  c->solver_->setMaxIterations(options.solver_iterations);
  c->solver_->setTolerance(float(options.solver_tolerance));
  c->solver_->compute(c->au_);
  if (options.reflectance_window_px > 0) {
    c->reflectance_window_px_ = options.reflectance_window_px;
  } else {
    const double grid_period_px = 2.0 * options.pattern_cell_px * CameraPxPerProjectorPx(scatter);
    c->reflectance_window_px_ = NearestOdd(std::max(grid_period_px, options.texture_period_camera_px));
  }
  const int top = crf.levels - 1;
  c->exposure_table_.resize(size_t(top) * 16 + 2);
  for (size_t k = 0; k < c->exposure_table_.size(); ++k) {
    c->exposure_table_[k] = float(std::exp(crf.LogExposure(std::min(double(k) / 16.0, double(top)))));
  }
  for (int k = 0; k <= 4096; ++k) {
    c->inverse_prf_[k] = cv::saturate_cast<uint8_t>(prf.GreyForIrradiance(double(k) / 4096.0));
  }
  return c;
}

Eigen::VectorXf Compensator::Downsample(const cv::Mat& irradiance) const {
  // Coarse node value = fine value at the node (the grid is aligned with pixel 0).
  const int s = options_.pattern_cell_px;
  const cv::Size cs = coarse_size_;
  Eigen::VectorXf c(cs.area());
  const float black = float(scatter_->projector_black_irradiance);
  for (int y = 0; y < cs.height; ++y) {
    const int v = std::min(y * s, irradiance.rows - 1);
    const float* row = irradiance.ptr<float>(v);
    for (int x = 0; x < cs.width; ++x) c[y * cs.width + x] = row[std::min(x * s, irradiance.cols - 1)] - black;
  }
  return c;
}

cv::Mat Compensator::Upsample(const Eigen::VectorXf& c) const {
  const int s = options_.pattern_cell_px;
  const cv::Size cs = coarse_size_;
  const cv::Size p = scatter_->projector_size;
  cv::Mat out(p, CV_32FC1);
  const float black = float(scatter_->projector_black_irradiance);
  for (int v = 0; v < p.height; ++v) {
    int y0, y1;
    float wy;
    Bilinear(v, s, cs.height, y0, y1, wy);
    float* o = out.ptr<float>(v);
    for (int u = 0; u < p.width; ++u) {
      int x0, x1;
      float wx;
      Bilinear(u, s, cs.width, x0, x1, wx);
      const float a = c[y0 * cs.width + x0] * (1 - wx) + c[y0 * cs.width + x1] * wx;
      const float b = c[y1 * cs.width + x0] * (1 - wx) + c[y1 * cs.width + x1] * wx;
      o[u] = std::clamp(a * (1 - wy) + b * wy + black, black, 1.0f);
    }
  }
  return out;
}

cv::Mat Compensator::PatternFor(const cv::Mat& irradiance) const {
  cv::Mat out(irradiance.size(), CV_8UC1);
  for (int y = 0; y < out.rows; ++y) {
    const float* e = irradiance.ptr<float>(y);
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int x = 0; x < out.cols; ++x) {
      const float k = std::clamp(e[x], 0.0f, 1.0f) * 4096.0f;
      o[x] = inverse_prf_[int(k + 0.5f)];
    }
  }
  return out;
}

StatusOr<cv::Mat> Compensator::SolveIrradiance(const cv::Mat& scene_radiance, const cv::Mat& warm_start,
                                               int* iterations, double* error) const {
  if (scene_radiance.type() != CV_32FC1 || scene_radiance.size() != scatter_->camera_size) {
    return Status::InvalidArgument("scene_radiance must be CV_32FC1 of the camera size");
  }
  if (warm_start.type() != CV_32FC1 || warm_start.size() != scatter_->projector_size) {
    return Status::InvalidArgument("warm_start must be CV_32FC1 of the projector size");
  }
  const Eigen::VectorXf c0 = Downsample(warm_start);
  // Rows without a constraint (NaN) take the prediction of the warm start, so they pull nothing.
  cv::Mat pred0;
  if (cv::checkRange(scene_radiance, true, nullptr, -1e30, 1e30) == false) {
    INSPECT_ASSIGN_OR_RETURN(pred0, scatter_->PredictRadiance(warm_start));
  }
  const int bin = options_.camera_bin_px;
  Eigen::VectorXf b = Eigen::VectorXf::Zero(au_.rows());
  for (int y = 0; y < scene_radiance.rows; ++y) {
    const float* s = scene_radiance.ptr<float>(y);
    const float* e = scatter_->black_radiance.ptr<float>(y);
    const float* p = pred0.empty() ? nullptr : pred0.ptr<float>(y);
    float* brow = b.data() + (y / bin) * bin_size_.width;
    for (int x = 0; x < scene_radiance.cols; ++x) {
      const float v = std::isfinite(s[x]) ? s[x] : p[x];
      brow[x / bin] += v - e[x];
    }
  }
  Eigen::VectorXf c = solver_->solveWithGuess(b, c0);
  if (iterations) *iterations = int(solver_->iterations());
  if (error) *error = double(solver_->error());
  for (Eigen::Index i = 0; i < c.size(); ++i) {
    if (!std::isfinite(c[i])) c[i] = c0[i];
  }
  return Upsample(c);
}

StatusOr<CompensationStep> Compensator::Step(const cv::Mat& irradiance, const cv::Mat& frame, double exposure_us,
                                             const cv::Mat& desired_grey, const cv::Mat& warm_start,
                                             ShownAt shown_at) const {
  if (frame.size() != scatter_->camera_size || (frame.type() != CV_8UC1 && frame.type() != CV_16UC1)) {
    return Status::InvalidArgument("frame must be CV_8UC1/CV_16UC1 of the camera size");
  }
  if (desired_grey.size() != scatter_->camera_size || desired_grey.type() != CV_32FC1) {
    return Status::InvalidArgument("desired_grey must be CV_32FC1 of the camera size");
  }
  if (!(exposure_us > 0)) return Status::InvalidArgument("exposure_us must be > 0");
  INSPECT_ASSIGN_OR_RETURN(cv::Mat predicted, scatter_->PredictRadiance(irradiance));
  const cv::Mat e_c = crf_->Radiance(frame, exposure_us);  // eq. 4.5
  double max_pred = 0;
  cv::minMaxLoc(predicted, nullptr, &max_pred);
  const float lit = float(options_.min_lit_fraction * max_pred);
  const int top = crf_->levels - 1;
  cv::Mat z;
  frame.convertTo(z, CV_32F);
  // Eq. 5.5 over the lit pixels: per pixel for the same z, else as a ratio of local means over
  // the reflectance window, sum E_c / sum A e_p (file comment in compensation.h).
  const bool same_z = shown_at == ShownAt::kSameZ;
  cv::Mat measured(frame.size(), CV_32FC1), predicted_lit(frame.size(), CV_32FC1);
  const float saturated_factor = same_z ? float(options_.saturated_reflectance_factor) : 1.0f;
  for (int y = 0; y < frame.rows; ++y) {
    const float* p = predicted.ptr<float>(y);
    const float* ec = e_c.ptr<float>(y);
    const float* zr = z.ptr<float>(y);
    float* m = measured.ptr<float>(y);
    float* q = predicted_lit.ptr<float>(y);
    for (int x = 0; x < frame.cols; ++x) {
      const bool is_lit = p[x] > lit;
      m[x] = is_lit ? (zr[x] >= float(top) ? ec[x] * saturated_factor : ec[x]) : 0.0f;
      q[x] = is_lit ? p[x] : 0.0f;
    }
  }
  if (!same_z && reflectance_window_px_ > 1) {
    const cv::Size w(reflectance_window_px_, reflectance_window_px_);
    cv::boxFilter(measured, measured, CV_32F, w, cv::Point(-1, -1), false, cv::BORDER_REFLECT);
    cv::boxFilter(predicted_lit, predicted_lit, CV_32F, w, cv::Point(-1, -1), false, cv::BORDER_REFLECT);
  }
  // Desired camera radiance per grey level (eq. 5.4 inverted) from the 1/16-grey table.
  const float inv_dt = float(1.0 / exposure_us);
  CompensationStep out;
  out.reflectance = cv::Mat(frame.size(), CV_32FC1);
  cv::Mat target(frame.size(), CV_32FC1);
  double err = 0;
  long n = 0;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int y = 0; y < frame.rows; ++y) {
    const float* p = predicted.ptr<float>(y);
    const float* m = measured.ptr<float>(y);
    const float* q = predicted_lit.ptr<float>(y);
    const float* zr = z.ptr<float>(y);
    const float* d = desired_grey.ptr<float>(y);
    float* r = out.reflectance.ptr<float>(y);
    float* t = target.ptr<float>(y);
    for (int x = 0; x < frame.cols; ++x) {
      if (!(p[x] > lit) || !(q[x] > 0)) {
        // Unlit: no reflectance estimate; the pixel keeps the radiance it has now, so it pulls
        // nothing (SolveIrradiance's NaN rule, without a second prediction A e_p).
        r[x] = nan;
        t[x] = p[x];
        continue;
      }
      const float refl = std::max(m[x] / q[x], 1e-6f);  // eq. 5.5
      r[x] = refl;
      const float g = std::clamp(d[x], 0.0f, float(top)) * 16.0f;
      const int k = int(g);
      const float f = g - float(k);
      const float want = (exposure_table_[k] * (1 - f) + exposure_table_[k + 1] * f) * inv_dt;
      t[x] = want / refl;  // eq. 5.6, scene radiance at unit reflectance
      err += std::abs(zr[x] - d[x]);
      ++n;
    }
  }
  out.mean_abs_error_grey = n ? err / double(n) : 0.0;
  INSPECT_ASSIGN_OR_RETURN(
      out.projector_irradiance,
      SolveIrradiance(target, warm_start.empty() ? irradiance : warm_start, &out.solver_iterations, &out.solver_error));
  out.pattern = PatternFor(out.projector_irradiance);
  return out;
}

StatusOr<cv::Mat> PredictIrradiance(const cv::Mat& current, const cv::Mat& previous, double lambda, double floor) {
  if (current.type() != CV_32FC1 || previous.type() != CV_32FC1 || current.size() != previous.size()) {
    return Status::InvalidArgument("current and previous irradiance must be CV_32FC1 of one size");
  }
  if (!std::isfinite(lambda) || lambda < 0) return Status::InvalidArgument("lambda must be >= 0");
  cv::Mat out = current + float(lambda) * (current - previous);
  cv::min(out, 1.0, out);
  cv::max(out, floor, out);
  return out;
}

}  // namespace inspection
