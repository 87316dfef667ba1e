// Regions of interest (ISO 25178-2 definition area): validation naming the field, rasterisation
// by pixel centres, intersection with the measured pixels.
#include "core/metrology/surface_roi.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

// Rounding slack when µm coordinates are converted to pixels (757.76 um / 0.74 um = 1024.0000000001).
constexpr double kEdgeSlackPx = 1e-6;

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

const char* UnitSuffix(RoiUnit unit) { return unit == RoiUnit::kPixel ? "px" : "um"; }

// Orientation of c against the line a->b: > 0 left turn, < 0 right turn, 0 collinear.
double Cross(const RoiPoint& a, const RoiPoint& b, const RoiPoint& c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

bool OnSegment(const RoiPoint& a, const RoiPoint& b, const RoiPoint& p) {
  return std::min(a.x, b.x) <= p.x && p.x <= std::max(a.x, b.x) && std::min(a.y, b.y) <= p.y &&
         p.y <= std::max(a.y, b.y);
}

// Closed segments ab and cd share at least one point.
bool SegmentsTouch(const RoiPoint& a, const RoiPoint& b, const RoiPoint& c, const RoiPoint& d) {
  const double d1 = Cross(c, d, a), d2 = Cross(c, d, b), d3 = Cross(a, b, c), d4 = Cross(a, b, d);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return true;
  return (d1 == 0 && OnSegment(c, d, a)) || (d2 == 0 && OnSegment(c, d, b)) || (d3 == 0 && OnSegment(a, b, c)) ||
         (d4 == 0 && OnSegment(a, b, d));
}

// Pixel index range [first, end) whose centres i + 0.5 lie in [lo, hi).
void CentreRange(double lo, double hi, int limit, int* first, int* end) {
  *first = std::max(0, int(std::ceil(lo - 0.5)));
  *end = std::min(limit, int(std::ceil(hi - 0.5)));
}

// Polygon vertices in pixels.
std::vector<RoiPoint> PolygonPx(const RegionOfInterest& roi, double scale) {
  std::vector<RoiPoint> v = roi.polygon;
  for (RoiPoint& p : v) {
    p.x *= scale;
    p.y *= scale;
  }
  return v;
}

void FillPolygon(const std::vector<RoiPoint>& v, cv::Mat& mask) {
  const size_t n = v.size();
  std::vector<double> xs;
  for (int row = 0; row < mask.rows; ++row) {
    const double yc = row + 0.5;
    xs.clear();
    for (size_t i = 0; i < n; ++i) {
      const RoiPoint& a = v[i];
      const RoiPoint& b = v[(i + 1) % n];
      // Half-open in y so a vertex on the scan line is counted once.
      if ((a.y <= yc && yc < b.y) || (b.y <= yc && yc < a.y)) {
        xs.push_back(a.x + (yc - a.y) * (b.x - a.x) / (b.y - a.y));
      }
    }
    std::sort(xs.begin(), xs.end());
    uint8_t* m = mask.ptr<uint8_t>(row);
    for (size_t k = 0; k + 1 < xs.size(); k += 2) {
      int first, end;
      CentreRange(xs[k], xs[k + 1], mask.cols, &first, &end);
      for (int col = first; col < end; ++col) m[col] = 255;
    }
  }
}

Status ValidateRectangle(const RegionOfInterest& roi, cv::Size size, double scale, const std::string& field) {
  const char* u = UnitSuffix(roi.unit);
  for (auto [name, v] :
       {std::pair<const char*, double>{"x", roi.x}, {"y", roi.y}, {"width", roi.width}, {"height", roi.height}}) {
    if (!std::isfinite(v)) return Status::InvalidArgument(field + "." + name + " is not a finite number");
  }
  if (!(roi.width > 0.0)) return Status::InvalidArgument(field + ".width must be > 0, got " + Num(roi.width) + " " + u);
  if (!(roi.height > 0.0)) {
    return Status::InvalidArgument(field + ".height must be > 0, got " + Num(roi.height) + " " + u);
  }
  const double x0 = roi.x * scale, y0 = roi.y * scale;
  const double x1 = (roi.x + roi.width) * scale, y1 = (roi.y + roi.height) * scale;
  if (x0 < -kEdgeSlackPx)
    return Status::InvalidArgument(field + ".x = " + Num(roi.x) + " " + u + " lies left of the image");
  if (y0 < -kEdgeSlackPx)
    return Status::InvalidArgument(field + ".y = " + Num(roi.y) + " " + u + " lies above the image");
  if (x1 > size.width + kEdgeSlackPx) {
    return Status::InvalidArgument(field + ": x + width = " + Num(x1) + " px exceeds the image width " +
                                   std::to_string(size.width) + " px");
  }
  if (y1 > size.height + kEdgeSlackPx) {
    return Status::InvalidArgument(field + ": y + height = " + Num(y1) + " px exceeds the image height " +
                                   std::to_string(size.height) + " px");
  }
  int c0, c1, r0, r1;
  CentreRange(x0, x1, size.width, &c0, &c1);
  CentreRange(y0, y1, size.height, &r0, &r1);
  if (c1 <= c0 || r1 <= r0) {
    return Status::InvalidArgument(field + ": the rectangle contains no pixel centre (degenerate region)");
  }
  return Status::Ok();
}

Status ValidatePolygon(const RegionOfInterest& roi, cv::Size size, double scale, const std::string& field) {
  const std::string pf = field + ".polygon";
  const size_t n = roi.polygon.size();
  if (n == 0) return Status::InvalidArgument(pf + " is empty (needs >= 3 vertices)");
  if (n < 3) return Status::InvalidArgument(pf + " has " + std::to_string(n) + " vertices (needs >= 3)");
  if (n > kMaxPolygonVertices) {
    return Status::InvalidArgument(pf + " has " + std::to_string(n) + " vertices (at most " +
                                   std::to_string(kMaxPolygonVertices) + ")");
  }
  const std::vector<RoiPoint> v = PolygonPx(roi, scale);
  for (size_t i = 0; i < n; ++i) {
    const std::string vf = pf + "[" + std::to_string(i) + "]";
    if (!std::isfinite(roi.polygon[i].x) || !std::isfinite(roi.polygon[i].y)) {
      return Status::InvalidArgument(vf + " is not a finite point");
    }
    if (v[i].x < -kEdgeSlackPx || v[i].y < -kEdgeSlackPx || v[i].x > size.width + kEdgeSlackPx ||
        v[i].y > size.height + kEdgeSlackPx) {
      return Status::InvalidArgument(vf + " = (" + Num(v[i].x) + ", " + Num(v[i].y) + ") px lies outside the image " +
                                     std::to_string(size.width) + "x" + std::to_string(size.height) + " px");
    }
  }
  for (size_t i = 0; i < n; ++i) {
    const RoiPoint& a = v[i];
    const RoiPoint& b = v[(i + 1) % n];
    if (a.x == b.x && a.y == b.y) {
      return Status::InvalidArgument(pf + ": vertices " + std::to_string(i) + " and " + std::to_string((i + 1) % n) +
                                     " coincide");
    }
  }
  double area2 = 0.0;
  for (size_t i = 0; i < n; ++i) area2 += v[i].x * v[(i + 1) % n].y - v[(i + 1) % n].x * v[i].y;
  if (!(std::abs(area2) > 1e-12)) return Status::InvalidArgument(pf + " has zero area (degenerate polygon)");
  // Edge i runs from vertex i to i + 1. Neighbouring edges share a vertex; they may not fold back
  // onto each other. Other pairs may not touch at all (a simple polygon).
  for (size_t i = 0; i < n; ++i) {
    const RoiPoint& a = v[i];
    const RoiPoint& b = v[(i + 1) % n];
    for (size_t j = i + 1; j < n; ++j) {
      const RoiPoint& c = v[j];
      const RoiPoint& d = v[(j + 1) % n];
      const bool adjacent = j == i + 1 || (i == 0 && j == n - 1);
      bool bad;
      if (adjacent) {
        // Shared vertex s; the edges overlap iff they are collinear and point the same way from s.
        const RoiPoint& s = j == i + 1 ? b : a;
        const RoiPoint& p = j == i + 1 ? a : b;
        const RoiPoint& q = j == i + 1 ? d : c;
        bad = Cross(s, p, q) == 0.0 && ((p.x - s.x) * (q.x - s.x) + (p.y - s.y) * (q.y - s.y)) > 0.0;
      } else {
        bad = SegmentsTouch(a, b, c, d);
      }
      if (bad) {
        return Status::InvalidArgument(pf + ": edges " + std::to_string(i) + " and " + std::to_string(j) +
                                       " cross or touch (the polygon must be simple)");
      }
    }
  }
  cv::Mat m(size, CV_8UC1, cv::Scalar(0));
  FillPolygon(v, m);
  if (cv::countNonZero(m) == 0) {
    return Status::InvalidArgument(pf + " contains no pixel centre (degenerate region)");
  }
  return Status::Ok();
}

}  // namespace

