// Geometric projector <-> camera calibration (thesis 4.3.2, eq. 4.10): Gray-code coarse map,
// dot-grid sub-pixel centroids, LUT inversion by triangle rasterisation, homography fit.
#include "core/calibration/geometric_calibration.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace inspection {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

bool Valid(const cv::Vec2f& v) { return std::isfinite(v[0]) && std::isfinite(v[1]); }

// Similarity transform taking points to zero mean and mean distance sqrt(2) (Hartley).
cv::Matx33d NormalisingTransform(const std::vector<cv::Point2d>& p) {
  cv::Point2d c(0, 0);
  for (const auto& q : p) c += q;
  c *= 1.0 / p.size();
  double d = 0;
  for (const auto& q : p) d += cv::norm(q - c);
  d /= p.size();
  const double s = d > 0 ? std::sqrt(2.0) / d : 1.0;
  return {s, 0, -s * c.x, 0, s, -s * c.y, 0, 0, 1};
}

cv::Matx33d FitHomographyOnce(const std::vector<cv::Point2d>& src, const std::vector<cv::Point2d>& dst) {
  const cv::Matx33d ts = NormalisingTransform(src), td = NormalisingTransform(dst);
  // DLT: accumulate A^T A (9x9) so millions of LUT points need no big matrix.
  Eigen::Matrix<double, 9, 9> ata = Eigen::Matrix<double, 9, 9>::Zero();
  std::vector<cv::Point2d> ns(src.size()), nd(dst.size());
  for (size_t i = 0; i < src.size(); ++i) {
    ns[i] = ApplyHomography(ts, src[i]);
    nd[i] = ApplyHomography(td, dst[i]);
    const double x = ns[i].x, y = ns[i].y, u = nd[i].x, v = nd[i].y;
    Eigen::Matrix<double, 9, 1> r1, r2;
    r1 << -x, -y, -1, 0, 0, 0, u * x, u * y, u;
    r2 << 0, 0, 0, -x, -y, -1, v * x, v * y, v;
    ata.noalias() += r1 * r1.transpose() + r2 * r2.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> es(ata);
  Eigen::Matrix<double, 9, 1> h = es.eigenvectors().col(0);
  h /= h(8);
  // Gauss-Newton on the transfer error in normalised dst coordinates, h(8) fixed to 1.
  for (int it = 0; it < 6; ++it) {
    Eigen::Matrix<double, 8, 8> jtj = Eigen::Matrix<double, 8, 8>::Zero();
    Eigen::Matrix<double, 8, 1> jtr = Eigen::Matrix<double, 8, 1>::Zero();
    for (size_t i = 0; i < ns.size(); ++i) {
      const double x = ns[i].x, y = ns[i].y;
      const double w = h(6) * x + h(7) * y + 1.0;
      const double u = (h(0) * x + h(1) * y + h(2)) / w, v = (h(3) * x + h(4) * y + h(5)) / w;
      Eigen::Matrix<double, 8, 1> ju, jv;
      ju << x / w, y / w, 1 / w, 0, 0, 0, -u * x / w, -u * y / w;
      jv << 0, 0, 0, x / w, y / w, 1 / w, -v * x / w, -v * y / w;
      jtj.noalias() += ju * ju.transpose() + jv * jv.transpose();
      jtr.noalias() += ju * (nd[i].x - u) + jv * (nd[i].y - v);
    }
    const Eigen::Matrix<double, 8, 1> step = jtj.ldlt().solve(jtr);
    if (!step.allFinite()) break;
    h.head<8>() += step;
    if (step.norm() < 1e-12) break;
  }
  const cv::Matx33d hn(h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8));
  cv::Matx33d out = td.inv() * hn * ts;
  return out * (1.0 / out(2, 2));
}

}  // namespace

// --- GeometricCalibration ---------------------------------------------------------------------

Status GeometricCalibration::Validate() const {
  if (projector_size.area() <= 0 || camera_size.area() <= 0) {
    return Status::InvalidArgument("geometry: projector_size and camera_size must be positive");
  }
  if (projector_to_camera.type() != CV_32FC2 || projector_to_camera.size() != projector_size) {
    return Status::InvalidArgument("geometry.projector_to_camera must be CV_32FC2 of the projector size");
  }
  if (camera_to_projector.type() != CV_32FC2 || camera_to_projector.size() != camera_size) {
    return Status::InvalidArgument("geometry.camera_to_projector must be CV_32FC2 of the camera size");
  }
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(homography(r, c))) return Status::InvalidArgument("geometry.homography is not finite");
  if (valid_projector_pixels <= 0) return Status::InvalidArgument("geometry: no valid LUT entry");
  return Status::Ok();
}

