// Scatter matrix construction and prediction (thesis 4.3.4, eq. 4.11-4.12): patches cut around
// LUT centroids into a CSC matrix in one counting pass, without a triplet sort.
#include "core/calibration/scatter_matrix.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <string>

namespace inspection {

Status ScatterMatrix::Validate() const {
  if (camera_size.area() <= 0 || projector_size.area() <= 0) {
    return Status::InvalidArgument("scatter: camera_size and projector_size must be positive");
  }
  if (a.rows() != camera_size.area() || a.cols() != projector_size.area()) {
    return Status::InvalidArgument("scatter.a must be (camera pixels) x (projector pixels), is " +
                                   std::to_string(a.rows()) + "x" + std::to_string(a.cols()));
  }
  if (!a.isCompressed()) return Status::InvalidArgument("scatter.a must be compressed");
  if (black_radiance.type() != CV_32FC1 || black_radiance.size() != camera_size) {
    return Status::InvalidArgument("scatter.black_radiance must be CV_32FC1 of the camera size");
  }
  for (int k = 0; k < a.nonZeros(); ++k) {
    if (!std::isfinite(a.valuePtr()[k])) return Status::InvalidArgument("scatter.a holds a non-finite value");
  }
  return Status::Ok();
}

double ScatterMatrix::Density() const {
  const double cells = static_cast<double>(a.rows()) * static_cast<double>(a.cols());
  return cells > 0 ? a.nonZeros() / cells : 0.0;
}

StatusOr<cv::Mat> ScatterMatrix::PredictRadiance(const cv::Mat& projector_irradiance) const {
  if (projector_irradiance.type() != CV_32FC1 || projector_irradiance.size() != projector_size) {
    return Status::InvalidArgument("projector_irradiance must be CV_32FC1 of the projector size");
  }
  cv::Mat ep = projector_irradiance.isContinuous() ? projector_irradiance : projector_irradiance.clone();
  Eigen::VectorXf x = Eigen::Map<const Eigen::VectorXf>(ep.ptr<float>(), ep.total()).array() -
                      static_cast<float>(projector_black_irradiance);
  Eigen::VectorXf y = a * x;
  cv::Mat out = black_radiance.clone();
  Eigen::Map<Eigen::VectorXf>(out.ptr<float>(), out.total()) += y;
  return out;
}

Status ScatterMatrixOptions::Validate() const {
  if (grid_spacing_px < 1) return Status::InvalidArgument("grid_spacing_px must be >= 1");
  if (patch_radius_px < 1) return Status::InvalidArgument("patch_radius_px must be >= 1");
  if (!(relative_threshold >= 0 && relative_threshold < 1)) {
    return Status::InvalidArgument("relative_threshold must lie in [0, 1)");
  }
  if (!(dot_irradiance > projector_black_irradiance) || projector_black_irradiance < 0) {
    return Status::InvalidArgument("dot_irradiance must exceed projector_black_irradiance >= 0");
  }
  return Status::Ok();
}

StatusOr<ScatterMatrixBuilder> ScatterMatrixBuilder::Create(const GeometricCalibration& geometry,
                                                            const cv::Mat& black_radiance,
                                                            const ScatterMatrixOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (geometry.projector_to_camera.type() != CV_32FC2 ||
      geometry.projector_to_camera.size() != geometry.projector_size) {
    return Status::InvalidArgument("scatter: geometry has no projector_to_camera LUT");
  }
  if (black_radiance.type() != CV_32FC1 || black_radiance.size() != geometry.camera_size) {
    return Status::InvalidArgument("scatter: black_radiance must be CV_32FC1 of the camera size");
  }
  ScatterMatrixBuilder b;
  b.geometry_ = &geometry;
  b.black_radiance_ = black_radiance.clone();
  b.options_ = options;
  const int cols = geometry.projector_size.area();
  b.start_.assign(cols, 0);
  b.count_.assign(cols, 0);
  return b;
}

Status ScatterMatrixBuilder::Add(const ScatterCapture& c) {
  const cv::Size cam = geometry_->camera_size, proj = geometry_->projector_size;
  if (c.radiance.type() != CV_32FC1 || c.radiance.size() != cam) {
    return Status::InvalidArgument("scatter: capture radiance must be CV_32FC1 of the camera size");
  }
  const int r = options_.patch_radius_px;
  const float inv = static_cast<float>(1.0 / (options_.dot_irradiance - options_.projector_black_irradiance));
  for (int v = c.offset_y; v < proj.height; v += options_.grid_spacing_px)
    for (int u = c.offset_x; u < proj.width; u += options_.grid_spacing_px) {
      const cv::Vec2f p = geometry_->projector_to_camera.at<cv::Vec2f>(v, u);
      if (!std::isfinite(p[0]) || !std::isfinite(p[1])) continue;
      const int cx = static_cast<int>(std::lround(p[0])), cy = static_cast<int>(std::lround(p[1]));
      const int x0 = std::max(0, cx - r), x1 = std::min(cam.width - 1, cx + r);
      const int y0 = std::max(0, cy - r), y1 = std::min(cam.height - 1, cy + r);
      if (x0 > x1 || y0 > y1) continue;
      float peak = 0;
      for (int y = y0; y <= y1; ++y) {
        const float* row = c.radiance.ptr<float>(y);
        for (int x = x0; x <= x1; ++x) peak = std::max(peak, row[x]);
      }
      if (!(peak > 0)) continue;
      const float t = static_cast<float>(options_.relative_threshold) * peak;
      const int col = v * proj.width + u;
      if (count_[col] != 0) {
        return Status::InvalidArgument("scatter: projector pixel (" + std::to_string(u) + ", " + std::to_string(v) +
                                       ") lit in two captures");
      }
      start_[col] = static_cast<int64_t>(pool_rows_.size());
      for (int y = y0; y <= y1; ++y) {
        const float* row = c.radiance.ptr<float>(y);
        for (int x = x0; x <= x1; ++x) {
          if (row[x] > t) {
            pool_rows_.push_back(y * cam.width + x);
            pool_vals_.push_back(row[x] * inv);
          }
        }
      }
      count_[col] = static_cast<int>(pool_rows_.size() - start_[col]);
    }
  if (pool_rows_.size() >= static_cast<size_t>(INT32_MAX)) {
    return Status::ResourceExhausted("scatter: more than 2^31 non-zeros");
  }
  return Status::Ok();
}

StatusOr<ScatterMatrix> ScatterMatrixBuilder::Finish() {
  if (!geometry_) return Status::FailedPrecondition("scatter: builder already finished");
  const cv::Size cam = geometry_->camera_size, proj = geometry_->projector_size;
  const int cols = proj.area();
  ScatterMatrix s;
  s.camera_size = cam;
  s.projector_size = proj;
  s.patch_radius_px = options_.patch_radius_px;
  s.grid_spacing_px = options_.grid_spacing_px;
  s.projector_black_irradiance = options_.projector_black_irradiance;
  s.black_radiance = black_radiance_;
  s.a.resize(cam.area(), cols);
  s.a.resizeNonZeros(static_cast<Eigen::Index>(pool_rows_.size()));
  int* outer = s.a.outerIndexPtr();
  int* inner = s.a.innerIndexPtr();
  float* vals = s.a.valuePtr();
  int64_t pos = 0;
  for (int col = 0; col < cols; ++col) {
    outer[col] = static_cast<int>(pos);
    if (count_[col] > 0) {
      std::memcpy(inner + pos, pool_rows_.data() + start_[col], sizeof(int) * count_[col]);
      std::memcpy(vals + pos, pool_vals_.data() + start_[col], sizeof(float) * count_[col]);
      pos += count_[col];
    }
  }
  outer[cols] = static_cast<int>(pos);
  *this = ScatterMatrixBuilder();
  return s;
}

StatusOr<ScatterMatrix> BuildScatterMatrix(const std::vector<ScatterCapture>& captures,
                                           const GeometricCalibration& geometry, const cv::Mat& black_radiance,
                                           const ScatterMatrixOptions& options) {
  INSPECT_ASSIGN_OR_RETURN(ScatterMatrixBuilder b, ScatterMatrixBuilder::Create(geometry, black_radiance, options));
  for (size_t k = 0; k < captures.size(); ++k) {
    INSPECT_RETURN_IF_ERROR(b.Add(captures[k]).WithContext("captures[" + std::to_string(k) + "]"));
  }
  return b.Finish();
}

StatusOr<ScatterPrediction> PredictAndCompare(const ScatterMatrix& scatter, const ProjectorResponseFunction& prf,
                                              const CameraResponseFunction& crf, const cv::Mat& pattern,
                                              double exposure_us, const cv::Mat& captured, const cv::Mat& mask) {
  if (pattern.type() != CV_8UC1 || pattern.size() != scatter.projector_size) {
    return Status::InvalidArgument("pattern must be CV_8UC1 of the projector size");
  }
  if (captured.size() != scatter.camera_size || captured.channels() != 1) {
    return Status::InvalidArgument("captured must be a single-channel image of the camera size");
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != scatter.camera_size)) {
    return Status::InvalidArgument("mask must be CV_8UC1 of the camera size");
  }
  if (!(exposure_us > 0)) return Status::InvalidArgument("exposure_us must be > 0");
  INSPECT_ASSIGN_OR_RETURN(cv::Mat e_c, scatter.PredictRadiance(prf.IrradianceImage(pattern)));
  ScatterPrediction out;
  out.predicted_grey = cv::Mat(scatter.camera_size, CV_32FC1);
  cv::Mat cap;
  captured.convertTo(cap, CV_32F);
  const double log_dt = std::log(exposure_us);
  double sum = 0;
  long n = 0;
  for (int y = 0; y < e_c.rows; ++y) {
    const float* e = e_c.ptr<float>(y);
    const float* z = cap.ptr<float>(y);
    float* o = out.predicted_grey.ptr<float>(y);
    for (int x = 0; x < e_c.cols; ++x) {
      // eq. 5.3-5.4: Z = crf^-1(ln(E dt)).
      o[x] = e[x] > 0 ? static_cast<float>(crf.GreyForLogExposure(std::log(e[x]) + log_dt)) : 0.0f;
      if (!mask.empty() && !mask.at<uint8_t>(y, x)) continue;
      sum += std::abs(o[x] - z[x]);
      ++n;
    }
  }
  if (n == 0) return Status::InvalidArgument("mask selects no pixel");
  out.pixel_count = n;
  out.mean_abs_error_grey = sum / n;
  out.mean_abs_error_percent = 100.0 * out.mean_abs_error_grey / (crf.levels - 1);
  return out;
}

