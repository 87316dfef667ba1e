// Step height (ISO 5436-1 type A style): common-slope or separate least-squares planes on two
// regions, height at the step, exact uncertainty of the linear estimate.
#include "core/metrology/step_height.h"

#include <cmath>

#include "core/metrology/form_removal.h"

namespace inspection {
namespace {

Status CheckMasks(const cv::Mat& depth_um, const cv::Mat& reference_mask, const cv::Mat& measured_mask,
                  double pixel_size_um) {
  if (depth_um.empty() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("depth map must be a non-empty CV_32FC1 image");
  }
  for (const auto& [name, m] : {std::pair<const char*, const cv::Mat*>{"reference region", &reference_mask},
                                {"measured region", &measured_mask}}) {
    if (m->type() != CV_8UC1 || m->size() != depth_um.size()) {
      return Status::InvalidArgument(std::string(name) + " mask must be CV_8UC1 of the depth map's size");
    }
  }
  if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um))
    return Status::InvalidArgument("pixel_size_um must be > 0");
  if (cv::countNonZero(reference_mask & measured_mask) > 0) {
    return Status::InvalidArgument("the reference and measured regions of a step height overlap");
  }
  return Status::Ok();
}

struct LabelledPoint {
  int row, col;
  double x, y, z;
  bool measured;
};

}  // namespace

const char* StepHeightFitName(StepHeightFit fit) {
  return fit == StepHeightFit::kCommonSlope ? "common_slope" : "separate_planes";
}

StatusOr<StepHeightFit> ParseStepHeightFit(const std::string& name) {
  if (name == "common_slope") return StepHeightFit::kCommonSlope;
  if (name == "separate_planes") return StepHeightFit::kSeparatePlanes;
  return Status::InvalidArgument("unknown step height fit '" + name + "' (common_slope, separate_planes)");
}

StatusOr<StepHeightResult> MeasureStepHeight(const cv::Mat& depth_um, const cv::Mat& reference_mask,
                                             const cv::Mat& measured_mask, double pixel_size_um,
                                             const StepHeightOptions& options, const DepthNoiseModel* noise) {
  INSPECT_RETURN_IF_ERROR(CheckMasks(depth_um, reference_mask, measured_mask, pixel_size_um));
  std::vector<LabelledPoint> pts;
  double cx[2] = {0, 0}, cy[2] = {0, 0};
  size_t count[2] = {0, 0};
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* z = depth_um.ptr<float>(row);
    const uint8_t* a = reference_mask.ptr<uint8_t>(row);
    const uint8_t* b = measured_mask.ptr<uint8_t>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (!(a[col] || b[col]) || !std::isfinite(z[col])) continue;
      const bool m = b[col] != 0;
      const double x = PixelCentreUm(col, pixel_size_um), y = PixelCentreUm(row, pixel_size_um);
      pts.push_back({row, col, x, y, double(z[col]), m});
      cx[m] += x;
      cy[m] += y;
      ++count[m];
    }
  }
  for (int k = 0; k < 2; ++k) {
    if (count[k] < 3) {
      return Status::FailedPrecondition(std::string(k ? "measured" : "reference") + " region has " +
                                        std::to_string(count[k]) + " measured pixels (a plane needs >= 3)");
    }
  }
  StepHeightResult res;
  res.reference_pixels = count[0];
  res.measured_pixels = count[1];
  res.evaluation_x_um = 0.5 * (cx[0] / count[0] + cx[1] / count[1]);
  res.evaluation_y_um = 0.5 * (cy[0] / count[0] + cy[1] / count[1]);
  const double ox = res.evaluation_x_um, oy = res.evaluation_y_um;
  cv::Mat weight = cv::Mat::zeros(depth_um.size(), CV_64F);  // d(vertical offset) / d(z(p))

  if (options.fit == StepHeightFit::kCommonSlope) {
    Eigen::Matrix4d n = Eigen::Matrix4d::Zero();
    Eigen::Vector4d bz = Eigen::Vector4d::Zero();
    const double z_ref = pts[0].z;
    for (const LabelledPoint& p : pts) {
      const Eigen::Vector4d b(1.0, p.measured ? 1.0 : 0.0, p.x - ox, p.y - oy);
      n += b * b.transpose();
      bz += b * (p.z - z_ref);
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(n, Eigen::EigenvaluesOnly);
    if (!(es.eigenvalues().minCoeff() > 1e-12 * es.eigenvalues().maxCoeff())) {
      return Status::FailedPrecondition("the two regions' pixels do not determine a common plane (all on one line)");
    }
    const Eigen::Matrix4d ninv = n.inverse();
    const Eigen::Vector4d par = ninv * bz;
    res.vertical_offset_um = par[1];
    res.slope_x = par[2];
    res.slope_y = par[3];
    double rss = 0.0;
    for (const LabelledPoint& p : pts) {
      const Eigen::Vector4d b(1.0, p.measured ? 1.0 : 0.0, p.x - ox, p.y - oy);
      const double r = p.z - z_ref - b.dot(par);
      rss += r * r;
      weight.at<double>(p.row, p.col) = ninv.row(1).dot(b);
    }
    res.residual_rms_um = std::sqrt(rss / double(pts.size()));
  } else {
    FormOptions plane;
    StatusOr<FormFit> ref = FitForm(depth_um, reference_mask, pixel_size_um, plane);
    if (!ref.ok()) return ref.status().WithContext("reference region");
    StatusOr<FormFit> mea = FitForm(depth_um, measured_mask, pixel_size_um, plane);
    if (!mea.ok()) return mea.status().WithContext("measured region");
    res.vertical_offset_um = mea->Evaluate(ox, oy) - ref->Evaluate(ox, oy);
    res.slope_x = ref->parameters[1];
    res.slope_y = ref->parameters[2];
    const double rss = ref->residual_rms_um * ref->residual_rms_um * double(ref->pixel_count) +
                       mea->residual_rms_um * mea->residual_rms_um * double(mea->pixel_count);
    res.residual_rms_um = std::sqrt(rss / double(ref->pixel_count + mea->pixel_count));
    // Height at (ox, oy) = g_m^T params_m - g_r^T params_r, each params = N^-1 J^T z.
    for (const auto& [fit, mask, sign] :
         {std::tuple<const FormFit*, const cv::Mat*, double>{&*mea, &measured_mask, 1.0},
          {&*ref, &reference_mask, -1.0}}) {
      double g[3];
      fit->ParameterGradient(ox, oy, g);
      const std::vector<cv::Mat> w = FormFitWeights(*fit, depth_um, *mask, pixel_size_um);
      for (int j = 0; j < 3; ++j) weight += sign * g[j] * w[j];
    }
  }
  const double cos_tilt = 1.0 / std::sqrt(1.0 + res.slope_x * res.slope_x + res.slope_y * res.slope_y);
  res.height_um = res.vertical_offset_um * cos_tilt;
  if (noise != nullptr) {
    INSPECT_ASSIGN_OR_RETURN(FunctionalCovariance cov, LinearFunctionalCovariance({weight}, depth_um, *noise));
    // The cosine (tilt known to ~1e-4 rad) only scales the offset; its own uncertainty is negligible.
    res.uncertainty = AnalyticBudget(cov, Eigen::VectorXd::Constant(1, cos_tilt));
  }
  return res;
}

}  // namespace inspection
