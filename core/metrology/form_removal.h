// Form removal (the F-operator of ISO 25178-2 3.1.5, ISO 25178-3): least-squares plane,
// polynomial of total order 2..3, sphere and cylinder (lenses) fitted to the measured pixels of a
// region; the residual (primary surface) map and the fit parameters with their covariance.
// Residuals are taken along z (the SFF depth axis, thesis 3.1: each depth is a stage position),
// because that is the direction of the measurement error.
#pragma once

#include <Eigen/Dense>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

enum class FormModel {
  kPlane,       // z = z0 + slope_x (x - x_o) + slope_y (y - y_o)
  kPolynomial,  // z = sum over a + b <= order of c_ab u^a v^b, u = (x - x_o) / s, v = (y - y_o) / s
  kSphere,      // z = centre_z + sign sqrt(R^2 - (x - centre_x)^2 - (y - centre_y)^2)
  kCylinder,    // axis in direction phi through the image plane: z = axis_z + axis_slope t + sign sqrt(R^2 - d^2)
};

const char* FormModelName(FormModel model);  // "plane", "polynomial", "sphere", "cylinder"
StatusOr<FormModel> ParseFormModel(const std::string& name);

struct FormOptions {
  FormModel model = FormModel::kPlane;
  int polynomial_order = 2;  // kPolynomial only: total order 1..3 (1 is the plane)
  int max_iterations = 100;  // sphere/cylinder: Levenberg-Marquardt iterations, 1..1000
  // INVALID_ARGUMENT naming the field.
  Status Validate() const;
};

// Result of FitForm. Coordinates x_um, y_um are image coordinates (core/metrology/surface_roi.h: from the
// top-left corner; pixel (col, row) has its centre at ((col + 0.5) p, (row + 0.5) p)).
//
// Parameters by model (names in parameter_names, units in the names):
//   kPlane:      z0_um (height at the origin), slope_x, slope_y (um/um)
//   kPolynomial: c<a><b>_um for u^a v^b, a + b <= order, ordered by total order then a descending
//                (c00, c10, c01, c20, c11, c02, ...); u, v dimensionless
//   kSphere:     centre_x_um, centre_y_um, centre_z_um, radius_um
//   kCylinder:   axis_angle_rad (axis direction from +x towards +y, in (-pi/2, pi/2]),
//                axis_offset_um (signed distance of the axis from the origin, along the
//                normal (-sin, cos)), axis_z_um (axis height at the origin's foot point),
//                axis_slope (dz per um along the axis), radius_um
// sign (sphere/cylinder): +1 convex (the surface bulges towards +z, e.g. a lens seen from
// above), -1 concave.
struct FormFit {
  FormModel model = FormModel::kPlane;
  int polynomial_order = 1;
  double origin_x_um = 0.0;  // centroid of the fitted pixels: conditions the fit
  double origin_y_um = 0.0;
  double scale_um = 1.0;  // kPolynomial: half the larger side of the fitted pixels' bounding box
  int sign = 1;
  std::vector<std::string> parameter_names;
  Eigen::VectorXd parameters;
  // (J^T J)^-1 at the solution, J the n x p Jacobian of the model values at the fitted pixels
  // with respect to the parameters. core/metrology/measurement_uncertainty.h propagates the depth map's
  // correlated noise model through it (sandwich (J^T J)^-1 J^T Sigma J (J^T J)^-1).
  Eigen::MatrixXd normal_inverse;
  // Textbook covariance s^2 (J^T J)^-1 with s^2 = RSS / (n - p): valid only for independent,
  // equal-variance residuals, which SFF depth noise is not (it is correlated over the focus
  // window); kept for reference and for data that is.
  Eigen::MatrixXd covariance_from_residuals;
  size_t pixel_count = 0;
  double residual_rms_um = 0.0;
  int iterations = 0;  // sphere/cylinder

  // The fitted form at image coordinates (µm).
  double Evaluate(double x_um, double y_um) const;
  // d(model value at (x_um, y_um)) / d(parameters), parameters.size() values into `out`.
  void ParameterGradient(double x_um, double y_um, double* out) const;
  // Index of a parameter by name, -1 when absent.
  int ParameterIndex(const std::string& name) const;
  // Plane only: the tilt of the plane's normal from the z axis (degrees) = atan(|slope|).
  double PlaneTiltDeg() const;
};

// Fits the model to the pixels where mask (CV_8UC1, same size) is non-zero and depth_um
// (CV_32FC1) is finite. pixel_size_um > 0. Errors: INVALID_ARGUMENT for bad inputs or options;
// FAILED_PRECONDITION when there are fewer pixels than parameters + 1, the pixels do not span
// the model (e.g. all on one line), or a sphere/cylinder does not converge or the region reaches
// beyond the fitted radius.
StatusOr<FormFit> FitForm(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                          const FormOptions& options);

// Residual map z - form (CV_32FC1): finite where mask is non-zero and depth is finite, NaN elsewhere.
cv::Mat FormResidual(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um, const FormFit& fit);

// Image coordinates of pixel centres.
inline double PixelCentreUm(int index, double pixel_size_um) { return (index + 0.5) * pixel_size_um; }

}  // namespace inspection
