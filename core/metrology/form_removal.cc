// Least-squares form fits (ISO 25178-3 F-operator): plane and polynomial by normal equations in
// centred, scaled coordinates; sphere and cylinder by Levenberg-Marquardt on vertical residuals,
// started from a quadratic fit.
#include "core/metrology/form_removal.h"

#include <algorithm>
#include <cmath>

namespace inspection {
namespace {

struct Sample {
  double x, y, z;
};

int PolynomialTerms(int order) { return (order + 1) * (order + 2) / 2; }

// Monomials u^a v^b ordered by total order, then a descending: 1, u, v, u2, uv, v2, u3, ...
void Monomials(int order, double u, double v, double* out) {
  int k = 0;
  for (int total = 0; total <= order; ++total) {
    for (int a = total; a >= 0; --a) {
      out[k++] = std::pow(u, a) * std::pow(v, total - a);
    }
  }
}

std::vector<std::string> PolynomialNames(int order) {
  std::vector<std::string> names;
  for (int total = 0; total <= order; ++total) {
    for (int a = total; a >= 0; --a) {
      std::string name(1, 'c');  // built by appending: GCC 12 warns falsely (-Wrestrict) on "c" + string
      name += std::to_string(a);
      name += std::to_string(total - a);
      name += "_um";
      names.push_back(std::move(name));
    }
  }
  return names;
}

constexpr double kPi = 3.14159265358979323846;

// Smallest over largest eigenvalue of a symmetric positive semi-definite matrix scaled to unit
// diagonal: ~0 when the design does not determine the parameters.
double ReciprocalCondition(const Eigen::MatrixXd& ata) {
  const Eigen::VectorXd d = ata.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd scaled = d.asDiagonal() * ata * d.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(scaled, Eigen::EigenvaluesOnly);
  const double hi = es.eigenvalues().maxCoeff();
  return hi > 0 ? es.eigenvalues().minCoeff() / hi : 0.0;
}

// Model value and gradient for the nonlinear models, in coordinates relative to the origin.
// Returns false when the point lies outside the sphere's/cylinder's footprint (R^2 <= d^2).
bool NonlinearModel(FormModel model, int sign, const Eigen::VectorXd& p, double x, double y, double* value,
                    double* grad) {
  if (model == FormModel::kSphere) {
    const double dx = x - p[0], dy = y - p[1], r = p[3];
    const double q2 = r * r - dx * dx - dy * dy;
    if (!(q2 > 0.0)) return false;
    const double q = std::sqrt(q2);
    *value = p[2] + sign * q;
    if (grad) {
      grad[0] = sign * dx / q;
      grad[1] = sign * dy / q;
      grad[2] = 1.0;
      grad[3] = sign * r / q;
    }
    return true;
  }
  // Cylinder: p = (phi, offset, axis_z, axis_slope, R).
  const double c = std::cos(p[0]), s = std::sin(p[0]);
  const double t = x * c + y * s;          // along the axis
  const double d = -x * s + y * c - p[1];  // from the axis, in the image plane
  const double r = p[4];
  const double q2 = r * r - d * d;
  if (!(q2 > 0.0)) return false;
  const double q = std::sqrt(q2);
  *value = p[2] + p[3] * t + sign * q;
  if (grad) {
    grad[0] = p[3] * (d + p[1]) + sign * d * t / q;
    grad[1] = sign * d / q;
    grad[2] = 1.0;
    grad[3] = t;
    grad[4] = sign * r / q;
  }
  return true;
}

// Quadratic z = c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2 in origin-relative µm (for starts).
StatusOr<Eigen::VectorXd> FitQuadratic(const std::vector<Sample>& pts, double scale) {
  Eigen::MatrixXd ata = Eigen::MatrixXd::Zero(6, 6);
  Eigen::VectorXd atz = Eigen::VectorXd::Zero(6);
  double b[6];
  for (const Sample& s : pts) {
    Monomials(2, s.x / scale, s.y / scale, b);
    const Eigen::Map<Eigen::VectorXd> bv(b, 6);
    ata.selfadjointView<Eigen::Lower>().rankUpdate(bv);
    atz += bv * s.z;
  }
  ata = ata.selfadjointView<Eigen::Lower>();
  if (ReciprocalCondition(ata) < 1e-12) {
    return Status::FailedPrecondition("the region's pixels do not span a quadratic surface (too narrow a region)");
  }
  Eigen::VectorXd c = ata.ldlt().solve(atz);
  // Back to µm: u = x / scale.
  c[1] /= scale;
  c[2] /= scale;
  c[3] /= scale * scale;
  c[4] /= scale * scale;
  c[5] /= scale * scale;
  return c;
}

StatusOr<Eigen::VectorXd> SphereStart(const std::vector<Sample>& pts, double scale, int* sign) {
  // Paraboloid z = a + b x + c y + k (x^2 + y^2): the sphere's osculating paraboloid at the apex.
  Eigen::Matrix4d ata = Eigen::Matrix4d::Zero();
  Eigen::Vector4d atz = Eigen::Vector4d::Zero();
  for (const Sample& s : pts) {
    const double u = s.x / scale, v = s.y / scale;
    const Eigen::Vector4d b(1.0, u, v, u * u + v * v);
    ata += b * b.transpose();
    atz += b * s.z;
  }
  if (ReciprocalCondition(ata) < 1e-12) {
    return Status::FailedPrecondition("the region's pixels do not span a sphere (too narrow a region)");
  }
  const Eigen::Vector4d c = ata.ldlt().solve(atz);
  const double k = c[3] / (scale * scale), bx = c[1] / scale, by = c[2] / scale;
  if (!(std::abs(k) > 0.0)) return Status::FailedPrecondition("the region is flat: no sphere radius can be fitted");
  *sign = k < 0 ? 1 : -1;
  const double r = 1.0 / (2.0 * std::abs(k));
  const double x0 = -bx / (2.0 * k), y0 = -by / (2.0 * k);
  const double apex = c[0] - (bx * bx + by * by) / (4.0 * k);
  Eigen::VectorXd p(4);
  p << x0, y0, apex - *sign * r, r;
  return p;
}

StatusOr<Eigen::VectorXd> CylinderStart(const std::vector<Sample>& pts, double scale, int* sign) {
  INSPECT_ASSIGN_OR_RETURN(Eigen::VectorXd c, FitQuadratic(pts, scale));
  Eigen::Matrix2d h;
  h << 2 * c[3], c[4], c[4], 2 * c[5];
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(h);
  // The larger |eigenvalue| is the curvature across the axis; the axis runs along the other.
  const int across = std::abs(es.eigenvalues()[0]) > std::abs(es.eigenvalues()[1]) ? 0 : 1;
  const double kappa = es.eigenvalues()[across];
  if (!(std::abs(kappa) > 0.0))
    return Status::FailedPrecondition("the region is flat: no cylinder radius can be fitted");
  const Eigen::Vector2d axis = es.eigenvectors().col(1 - across);
  double phi = std::atan2(axis.y(), axis.x());
  if (phi > kPi / 2) phi -= kPi;
  if (phi <= -kPi / 2) phi += kPi;
  const Eigen::Vector2d along(std::cos(phi), std::sin(phi)), normal(-std::sin(phi), std::cos(phi));
  const Eigen::Vector2d grad(c[1], c[2]);
  *sign = kappa < 0 ? 1 : -1;
  const double r = 1.0 / std::abs(kappa);
  // Across the axis z ~ z(0) + (grad . n) d + kappa / 2 d^2: vertex at d* = -(grad . n) / kappa.
  const double dstar = -grad.dot(normal) / kappa;
  const double zvertex = c[0] + grad.dot(normal) * dstar + 0.5 * kappa * dstar * dstar;
  Eigen::VectorXd p(5);
  p << phi, dstar, zvertex - *sign * r, grad.dot(along), r;
  return p;
}

Status FitNonlinear(const std::vector<Sample>& pts, const FormOptions& options, FormFit* fit) {
  const double scale = fit->scale_um;
  INSPECT_ASSIGN_OR_RETURN(Eigen::VectorXd p, fit->model == FormModel::kSphere ? SphereStart(pts, scale, &fit->sign)
                                                                               : CylinderStart(pts, scale, &fit->sign));
  const int np = int(p.size());
  std::vector<double> g(np);
  // Sum of squared residuals at p, and the normal equations when wanted; false when a pixel lies
  // beyond the radius.
  auto evaluate = [&](const Eigen::VectorXd& q, double* rss, Eigen::MatrixXd* jtj, Eigen::VectorXd* jtr) {
    *rss = 0.0;
    if (jtj) {
      jtj->setZero(np, np);
      jtr->setZero(np);
    }
    for (const Sample& s : pts) {
      double v;
      if (!NonlinearModel(fit->model, fit->sign, q, s.x, s.y, &v, jtj ? g.data() : nullptr)) return false;
      const double r = s.z - v;
      *rss += r * r;
      if (jtj) {
        const Eigen::Map<Eigen::VectorXd> gv(g.data(), np);
        jtj->selfadjointView<Eigen::Lower>().rankUpdate(gv);
        *jtr += gv * r;
      }
    }
    if (jtj) *jtj = jtj->selfadjointView<Eigen::Lower>();
    return true;
  };
  // A start whose radius does not cover the region: grow the radius (keeping the apex) until it does.
  double rss = 0.0;
  Eigen::MatrixXd jtj;
  Eigen::VectorXd jtr;
  const int radius_index = np - 1;
  for (int k = 0; k < 60 && !evaluate(p, &rss, nullptr, nullptr); ++k) {
    const double grow = p[radius_index] * 0.5;
    p[radius_index] += grow;
    p[2] -= fit->sign * grow;
  }
  if (!evaluate(p, &rss, &jtj, &jtr)) {
    return Status::FailedPrecondition(std::string("no ") + FormModelName(fit->model) +
                                      " covers the region (the region reaches beyond any fitted radius)");
  }
  double lambda = 1e-3;
  bool converged = false;
  int it = 0;
  for (; it < options.max_iterations && !converged; ++it) {
    bool stepped = false;
    for (int tries = 0; tries < 30 && !stepped; ++tries) {
      Eigen::MatrixXd a = jtj;
      a.diagonal() += lambda * jtj.diagonal().cwiseMax(1e-300);
      const Eigen::VectorXd delta = a.ldlt().solve(jtr);
      const Eigen::VectorXd q = p + delta;
      double rss_new;
      if (q[radius_index] > 0.0 && delta.allFinite() && evaluate(q, &rss_new, nullptr, nullptr) && rss_new <= rss) {
        const double rel_change = (rss - rss_new) / std::max(rss, 1e-300);
        const double step_norm = std::abs(delta[radius_index]) / q[radius_index];
        p = q;
        stepped = true;
        lambda = std::max(lambda / 10.0, 1e-12);
        if (rel_change < 1e-12 || step_norm < 1e-12) converged = true;
        evaluate(p, &rss, &jtj, &jtr);
      } else {
        lambda *= 10.0;
      }
    }
    if (!stepped) converged = true;  // no step reduces the residual: at the minimum (to precision)
  }
  if (!converged) {
    return Status::FailedPrecondition(std::string(FormModelName(fit->model)) + " fit did not converge in " +
                                      std::to_string(options.max_iterations) + " iterations");
  }
  if (ReciprocalCondition(jtj) < 1e-14) {
    return Status::FailedPrecondition(std::string("the region's pixels do not determine the ") +
                                      FormModelName(fit->model) + " (too narrow or too flat a region)");
  }
  if (fit->model == FormModel::kCylinder) {
    // Keep phi in (-pi/2, pi/2]; turning the axis by pi flips t and d.
    auto wrap = [&](double shift) {
      p[0] += shift;
      p[1] = -p[1];
      p[3] = -p[3];
    };
    while (p[0] > kPi / 2) wrap(-kPi);
    while (p[0] <= -kPi / 2) wrap(kPi);
    double unused;
    evaluate(p, &unused, &jtj, &jtr);
  }
  if (fit->model == FormModel::kSphere) {  // centre to image coordinates
    p[0] += fit->origin_x_um;
    p[1] += fit->origin_y_um;
  }
  fit->iterations = it;
  fit->parameters = p;
  fit->normal_inverse = jtj.ldlt().solve(Eigen::MatrixXd::Identity(np, np));
  return Status::Ok();
}

}  // namespace

const char* FormModelName(FormModel model) {
  switch (model) {
    case FormModel::kPlane:
      return "plane";
    case FormModel::kPolynomial:
      return "polynomial";
    case FormModel::kSphere:
      return "sphere";
    case FormModel::kCylinder:
      return "cylinder";
  }
  return "unknown";
}

StatusOr<FormModel> ParseFormModel(const std::string& name) {
  for (FormModel m : {FormModel::kPlane, FormModel::kPolynomial, FormModel::kSphere, FormModel::kCylinder}) {
    if (name == FormModelName(m)) return m;
  }
  return Status::InvalidArgument("unknown form model '" + name + "' (plane, polynomial, sphere, cylinder)");
}

Status FormOptions::Validate() const {
  if (model == FormModel::kPolynomial && (polynomial_order < 1 || polynomial_order > 3)) {
    return Status::InvalidArgument("polynomial_order must be in 1..3, got " + std::to_string(polynomial_order));
  }
  if (max_iterations < 1 || max_iterations > 1000) {
    return Status::InvalidArgument("max_iterations must be in 1..1000, got " + std::to_string(max_iterations));
  }
  return Status::Ok();
}

double FormFit::Evaluate(double x_um, double y_um) const {
  // The sphere's centre is stored in image coordinates, every other model relative to the origin.
  const bool absolute = model == FormModel::kSphere;
  const double x = absolute ? x_um : x_um - origin_x_um, y = absolute ? y_um : y_um - origin_y_um;
  switch (model) {
    case FormModel::kPlane:
      return parameters[0] + parameters[1] * x + parameters[2] * y;
    case FormModel::kPolynomial: {
      double b[10];
      Monomials(polynomial_order, x / scale_um, y / scale_um, b);
      double z = 0.0;
      for (int k = 0; k < int(parameters.size()); ++k) z += parameters[k] * b[k];
      return z;
    }
    case FormModel::kSphere:
    case FormModel::kCylinder: {
      double v;
      if (!NonlinearModel(model, sign, parameters, x, y, &v, nullptr)) return std::nan("");
      return v;
    }
  }
  return std::nan("");
}

void FormFit::ParameterGradient(double x_um, double y_um, double* out) const {
  const bool absolute = model == FormModel::kSphere;
  const double x = absolute ? x_um : x_um - origin_x_um, y = absolute ? y_um : y_um - origin_y_um;
  switch (model) {
    case FormModel::kPlane:
      out[0] = 1.0;
      out[1] = x;
      out[2] = y;
      return;
    case FormModel::kPolynomial:
      Monomials(polynomial_order, x / scale_um, y / scale_um, out);
      return;
    case FormModel::kSphere:
    case FormModel::kCylinder: {
      double v;
      if (!NonlinearModel(model, sign, parameters, x, y, &v, out)) {
        for (int k = 0; k < int(parameters.size()); ++k) out[k] = std::nan("");
      }
      return;
    }
  }
}

int FormFit::ParameterIndex(const std::string& name) const {
  for (size_t k = 0; k < parameter_names.size(); ++k) {
    if (parameter_names[k] == name) return int(k);
  }
  return -1;
}

double FormFit::PlaneTiltDeg() const {
  if (model != FormModel::kPlane) return std::nan("");
  return std::atan(std::hypot(parameters[1], parameters[2])) * 180.0 / kPi;
}

StatusOr<FormFit> FitForm(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                          const FormOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.empty() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("depth map must be a non-empty CV_32FC1 image");
  }
  if (mask.type() != CV_8UC1 || mask.size() != depth_um.size()) {
    return Status::InvalidArgument("mask must be CV_8UC1 of the depth map's size");
  }
  if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um)) {
    return Status::InvalidArgument("pixel_size_um must be > 0");
  }
  // Pass 1: count, centroid and extent of the usable pixels (nothing stored: maps reach ~1e6 pixels).
  size_t count = 0;
  double sx = 0.0, sy = 0.0;
  int c0 = depth_um.cols, c1 = -1, r0 = depth_um.rows, r1 = -1;
  double z_ref = 0.0;  // first usable depth: sums of z - z_ref keep their precision
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* d = depth_um.ptr<float>(row);
    const uint8_t* m = mask.ptr<uint8_t>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (!m[col] || !std::isfinite(d[col])) continue;
      if (count == 0) z_ref = d[col];
      ++count;
      sx += col;
      sy += row;
      c0 = std::min(c0, col);
      c1 = std::max(c1, col);
      r0 = std::min(r0, row);
      r1 = std::max(r1, row);
    }
  }
  FormFit fit;
  fit.model = options.model;
  fit.polynomial_order = options.model == FormModel::kPolynomial ? options.polynomial_order : 1;
  int np = 0;
  switch (options.model) {
    case FormModel::kPlane:
      np = 3;
      fit.parameter_names = {"z0_um", "slope_x", "slope_y"};
      break;
    case FormModel::kPolynomial:
      np = PolynomialTerms(fit.polynomial_order);
      fit.parameter_names = PolynomialNames(fit.polynomial_order);
      break;
    case FormModel::kSphere:
      np = 4;
      fit.parameter_names = {"centre_x_um", "centre_y_um", "centre_z_um", "radius_um"};
      break;
    case FormModel::kCylinder:
      np = 5;
      fit.parameter_names = {"axis_angle_rad", "axis_offset_um", "axis_z_um", "axis_slope", "radius_um"};
      break;
  }
  if (count < size_t(np + 1)) {
    return Status::FailedPrecondition(std::string(FormModelName(options.model)) + " fit needs at least " +
                                      std::to_string(np + 1) + " measured pixels, the region has " +
                                      std::to_string(count));
  }
  const double n = double(count);
  fit.origin_x_um = PixelCentreUm(0, pixel_size_um) + sx / n * pixel_size_um;
  fit.origin_y_um = PixelCentreUm(0, pixel_size_um) + sy / n * pixel_size_um;
  fit.scale_um = 0.5 * std::max(c1 - c0 + 1, r1 - r0 + 1) * pixel_size_um;
  fit.pixel_count = count;
  // Visits the usable pixels with origin-relative coordinates.
  auto for_each = [&](auto&& f) {
    for (int row = r0; row <= r1; ++row) {
      const float* d = depth_um.ptr<float>(row);
      const uint8_t* m = mask.ptr<uint8_t>(row);
      const double y = PixelCentreUm(row, pixel_size_um) - fit.origin_y_um;
      for (int col = c0; col <= c1; ++col) {
        if (!m[col] || !std::isfinite(d[col])) continue;
        f(PixelCentreUm(col, pixel_size_um) - fit.origin_x_um, y, double(d[col]));
      }
    }
  };
  if (options.model == FormModel::kPlane || options.model == FormModel::kPolynomial) {
    // Pass 2: normal equations in plain arrays (upper triangle), the hot loop of every fit.
    double ata[10][10] = {}, atz[10] = {}, b[10];
    const bool plane = options.model == FormModel::kPlane;
    const double inv_scale = 1.0 / fit.scale_um;
    for_each([&](double x, double y, double z) {
      if (plane) {
        b[0] = 1.0;
        b[1] = x;
        b[2] = y;
      } else {
        Monomials(fit.polynomial_order, x * inv_scale, y * inv_scale, b);
      }
      const double dz = z - z_ref;
      for (int i = 0; i < np; ++i) {
        for (int j = i; j < np; ++j) ata[i][j] += b[i] * b[j];
        atz[i] += b[i] * dz;
      }
    });
    Eigen::MatrixXd a(np, np);
    Eigen::VectorXd v(np);
    for (int i = 0; i < np; ++i) {
      v[i] = atz[i];
      for (int j = i; j < np; ++j) a(i, j) = a(j, i) = ata[i][j];
    }
    if (ReciprocalCondition(a) < 1e-13) {
      return Status::FailedPrecondition(std::string("the region's pixels do not determine the ") +
                                        FormModelName(options.model) + " (e.g. all on one line)");
    }
    const Eigen::LDLT<Eigen::MatrixXd> ldlt = a.ldlt();
    fit.parameters = ldlt.solve(v);
    fit.parameters[0] += z_ref;  // the constant term is first in both bases
    fit.normal_inverse = ldlt.solve(Eigen::MatrixXd::Identity(np, np));
  } else {
    std::vector<Sample> pts;
    pts.reserve(count);
    for_each([&](double x, double y, double z) { pts.push_back({x, y, z}); });
    INSPECT_RETURN_IF_ERROR(FitNonlinear(pts, options, &fit));
  }
  double rss = 0.0;
  for_each([&](double x, double y, double z) {
    const double r = z - fit.Evaluate(x + fit.origin_x_um, y + fit.origin_y_um);
    rss += r * r;
  });
  fit.residual_rms_um = std::sqrt(rss / n);
  fit.covariance_from_residuals = fit.normal_inverse * (rss / std::max(1.0, n - np));
  return fit;
}

cv::Mat FormResidual(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um, const FormFit& fit) {
  cv::Mat out(depth_um.size(), CV_32FC1, cv::Scalar(std::nanf("")));
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* d = depth_um.ptr<float>(row);
    const uint8_t* m = mask.ptr<uint8_t>(row);
    float* o = out.ptr<float>(row);
    const double y = PixelCentreUm(row, pixel_size_um);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (!m[col] || !std::isfinite(d[col])) continue;
      o[col] = float(double(d[col]) - fit.Evaluate(PixelCentreUm(col, pixel_size_um), y));
    }
  }
  return out;
}

}  // namespace inspection