Status WriteSparseMatrix(const std::filesystem::path& file, const ScatterMatrix::Sparse& a) {
  if (!a.isCompressed()) return Status::InvalidArgument("sparse matrix must be compressed");
  const std::filesystem::path tmp = file.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) return Status::Unavailable("cannot write " + tmp.string());
    const char magic[8] = {'I', 'N', 'S', 'P', 'S', 'C', 'T', '1'};
    const int32_t rows = static_cast<int32_t>(a.rows()), cols = static_cast<int32_t>(a.cols());
    const int64_t nnz = a.nonZeros();
    f.write(magic, 8);
    f.write(reinterpret_cast<const char*>(&rows), 4);
    f.write(reinterpret_cast<const char*>(&cols), 4);
    f.write(reinterpret_cast<const char*>(&nnz), 8);
    f.write(reinterpret_cast<const char*>(a.outerIndexPtr()), sizeof(int32_t) * (static_cast<size_t>(cols) + 1));
    f.write(reinterpret_cast<const char*>(a.innerIndexPtr()), sizeof(int32_t) * static_cast<size_t>(nnz));
    f.write(reinterpret_cast<const char*>(a.valuePtr()), sizeof(float) * static_cast<size_t>(nnz));
    if (!f) return Status::Unavailable("write failed: " + tmp.string());
  }
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) return Status::Unavailable("cannot rename " + tmp.string() + ": " + ec.message());
  return Status::Ok();
}