std::optional<cv::Point2d> GeometricCalibration::CameraFromProjector(cv::Point2d p) const {
  if (p.x < 0 || p.y < 0 || p.x > projector_size.width - 1 || p.y > projector_size.height - 1) {
    return std::nullopt;
  }
  const int u0 = std::min(static_cast<int>(p.x), projector_size.width - 2);
  const int v0 = std::min(static_cast<int>(p.y), projector_size.height - 2);
  if (u0 >= 0 && v0 >= 0 && !projector_to_camera.empty()) {
    const cv::Vec2f a = projector_to_camera.at<cv::Vec2f>(v0, u0), b = projector_to_camera.at<cv::Vec2f>(v0, u0 + 1);
    const cv::Vec2f c = projector_to_camera.at<cv::Vec2f>(v0 + 1, u0),
                    d = projector_to_camera.at<cv::Vec2f>(v0 + 1, u0 + 1);
    if (Valid(a) && Valid(b) && Valid(c) && Valid(d)) {
      const double tx = p.x - u0, ty = p.y - v0;
      const cv::Vec2f top = a * (1 - tx) + b * tx, bottom = c * (1 - tx) + d * tx;
      const cv::Vec2f r = top * (1 - ty) + bottom * ty;
      return cv::Point2d(r[0], r[1]);
    }
  }
  return ApplyHomography(homography, p);
}

std::optional<cv::Point2d> GeometricCalibration::ProjectorFromCamera(cv::Point c) const {
  if (c.x < 0 || c.y < 0 || c.x >= camera_size.width || c.y >= camera_size.height) return std::nullopt;
  const cv::Vec2f v = camera_to_projector.at<cv::Vec2f>(c);
  if (!Valid(v)) return std::nullopt;
  return cv::Point2d(v[0], v[1]);
}

// --- Homography ---------------------------------------------------------------------------

cv::Point2d ApplyHomography(const cv::Matx33d& h, cv::Point2d p) {
  const double w = h(2, 0) * p.x + h(2, 1) * p.y + h(2, 2);
  return {(h(0, 0) * p.x + h(0, 1) * p.y + h(0, 2)) / w, (h(1, 0) * p.x + h(1, 1) * p.y + h(1, 2)) / w};
}

StatusOr<cv::Matx33d> FitHomography(const std::vector<cv::Point2d>& src, const std::vector<cv::Point2d>& dst,
                                    int trim_iterations, double min_trim_px) {
  if (src.size() != dst.size()) return Status::InvalidArgument("homography: src and dst differ in length");
  if (src.size() < 4) return Status::InvalidArgument("homography: need at least 4 correspondences");
  cv::Matx33d h = FitHomographyOnce(src, dst);
  std::vector<cv::Point2d> s = src, d = dst;
  for (int it = 0; it < trim_iterations; ++it) {
    std::vector<double> res(s.size());
    for (size_t i = 0; i < s.size(); ++i) res[i] = cv::norm(ApplyHomography(h, s[i]) - d[i]);
    std::vector<double> sorted = res;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double limit = std::max(3.0 * sorted[sorted.size() / 2], min_trim_px);
    std::vector<cv::Point2d> s2, d2;
    for (size_t i = 0; i < s.size(); ++i)
      if (res[i] <= limit) {
        s2.push_back(s[i]);
        d2.push_back(d[i]);
      }
    if (s2.size() == s.size() || s2.size() < 4) break;
    s.swap(s2);
    d.swap(d2);
    h = FitHomographyOnce(s, d);
  }
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(h(r, c))) return Status::InvalidArgument("homography: degenerate correspondences");
  return h;
}

// --- Gray code -------------------------------------------------------------------------------

namespace {
int BitsFor(int length) {
  int n = 0;
  while ((1 << n) < length) ++n;
  return n;
}
// Lowest Gray bit position kept: stripe width of bit k is 2^(k+1) projector pixels.
int LowestBit(int finest_stripe_px) {
  int k = 0;
  while ((2 << k) < finest_stripe_px) ++k;
  return k;
}
}  // namespace