const char* RoiShapeName(RoiShape shape) {
  switch (shape) {
    case RoiShape::kWholeField:
      return "whole_field";
    case RoiShape::kRectangle:
      return "rectangle";
    case RoiShape::kPolygon:
      return "polygon";
  }
  return "unknown";
}

StatusOr<RoiShape> ParseRoiShape(const std::string& name) {
  for (RoiShape s : {RoiShape::kWholeField, RoiShape::kRectangle, RoiShape::kPolygon}) {
    if (name == RoiShapeName(s)) return s;
  }
  return Status::InvalidArgument("unknown ROI shape '" + name + "' (whole_field, rectangle, polygon)");
}

StatusOr<RoiUnit> ParseRoiUnit(const std::string& name) {
  if (name == "px") return RoiUnit::kPixel;
  if (name == "um") return RoiUnit::kMicrometre;
  return Status::InvalidArgument("unknown ROI unit '" + name + "' (px, um)");
}

RegionOfInterest RegionOfInterest::Rectangle(double x, double y, double width, double height, RoiUnit unit) {
  RegionOfInterest r;
  r.shape = RoiShape::kRectangle;
  r.unit = unit;
  r.x = x;
  r.y = y;
  r.width = width;
  r.height = height;
  return r;
}

RegionOfInterest RegionOfInterest::Polygon(std::vector<RoiPoint> vertices, RoiUnit unit) {
  RegionOfInterest r;
  r.shape = RoiShape::kPolygon;
  r.unit = unit;
  r.polygon = std::move(vertices);
  return r;
}

