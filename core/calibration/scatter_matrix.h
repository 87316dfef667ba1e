// Sparse scatter matrix A (thesis 4.3.4, eq. 4.11-4.12): column j holds the camera radiance
// patch of projector pixel j around its LUT position, so a camera radiance image is predicted
// from any projector pattern as e_c = A e_p + e. Built from dot grids (one capture per grid
// offset, spacing^2 captures), stored compressed (Eigen SparseMatrix, CSC, float).
#pragma once

#include <Eigen/SparseCore>
#include <filesystem>
#include <opencv2/core.hpp>
#include <vector>

#include "core/calibration/camera_response.h"
#include "core/calibration/geometric_calibration.h"
#include "core/calibration/projector_response.h"
#include "core/util/status.h"

namespace inspection {

// Plain data. Rows: camera pixels y * camera_width + x. Columns: projector pixels
// v * projector_width + u. Values: camera radiance (eq. 4.5 units) per unit of relative
// projector irradiance above the projector's black level.
struct ScatterMatrix {
  using Sparse = Eigen::SparseMatrix<float, Eigen::ColMajor, int>;

  cv::Size camera_size;
  cv::Size projector_size;
  Sparse a;
  cv::Mat black_radiance;                 // e of eq. 4.11: camera radiance at projector black, CV_32FC1
  double projector_black_irradiance = 0;  // prf(0): the part of e_p already contained in e
  int patch_radius_px = 0;
  int grid_spacing_px = 0;

  Status Validate() const;
  // nnz / (rows * cols), the thesis's density figure (0.00065 % there).
  double Density() const;
  // Predicted camera radiance for a relative projector irradiance image (CV_32FC1 of
  // projector_size, e.g. ProjectorResponseFunction::IrradianceImage): e + A (e_p - prf(0)).
  StatusOr<cv::Mat> PredictRadiance(const cv::Mat& projector_irradiance) const;
};

// One dot-grid capture converted to radiance (eq. 4.5) with the black-level radiance subtracted.
struct ScatterCapture {
  int offset_x = 0;
  int offset_y = 0;
  cv::Mat radiance;  // CV_32FC1, camera size
};

struct ScatterMatrixOptions {
  int grid_spacing_px = 8;
  int patch_radius_px = 6;                  // square patch (2r+1)^2 around the LUT centroid
  double relative_threshold = 0.01;         // entries below this share of the patch peak are dropped
  double dot_irradiance = 1.0;              // prf of the dots' grey level (255 -> 1)
  double projector_black_irradiance = 0.0;  // prf(0); columns are scaled by 1 / (dot - black)

  Status Validate() const;
};

// Incremental construction: Add() cuts the patches out of one capture right away, so only the
// non-zeros are kept between captures (a full-size run would otherwise hold spacing^2 float
// frames). Not thread-safe.
class ScatterMatrixBuilder {
 public:
  // geometry must outlive the builder.
  static StatusOr<ScatterMatrixBuilder> Create(const GeometricCalibration& geometry, const cv::Mat& black_radiance,
                                               const ScatterMatrixOptions& options);
  // One dot grid capture; INVALID_ARGUMENT if a projector pixel was already added.
  Status Add(const ScatterCapture& capture);
  // Assembles the CSC matrix; the builder is empty afterwards.
  StatusOr<ScatterMatrix> Finish();

 private:
  ScatterMatrixBuilder() = default;
  const GeometricCalibration* geometry_ = nullptr;
  cv::Mat black_radiance_;
  ScatterMatrixOptions options_;
  std::vector<int64_t> start_;
  std::vector<int> count_;
  std::vector<int> pool_rows_;
  std::vector<float> pool_vals_;
};

// Cuts each lit projector pixel's patch around geometry.projector_to_camera and stores it as
// its column. Projector pixels without a LUT entry get empty columns.
StatusOr<ScatterMatrix> BuildScatterMatrix(const std::vector<ScatterCapture>& captures,
                                           const GeometricCalibration& geometry, const cv::Mat& black_radiance,
                                           const ScatterMatrixOptions& options);

struct ScatterPrediction {
  cv::Mat predicted_grey;             // CV_32FC1, in the camera's grey levels
  double mean_abs_error_grey = 0;     // over the mask
  double mean_abs_error_percent = 0;  // of the camera's full scale (thesis: ~6 %)
  long pixel_count = 0;
};

// Predicts the camera image of `pattern` (CV_8UC1 projector image) captured at exposure_us and
// compares it with `captured` over `mask` (CV_8UC1, non-zero = compared; empty = all).
StatusOr<ScatterPrediction> PredictAndCompare(const ScatterMatrix& scatter, const ProjectorResponseFunction& prf,
                                              const CameraResponseFunction& crf, const cv::Mat& pattern,
                                              double exposure_us, const cv::Mat& captured, const cv::Mat& mask);

// Binary CSC file: magic "INSPSCT1", int32 rows, cols; int64 nnz; int32 outer[cols+1] (as
// int64 offsets would overflow nothing here: nnz < 2^31 is checked), int32 inner[nnz],
// float32 values[nnz]; little-endian as the host.
Status WriteSparseMatrix(const std::filesystem::path& file, const ScatterMatrix::Sparse& a);
StatusOr<ScatterMatrix::Sparse> ReadSparseMatrix(const std::filesystem::path& file);

}  // namespace inspection