std::vector<GrayCodePattern> MakeGrayCodePatterns(cv::Size projector_size, int finest_stripe_px) {
  std::vector<GrayCodePattern> out;
  for (bool vertical : {true, false}) {
    const int length = vertical ? projector_size.width : projector_size.height;
    const int nb = BitsFor(length);
    const int low = std::min(LowestBit(finest_stripe_px), std::max(nb - 1, 0));
    for (int k = nb - 1, b = 0; k >= low; --k, ++b) {
      for (bool inv : {false, true}) {
        GrayCodePattern g;
        g.vertical_stripes = vertical;
        g.bit = b;
        g.inverted = inv;
        g.pattern = cv::Mat(projector_size, CV_8UC1);
        for (int y = 0; y < projector_size.height; ++y) {
          uint8_t* p = g.pattern.ptr<uint8_t>(y);
          for (int x = 0; x < projector_size.width; ++x) {
            const int c = vertical ? x : y;
            const bool on = (((c ^ (c >> 1)) >> k) & 1) != inv;
            p[x] = on ? 255 : 0;
          }
        }
        out.push_back(std::move(g));
      }
    }
  }
  return out;
}

StatusOr<cv::Mat> DecodeGrayCode(const std::vector<GrayCodePattern>& patterns, const std::vector<cv::Mat>& captures,
                                 cv::Size projector_size, double min_contrast) {
  if (patterns.size() != captures.size() || captures.empty()) {
    return Status::InvalidArgument("gray code: patterns and captures differ in count");
  }
  const cv::Size size = captures[0].size();
  std::vector<cv::Mat> f(captures.size());
  for (size_t i = 0; i < captures.size(); ++i) {
    if (captures[i].size() != size || captures[i].channels() != 1) {
      return Status::InvalidArgument("gray code: captures[" + std::to_string(i) + "] differs in size");
    }
    captures[i].convertTo(f[i], CV_32F);
  }
  cv::Mat prefix[2] = {cv::Mat::zeros(size, CV_32S), cv::Mat::zeros(size, CV_32S)};
  cv::Mat ok(size, CV_8U, cv::Scalar(1));
  int bits[2] = {0, 0};
  for (size_t i = 0; i + 1 < patterns.size(); i += 2) {
    const GrayCodePattern& a = patterns[i];
    if (a.inverted || !patterns[i + 1].inverted || patterns[i + 1].bit != a.bit ||
        patterns[i + 1].vertical_stripes != a.vertical_stripes) {
      return Status::InvalidArgument("gray code: patterns must alternate pattern / inverse");
    }
    const int axis = a.vertical_stripes ? 0 : 1;
    ++bits[axis];
    for (int y = 0; y < size.height; ++y) {
      const float* p = f[i].ptr<float>(y);
      const float* q = f[i + 1].ptr<float>(y);
      int* g = prefix[axis].ptr<int>(y);
      uint8_t* o = ok.ptr<uint8_t>(y);
      for (int x = 0; x < size.width; ++x) {
        const float d = p[x] - q[x];
        if (std::abs(d) < min_contrast) o[x] = 0;
        g[x] = (g[x] << 1) | (d > 0 ? 1 : 0);
      }
    }
  }
  cv::Mat out(size, CV_32FC2);
  const int len[2] = {projector_size.width, projector_size.height};
  for (int y = 0; y < size.height; ++y) {
    const int* gu = prefix[0].ptr<int>(y);
    const int* gv = prefix[1].ptr<int>(y);
    const uint8_t* o = ok.ptr<uint8_t>(y);
    cv::Vec2f* r = out.ptr<cv::Vec2f>(y);
    for (int x = 0; x < size.width; ++x) {
      if (!o[x]) {
        r[x] = {kNaN, kNaN};
        continue;
      }
      float coord[2];
      bool inside = true;
      for (int ax = 0; ax < 2; ++ax) {
        int g = ax == 0 ? gu[x] : gv[x];
        int b = 0;  // Gray -> binary on the decoded prefix
        for (; g; g >>= 1) b ^= g;
        const int skipped = BitsFor(len[ax]) - bits[ax];
        const double cell = std::ldexp(1.0, skipped);
        coord[ax] = static_cast<float>(b * cell + (cell - 1) / 2);
        if (b * cell >= len[ax]) inside = false;
      }
      r[x] = inside ? cv::Vec2f(coord[0], coord[1]) : cv::Vec2f(kNaN, kNaN);
    }
  }
  return out;
}