StatusOr<ScatterMatrix::Sparse> ReadSparseMatrix(const std::filesystem::path& file) {
  std::ifstream f(file, std::ios::binary);
  if (!f) return Status::NotFound("cannot open " + file.string());
  char magic[8];
  int32_t rows = 0, cols = 0;
  int64_t nnz = 0;
  f.read(magic, 8);
  f.read(reinterpret_cast<char*>(&rows), 4);
  f.read(reinterpret_cast<char*>(&cols), 4);
  f.read(reinterpret_cast<char*>(&nnz), 8);
  const std::string name = file.filename().string();
  if (!f || std::memcmp(magic, "INSPSCT1", 8) != 0) return Status::DataLoss(name + ": not a scatter matrix file");
  if (rows < 0 || cols < 0 || nnz < 0 || nnz > INT32_MAX) return Status::DataLoss(name + ": bad header");
  std::error_code ec;
  const auto fsize = std::filesystem::file_size(file, ec);
  const uint64_t expected = 24 + 4ull * (static_cast<uint64_t>(cols) + 1) + 8ull * static_cast<uint64_t>(nnz);
  if (ec || fsize != expected) return Status::DataLoss(name + ": size does not match its header");
  ScatterMatrix::Sparse a(rows, cols);
  a.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  f.read(reinterpret_cast<char*>(a.outerIndexPtr()), sizeof(int32_t) * (static_cast<size_t>(cols) + 1));
  f.read(reinterpret_cast<char*>(a.innerIndexPtr()), sizeof(int32_t) * static_cast<size_t>(nnz));
  f.read(reinterpret_cast<char*>(a.valuePtr()), sizeof(float) * static_cast<size_t>(nnz));
  if (!f) return Status::DataLoss(name + ": truncated");
  // Structural checks: monotone outer index, rows in range and sorted within each column.
  const int* outer = a.outerIndexPtr();
  if (outer[0] != 0 || outer[cols] != nnz) return Status::DataLoss(name + ": bad column index");
  for (int c = 0; c < cols; ++c) {
    if (outer[c + 1] < outer[c]) return Status::DataLoss(name + ": column index decreases");
  }
  for (int c = 0; c < cols; ++c) {
    for (int k = outer[c]; k < outer[c + 1]; ++k) {
      const int row = a.innerIndexPtr()[k];
      if (row < 0 || row >= rows || (k > outer[c] && row <= a.innerIndexPtr()[k - 1])) {
        return Status::DataLoss(name + ": row index out of order in column " + std::to_string(c));
      }
    }
  }
  return a;
}

}  // namespace inspection