Status ValidateRoi(const RegionOfInterest& roi, cv::Size image_size, double pixel_size_um, const std::string& field) {
  if (image_size.width <= 0 || image_size.height <= 0) {
    return Status::InvalidArgument(field + ": the image is empty");
  }
  double scale = 1.0;
  if (roi.unit == RoiUnit::kMicrometre) {
    if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um)) {
      return Status::InvalidArgument(field + ": coordinates in um need a pixel size > 0, got " + Num(pixel_size_um));
    }
    scale = 1.0 / pixel_size_um;
  }
  switch (roi.shape) {
    case RoiShape::kWholeField:
      return Status::Ok();
    case RoiShape::kRectangle:
      return ValidateRectangle(roi, image_size, scale, field);
    case RoiShape::kPolygon:
      return ValidatePolygon(roi, image_size, scale, field);
  }
  return Status::InvalidArgument(field + ".shape is not a known shape");
}

StatusOr<cv::Mat> RasteriseRegion(const RegionOfInterest& roi, cv::Size image_size, double pixel_size_um,
                                  const std::string& field) {
  INSPECT_RETURN_IF_ERROR(ValidateRoi(roi, image_size, pixel_size_um, field));
  const double scale = roi.unit == RoiUnit::kMicrometre ? 1.0 / pixel_size_um : 1.0;
  cv::Mat m(image_size, CV_8UC1, cv::Scalar(0));
  switch (roi.shape) {
    case RoiShape::kWholeField:
      m.setTo(255);
      break;
    case RoiShape::kRectangle: {
      int c0, c1, r0, r1;
      CentreRange(roi.x * scale, (roi.x + roi.width) * scale, image_size.width, &c0, &c1);
      CentreRange(roi.y * scale, (roi.y + roi.height) * scale, image_size.height, &r0, &r1);
      m(cv::Rect(c0, r0, c1 - c0, r1 - r0)).setTo(255);
      break;
    }
    case RoiShape::kPolygon:
      FillPolygon(PolygonPx(roi, scale), m);
      break;
  }
  return m;
}

StatusOr<RoiMask> RasteriseRoi(const RegionOfInterest& roi, const cv::Mat& depth_um, double pixel_size_um,
                               const std::string& field) {
  if (depth_um.empty() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument(field + ": the depth map must be a non-empty CV_32FC1 image");
  }
  RoiMask out;
  INSPECT_ASSIGN_OR_RETURN(out.region, RasteriseRegion(roi, depth_um.size(), pixel_size_um, field));
  out.measured = cv::Mat(depth_um.size(), CV_8UC1, cv::Scalar(0));
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* d = depth_um.ptr<float>(row);
    const uint8_t* r = out.region.ptr<uint8_t>(row);
    uint8_t* m = out.measured.ptr<uint8_t>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (!r[col]) continue;
      ++out.region_pixels;
      if (std::isfinite(d[col])) {
        m[col] = 255;
        ++out.measured_pixels;
      }
    }
  }
  out.bounds = cv::boundingRect(out.region);
  return out;
}

}  // namespace inspection