StatusOr<cv::Matx33d> CoarseHomographyFromGrayCode(const cv::Mat& decoded) {
  if (decoded.type() != CV_32FC2) return Status::InvalidArgument("decoded must be CV_32FC2");
  const int stride = std::max(1, static_cast<int>(std::sqrt(decoded.total() / 20000.0)));
  std::vector<cv::Point2d> src, dst;
  for (int y = stride / 2; y < decoded.rows; y += stride)
    for (int x = stride / 2; x < decoded.cols; x += stride) {
      const cv::Vec2f v = decoded.at<cv::Vec2f>(y, x);
      if (!Valid(v)) continue;
      src.emplace_back(v[0], v[1]);
      dst.emplace_back(x, y);
    }
  if (src.size() < 16) {
    return Status::FailedPrecondition(
        "gray code: fewer than 16 decodable camera pixels (is the "
        "projector lighting the camera's field of view?)");
  }
  return FitHomography(src, dst, 4, 1.0);
}

// --- Dot grids ---------------------------------------------------------------------------------

cv::Mat MakeDotGridPattern(cv::Size projector_size, int spacing_px, int offset_x, int offset_y, int grey) {
  cv::Mat p = cv::Mat::zeros(projector_size, CV_8UC1);
  for (int v = offset_y; v < projector_size.height; v += spacing_px)
    for (int u = offset_x; u < projector_size.width; u += spacing_px) p.at<uint8_t>(v, u) = static_cast<uint8_t>(grey);
  return p;
}

std::optional<cv::Point2d> DotCentroid(const cv::Mat& signal, cv::Point2d predicted, const CentroidOptions& o) {
  const int r = std::max(1, static_cast<int>(std::ceil(o.window_radius_px)));
  const cv::Rect frame(0, 0, signal.cols, signal.rows);
  const cv::Point c(static_cast<int>(std::lround(predicted.x)), static_cast<int>(std::lround(predicted.y)));
  const cv::Rect win = cv::Rect(c.x - r, c.y - r, 2 * r + 1, 2 * r + 1) & frame;
  if (win.area() == 0) return std::nullopt;
  double vmax = 0;
  cv::minMaxLoc(signal(win), nullptr, &vmax);
  if (vmax < o.min_peak) return std::nullopt;
  // Coarse centre: centre of mass of the binary mask above coarse_threshold * max.
  double sx = 0, sy = 0, n = 0;
  for (int y = win.y; y < win.y + win.height; ++y) {
    const float* p = signal.ptr<float>(y);
    for (int x = win.x; x < win.x + win.width; ++x)
      if (p[x] >= o.coarse_threshold * vmax) {
        sx += x;
        sy += y;
        n += 1;
      }
  }
  const cv::Point cc(static_cast<int>(std::lround(sx / n)), static_cast<int>(std::lround(sy / n)));
  // Patch around the coarse centre: pixels above patch_threshold * max, weighted by grey (4.10).
  const cv::Rect patch = cv::Rect(cc.x - r, cc.y - r, 2 * r + 1, 2 * r + 1) & frame;
  double wx = 0, wy = 0, w = 0;
  const double t = o.patch_threshold * vmax;
  for (int y = patch.y; y < patch.y + patch.height; ++y) {
    const float* p = signal.ptr<float>(y);
    for (int x = patch.x; x < patch.x + patch.width; ++x) {
      if ((x - cc.x) * (x - cc.x) + (y - cc.y) * (y - cc.y) > r * r) continue;
      if (p[x] >= t) {
        wx += x * p[x];
        wy += y * p[x];
        w += p[x];
      }
    }
  }
  if (w <= 0) return std::nullopt;
  return cv::Point2d(wx / w, wy / w);
}

Status GeometricCalibrationOptions::Validate() const {
  if (grid_spacing_px < 2) return Status::InvalidArgument("grid_spacing_px must be >= 2");
  if (!(centroid.coarse_threshold > 0 && centroid.coarse_threshold < 1) ||
      !(centroid.patch_threshold >= 0 && centroid.patch_threshold < 1)) {
    return Status::InvalidArgument("centroid thresholds must lie in (0, 1)");
  }
  return Status::Ok();
}

