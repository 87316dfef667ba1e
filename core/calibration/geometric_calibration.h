// Geometric projector <-> camera calibration (thesis 4.3.2): look-up tables in both directions
// from projected dot grids with sub-pixel centroids (eq. 4.10), a homography fitted to the
// LUT and the LUT-vs-homography deviation (the thesis measured 0.266 px mean, 0.084 px std).
//
// Coarse correspondence first comes from Gray-code stripes (one decoded projector column/row
// per camera pixel), which tells where each dot of a grid must appear; the dot grids then give
// the sub-pixel positions. Pixel coordinates follow OpenCV: pixel (x, y) covers [x-0.5, x+0.5].
#pragma once

#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include "core/util/status.h"

namespace inspection {

// Plain data: the calibrated mapping.
struct GeometricCalibration {
  cv::Size projector_size;
  cv::Size camera_size;
  // For every projector pixel (u, v): its centroid (x, y) in the camera, CV_32FC2 of
  // projector_size; NaN where the pixel is not seen by the camera.
  cv::Mat projector_to_camera;
  // For every camera pixel (x, y): the projector position (u, v) lighting it, CV_32FC2 of
  // camera_size, interpolated between measured centroids; NaN outside the lit area.
  cv::Mat camera_to_projector;
  // Camera-from-projector homography fitted to every valid LUT entry (least squares).
  cv::Matx33d homography = cv::Matx33d::eye();
  int grid_spacing_px = 0;                // projector pixels between dots of one grid
  int valid_projector_pixels = 0;         // LUT entries with a centroid
  double camera_px_per_projector_px = 0;  // mean scale of the homography at the image centre
  double projector_rotation_deg = 0;      // angle of the projector x axis in the camera
  double lut_vs_homography_mean_px = 0;   // |LUT - H(u, v)| over valid entries (thesis 0.266)
  double lut_vs_homography_std_px = 0;    // (thesis 0.084)
  double lut_vs_homography_max_px = 0;

  Status Validate() const;
  // Camera position of projector point (u, v): bilinear LUT interpolation, falling back to the
  // homography where a neighbour is missing. Returns nullopt outside the projector.
  std::optional<cv::Point2d> CameraFromProjector(cv::Point2d projector_px) const;
  // Projector position of a camera pixel from camera_to_projector; nullopt when unlit.
  std::optional<cv::Point2d> ProjectorFromCamera(cv::Point camera_px) const;
};

// --- Homography ---------------------------------------------------------------------------

// Applies h to a point (homogeneous division).
cv::Point2d ApplyHomography(const cv::Matx33d& h, cv::Point2d p);

// Least-squares homography dst ~ H src: normalised DLT, then Gauss-Newton on the transfer
// error in dst. With trim_iterations > 0, points with residual above
// max(3 * median, min_trim_px) are dropped and the fit repeated (outliers from decoding).
StatusOr<cv::Matx33d> FitHomography(const std::vector<cv::Point2d>& src, const std::vector<cv::Point2d>& dst,
                                    int trim_iterations = 0, double min_trim_px = 1.0);

// --- Gray code coarse correspondence ---------------------------------------------------------

struct GrayCodePattern {
  cv::Mat pattern;               // CV_8UC1 of the projector size, 0 / 255
  bool vertical_stripes = true;  // true: encodes the projector column u, false: row v
  int bit = 0;                   // bit of the Gray code, most significant first from 0
  bool inverted = false;
};

// Patterns for both axes, each bit followed by its inverse. Bits finer than
// finest_stripe_px projector pixels are left out (they blur away on a microscope).
std::vector<GrayCodePattern> MakeGrayCodePatterns(cv::Size projector_size, int finest_stripe_px = 4);

// Decodes captures of MakeGrayCodePatterns (same order) into, per camera pixel, the projector
// (u, v) at the centre of the decoded stripe cell (CV_32FC2; NaN where any bit had a contrast
// below min_contrast grey levels between pattern and inverse).
StatusOr<cv::Mat> DecodeGrayCode(const std::vector<GrayCodePattern>& patterns, const std::vector<cv::Mat>& captures,
                                 cv::Size projector_size, double min_contrast);

// Camera-from-projector homography from a decoded Gray-code map (trimmed fit on a subsample).
StatusOr<cv::Matx33d> CoarseHomographyFromGrayCode(const cv::Mat& decoded);

// --- Dot grids and centroids ------------------------------------------------------------------

// A grid of single lit projector pixels (grey) at (offset_x + k * spacing, offset_y + l * spacing).
cv::Mat MakeDotGridPattern(cv::Size projector_size, int spacing_px, int offset_x, int offset_y, int grey = 255);

struct CentroidOptions {
  double window_radius_px = 6.0;  // half size of the search window around the prediction
  double coarse_threshold = 0.5;  // of the window maximum: binary mask for the coarse centre
  double patch_threshold = 0.1;   // of the maximum: pixels entering eq. 4.10
  double min_peak = 8.0;          // peak above background (input units) to accept a dot
};

// Sub-pixel centroid of one dot (eq. 4.10) in a background-subtracted image (CV_32FC1) near
// `predicted`: centre of mass of the thresholded window gives the coarse centre, the weighted
// mean of the patch around it the result. nullopt when no dot is found.
std::optional<cv::Point2d> DotCentroid(const cv::Mat& signal, cv::Point2d predicted, const CentroidOptions& options);

// One captured dot-grid pattern.
struct DotGridCapture {
  int offset_x = 0;
  int offset_y = 0;
  cv::Mat image;  // CV_8UC1 / CV_16UC1, as captured
};

struct GeometricCalibrationOptions {
  int grid_spacing_px = 8;   // projector pixels between lit dots (spacing^2 patterns)
  CentroidOptions centroid;  // window_radius_px <= 0: 0.4 * spacing * scale
  int border_px = 2;         // dots whose window leaves the frame by more are dropped

  Status Validate() const;
};

// Fills the projector->camera LUT from dot grid captures (black-level image subtracted), the
// dots located near coarse_homography predictions; then inverts it into the camera->projector
// LUT, fits the homography and computes the deviation figures.
StatusOr<GeometricCalibration> EstimateGeometricCalibration(const std::vector<DotGridCapture>& captures,
                                                            const cv::Mat& black_image,
                                                            const cv::Matx33d& coarse_homography,
                                                            cv::Size projector_size,
                                                            const GeometricCalibrationOptions& options);

// Completes a calibration whose projector_to_camera is filled: camera_to_projector (triangle
// rasterisation of neighbouring LUT entries), homography and deviation figures.
Status FinishGeometricCalibration(GeometricCalibration& calibration);

}  // namespace inspection
