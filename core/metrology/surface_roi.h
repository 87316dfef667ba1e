// Regions of interest on a depth map (the "definition area" of ISO 25178-2 3.1.9): a rectangle,
// a polygon or the whole field, in pixels or µm, rasterised to a pixel mask and intersected with
// the measured (finite-depth) pixels; coverage = measured share of the region.
//
// Coordinates (px or µm) are measured from the image's top-left corner, x to the right (columns),
// y down (rows). Pixel (col, row) covers [col, col + 1) x [row, row + 1) px; its centre is at
// (col + 0.5, row + 0.5) px = ((col + 0.5) p, (row + 0.5) p) µm with p = pixel_size_um. A pixel
// belongs to a region when its centre lies inside (half-open on the right and bottom edges, so
// regions that share an edge never share a pixel). The whole image spans [0, width] x [0, height].
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

enum class RoiShape {
  kWholeField,  // every pixel of the image
  kRectangle,   // axis-aligned: x, y (top-left corner), width, height
  kPolygon,     // simple polygon (edges must not cross), >= 3 vertices, either orientation
};

enum class RoiUnit {
  kPixel,       // coordinates in camera pixels
  kMicrometre,  // coordinates in µm on the specimen (divided by pixel_size_um)
};

const char* RoiShapeName(RoiShape shape);  // "whole_field", "rectangle", "polygon"
StatusOr<RoiShape> ParseRoiShape(const std::string& name);
StatusOr<RoiUnit> ParseRoiUnit(const std::string& name);

struct RoiPoint {
  double x = 0.0;
  double y = 0.0;
};

// A region as a recipe states it. Plain data; RasteriseRoi checks it against an image.
struct RegionOfInterest {
  RoiShape shape = RoiShape::kWholeField;
  RoiUnit unit = RoiUnit::kPixel;
  // kRectangle: top-left corner and size, in `unit`. width, height > 0.
  double x = 0.0;
  double y = 0.0;
  double width = 0.0;
  double height = 0.0;
  // kPolygon: vertices in `unit`, in order (closing edge implied); 3..kMaxPolygonVertices.
  std::vector<RoiPoint> polygon;

  static RegionOfInterest WholeField() { return {}; }
  static RegionOfInterest Rectangle(double x, double y, double width, double height, RoiUnit unit = RoiUnit::kPixel);
  static RegionOfInterest Polygon(std::vector<RoiPoint> vertices, RoiUnit unit = RoiUnit::kPixel);
};

inline constexpr size_t kMaxPolygonVertices = 1000;

// Checks the region against an image of image_size pixels of pixel_size_um (> 0, used only for
// kMicrometre). INVALID_ARGUMENT with a message that starts with `field` (e.g.
// "measurements[2].roi") and names what is wrong: a non-finite or non-positive size, a region
// reaching outside the image ("x + width = 1100 px exceeds the image width 1024 px"; regions must
// lie inside the image, so a recipe never silently measures less than it says), a polygon with
// fewer than 3 vertices, zero area or crossing edges, or a region that contains no pixel centre.
Status ValidateRoi(const RegionOfInterest& roi, cv::Size image_size, double pixel_size_um, const std::string& field);

// A rasterised region on one depth map.
struct RoiMask {
  cv::Mat region;    // CV_8UC1, 255 on every pixel of the region (measured or not)
  cv::Mat measured;  // CV_8UC1, 255 on the region's pixels with finite depth
  cv::Rect bounds;   // bounding box of `region` (pixels)
  size_t region_pixels = 0;
  size_t measured_pixels = 0;
  // measured_pixels / region_pixels in percent (0 for an empty region).
  double coverage_percent() const {
    return region_pixels ? 100.0 * double(measured_pixels) / double(region_pixels) : 0.0;
  }
};

// Validates (see ValidateRoi) and rasterises the region on depth_um (CV_32FC1, NaN = no depth).
// A region with no measured pixel is not an error here (coverage 0 %): the caller decides
// (a verdict is then NOT_DECIDABLE); measurement functions return FAILED_PRECONDITION when they
// get too few measured pixels.
StatusOr<RoiMask> RasteriseRoi(const RegionOfInterest& roi, const cv::Mat& depth_um, double pixel_size_um,
                               const std::string& field = "roi");

// Region mask alone (no depth map): CV_8UC1 of image_size, 255 inside. Validates like ValidateRoi.
StatusOr<cv::Mat> RasteriseRegion(const RegionOfInterest& roi, cv::Size image_size, double pixel_size_um,
                                  const std::string& field = "roi");

}  // namespace inspection