namespace {
// Jacobian of h at p (camera px per projector px).
cv::Matx22d HomographyJacobian(const cv::Matx33d& h, cv::Point2d p) {
  const double e = 0.5;
  const cv::Point2d dx = ApplyHomography(h, p + cv::Point2d(e, 0)) - ApplyHomography(h, p - cv::Point2d(e, 0));
  const cv::Point2d dy = ApplyHomography(h, p + cv::Point2d(0, e)) - ApplyHomography(h, p - cv::Point2d(0, e));
  return {dx.x / (2 * e), dy.x / (2 * e), dx.y / (2 * e), dy.y / (2 * e)};
}
}  // namespace

StatusOr<GeometricCalibration> EstimateGeometricCalibration(const std::vector<DotGridCapture>& captures,
                                                            const cv::Mat& black_image,
                                                            const cv::Matx33d& coarse_homography,
                                                            cv::Size projector_size,
                                                            const GeometricCalibrationOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (captures.empty()) return Status::InvalidArgument("geometry: no dot grid captures");
  if (projector_size.area() <= 0) return Status::InvalidArgument("geometry: projector_size must be positive");
  const cv::Size camera_size = captures[0].image.size();
  if (black_image.size() != camera_size) return Status::InvalidArgument("geometry: black_image differs in size");
  cv::Mat black;
  black_image.convertTo(black, CV_32F);
  const cv::Matx22d j =
      HomographyJacobian(coarse_homography, {projector_size.width / 2.0, projector_size.height / 2.0});
  const double scale = std::sqrt(std::abs(cv::determinant(j)));
  CentroidOptions co = options.centroid;
  if (co.window_radius_px <= 0) co.window_radius_px = std::max(1.5, 0.4 * options.grid_spacing_px * scale);

  GeometricCalibration g;
  g.projector_size = projector_size;
  g.camera_size = camera_size;
  g.grid_spacing_px = options.grid_spacing_px;
  g.projector_to_camera = cv::Mat(projector_size, CV_32FC2, cv::Scalar(kNaN, kNaN));
  const double margin = options.border_px;
  for (size_t k = 0; k < captures.size(); ++k) {
    const DotGridCapture& cap = captures[k];
    if (cap.image.size() != camera_size) {
      return Status::InvalidArgument("geometry: captures[" + std::to_string(k) + "] differs in size");
    }
    cv::Mat signal;
    cap.image.convertTo(signal, CV_32F);
    signal -= black;
    for (int v = cap.offset_y; v < projector_size.height; v += options.grid_spacing_px)
      for (int u = cap.offset_x; u < projector_size.width; u += options.grid_spacing_px) {
        const cv::Point2d pred = ApplyHomography(coarse_homography, {double(u), double(v)});
        if (pred.x < -margin || pred.y < -margin || pred.x > camera_size.width - 1 + margin ||
            pred.y > camera_size.height - 1 + margin) {
          continue;
        }
        // Dots whose window is cut by the frame would get a biased centroid.
        if (pred.x < co.window_radius_px - margin || pred.y < co.window_radius_px - margin ||
            pred.x > camera_size.width - 1 - co.window_radius_px + margin ||
            pred.y > camera_size.height - 1 - co.window_radius_px + margin) {
          continue;
        }
        const auto c = DotCentroid(signal, pred, co);
        if (c) g.projector_to_camera.at<cv::Vec2f>(v, u) = cv::Vec2f(float(c->x), float(c->y));
      }
  }
  INSPECT_RETURN_IF_ERROR(FinishGeometricCalibration(g));
  return g;
}

Status FinishGeometricCalibration(GeometricCalibration& g) {
  if (g.projector_to_camera.type() != CV_32FC2 || g.projector_to_camera.size() != g.projector_size) {
    return Status::InvalidArgument("geometry.projector_to_camera must be CV_32FC2 of the projector size");
  }
  std::vector<cv::Point2d> src, dst;
  for (int v = 0; v < g.projector_size.height; ++v)
    for (int u = 0; u < g.projector_size.width; ++u) {
      const cv::Vec2f c = g.projector_to_camera.at<cv::Vec2f>(v, u);
      if (!Valid(c)) continue;
      src.emplace_back(u, v);
      dst.emplace_back(c[0], c[1]);
    }
  g.valid_projector_pixels = static_cast<int>(src.size());
  if (src.size() < 4) {
    return Status::FailedPrecondition("geometry: only " + std::to_string(src.size()) +
                                      " dots found (is the plane in focus and lit?)");
  }
  INSPECT_ASSIGN_OR_RETURN(g.homography, FitHomography(src, dst));
  double sum = 0, sum2 = 0, mx = 0;
  for (size_t i = 0; i < src.size(); ++i) {
    const double d = cv::norm(ApplyHomography(g.homography, src[i]) - dst[i]);
    sum += d;
    sum2 += d * d;
    mx = std::max(mx, d);
  }
  const double n = static_cast<double>(src.size());
  g.lut_vs_homography_mean_px = sum / n;
  g.lut_vs_homography_std_px = std::sqrt(std::max(0.0, sum2 / n - (sum / n) * (sum / n)));
  g.lut_vs_homography_max_px = mx;
  const cv::Matx22d j = HomographyJacobian(g.homography, {g.projector_size.width / 2.0, g.projector_size.height / 2.0});
  g.camera_px_per_projector_px = std::sqrt(std::abs(cv::determinant(j)));
  g.projector_rotation_deg = std::atan2(j(1, 0), j(0, 0)) * 180.0 / CV_PI;

  // camera -> projector: every projector quad of four valid centroids is split into two
  // triangles; camera pixels inside get barycentric (u, v).
  g.camera_to_projector = cv::Mat(g.camera_size, CV_32FC2, cv::Scalar(kNaN, kNaN));
  const cv::Mat& lut = g.projector_to_camera;
  auto raster = [&](cv::Point2d a, cv::Point2d b, cv::Point2d c, cv::Point2d pa, cv::Point2d pb, cv::Point2d pc) {
    const double det = (b.y - c.y) * (a.x - c.x) + (c.x - b.x) * (a.y - c.y);
    if (std::abs(det) < 1e-12) return;
    const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({a.x, b.x, c.x}))));
    const int x1 = std::min(g.camera_size.width - 1, static_cast<int>(std::floor(std::max({a.x, b.x, c.x}))));
    const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({a.y, b.y, c.y}))));
    const int y1 = std::min(g.camera_size.height - 1, static_cast<int>(std::floor(std::max({a.y, b.y, c.y}))));
    for (int y = y0; y <= y1; ++y) {
      cv::Vec2f* out = g.camera_to_projector.ptr<cv::Vec2f>(y);
      for (int x = x0; x <= x1; ++x) {
        const double l1 = ((b.y - c.y) * (x - c.x) + (c.x - b.x) * (y - c.y)) / det;
        const double l2 = ((c.y - a.y) * (x - c.x) + (a.x - c.x) * (y - c.y)) / det;
        const double l3 = 1 - l1 - l2;
        if (l1 < -1e-9 || l2 < -1e-9 || l3 < -1e-9) continue;
        const cv::Point2d p = pa * l1 + pb * l2 + pc * l3;
        out[x] = cv::Vec2f(float(p.x), float(p.y));
      }
    }
  };
  for (int v = 0; v + 1 < g.projector_size.height; ++v)
    for (int u = 0; u + 1 < g.projector_size.width; ++u) {
      const cv::Vec2f a = lut.at<cv::Vec2f>(v, u), b = lut.at<cv::Vec2f>(v, u + 1);
      const cv::Vec2f c = lut.at<cv::Vec2f>(v + 1, u), d = lut.at<cv::Vec2f>(v + 1, u + 1);
      if (!Valid(a) || !Valid(b) || !Valid(c) || !Valid(d)) continue;
      const cv::Point2d ca(a[0], a[1]), cb(b[0], b[1]), cc(c[0], c[1]), cd(d[0], d[1]);
      raster(ca, cb, cd, {double(u), double(v)}, {u + 1.0, double(v)}, {u + 1.0, v + 1.0});
      raster(ca, cd, cc, {double(u), double(v)}, {u + 1.0, v + 1.0}, {double(u), v + 1.0});
    }
  return Status::Ok();
}

}  // namespace inspection
