// Regions of interest: pixel-centre rasterisation of rectangles and polygons in px and um,
// coverage against NaN depth, and validation messages that name the field.
#include "core/metrology/surface_roi.h"

#include <gtest/gtest.h>

#include <cmath>

namespace inspection {
namespace {

cv::Mat Depth(int w, int h) { return cv::Mat(h, w, CV_32FC1, cv::Scalar(200.f)); }

TEST(SurfaceRoiTest, WholeFieldCoversEveryPixelAndCountsMissingDepth) {
  cv::Mat d = Depth(40, 30);
  d(cv::Rect(0, 0, 10, 3)).setTo(NAN);  // 30 pixels without depth
  auto m = RasteriseRoi(RegionOfInterest::WholeField(), d, 0.74);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->region_pixels, 1200u);
  EXPECT_EQ(m->measured_pixels, 1170u);
  EXPECT_DOUBLE_EQ(m->coverage_percent(), 97.5);
  EXPECT_EQ(m->bounds, cv::Rect(0, 0, 40, 30));
}

TEST(SurfaceRoiTest, RectangleTakesThePixelsWhoseCentresLieInside) {
  cv::Mat d = Depth(40, 30);
  // [2.4, 7.4) x [3, 5): centres 2.5 .. 6.5 in x (cols 2..6), 3.5, 4.5 in y (rows 3, 4).
  auto m = RasteriseRoi(RegionOfInterest::Rectangle(2.4, 3.0, 5.0, 2.0), d, 0.74);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->region_pixels, 10u);
  EXPECT_EQ(m->bounds, cv::Rect(2, 3, 5, 2));
  // The same rectangle in um (0.5 um pixels) and two rectangles sharing an edge share no pixel.
  auto um = RasteriseRoi(RegionOfInterest::Rectangle(1.2, 1.5, 2.5, 1.0, RoiUnit::kMicrometre), d, 0.5);
  ASSERT_TRUE(um.ok()) << um.status().ToString();
  EXPECT_EQ(cv::countNonZero(um->region != m->region), 0);
  auto left = RasteriseRegion(RegionOfInterest::Rectangle(0, 0, 20, 30), d.size(), 1.0);
  auto right = RasteriseRegion(RegionOfInterest::Rectangle(20, 0, 20, 30), d.size(), 1.0);
  ASSERT_TRUE(left.ok() && right.ok());
  EXPECT_EQ(cv::countNonZero(*left & *right), 0);
  EXPECT_EQ(cv::countNonZero(*left | *right), 1200);
}

TEST(SurfaceRoiTest, PolygonPixelCountMatchesItsArea) {
  cv::Mat d = Depth(200, 150);
  // Triangle of area 0.5 * 120 * 100 = 6000 px^2 and a concave L of area 100*100 - 60*60 = 6400.
  auto tri = RasteriseRoi(RegionOfInterest::Polygon({{40, 20}, {160, 20}, {40, 120}}), d, 1.0);
  ASSERT_TRUE(tri.ok()) << tri.status().ToString();
  // Pixel-centre sampling of a region with perimeter P errs by at most ~P/2 pixels; for these
  // axis-aligned and 45-degree-ish edges the count is within 1 % of the area.
  EXPECT_NEAR(double(tri->region_pixels), 6000.0, 60.0);
  auto ell =
      RasteriseRoi(RegionOfInterest::Polygon({{10, 10}, {110, 10}, {110, 50}, {50, 50}, {50, 110}, {10, 110}}), d, 1.0);
  ASSERT_TRUE(ell.ok()) << ell.status().ToString();
  EXPECT_EQ(ell->region_pixels, 6400u);           // edges on integer coordinates: exact
  EXPECT_EQ(ell->region.at<uint8_t>(80, 80), 0);  // the notch is outside
  EXPECT_EQ(ell->region.at<uint8_t>(80, 20), 255);
  // Reversed orientation gives the same mask.
  auto rev =
      RasteriseRoi(RegionOfInterest::Polygon({{10, 110}, {50, 110}, {50, 50}, {110, 50}, {110, 10}, {10, 10}}), d, 1.0);
  ASSERT_TRUE(rev.ok());
  EXPECT_EQ(cv::countNonZero(rev->region != ell->region), 0);
}

TEST(SurfaceRoiTest, CoverageCountsOnlyTheRegionsPixels) {
  cv::Mat d = Depth(40, 30);
  d(cv::Rect(0, 0, 5, 30)).setTo(NAN);  // left strip without depth, outside the region
  d.at<float>(12, 12) = NAN;            // one inside
  auto m = RasteriseRoi(RegionOfInterest::Rectangle(10, 10, 10, 10), d, 1.0);
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->region_pixels, 100u);
  EXPECT_EQ(m->measured_pixels, 99u);
  EXPECT_EQ(m->measured.at<uint8_t>(12, 12), 0);
  EXPECT_DOUBLE_EQ(m->coverage_percent(), 99.0);
}

void ExpectInvalid(const RegionOfInterest& roi, const std::string& needle, double px = 1.0) {
  const Status s = ValidateRoi(roi, cv::Size(100, 80), px, "measurements[3].roi");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << needle;
  EXPECT_NE(s.message().find("measurements[3].roi"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find(needle), std::string::npos) << s.message();
}

TEST(SurfaceRoiTest, ValidationNamesTheFieldAndTheProblem) {
  ExpectInvalid(RegionOfInterest::Rectangle(90, 0, 20, 10), "exceeds the image width 100 px");
  ExpectInvalid(RegionOfInterest::Rectangle(0, 75, 20, 10), "exceeds the image height 80 px");
  ExpectInvalid(RegionOfInterest::Rectangle(-1, 0, 20, 10), ".x");
  ExpectInvalid(RegionOfInterest::Rectangle(0, 0, 0, 10), ".width must be > 0");
  ExpectInvalid(RegionOfInterest::Rectangle(0, 0, 10, NAN), ".height is not a finite number");
  ExpectInvalid(RegionOfInterest::Rectangle(10.1, 10.1, 0.2, 0.2), "contains no pixel centre");
  // 80 um at 0.74 um/px = 108 px: outside a 100 px wide image.
  ExpectInvalid(RegionOfInterest::Rectangle(0, 0, 80, 10, RoiUnit::kMicrometre), "exceeds the image width", 0.74);
  ExpectInvalid(RegionOfInterest::Rectangle(0, 0, 8, 8, RoiUnit::kMicrometre), "pixel size > 0", 0.0);
  ExpectInvalid(RegionOfInterest::Polygon({}), "polygon is empty");
  ExpectInvalid(RegionOfInterest::Polygon({{0, 0}, {10, 10}}), "has 2 vertices");
  ExpectInvalid(RegionOfInterest::Polygon({{0, 0}, {10, 10}, {20, 20}}), "zero area");
  ExpectInvalid(RegionOfInterest::Polygon({{0, 0}, {30, 20}, {30, 0}, {0, 10}}), "edges 0 and 2 cross");  // bow tie
  ExpectInvalid(RegionOfInterest::Polygon({{0, 0}, {50, 0}, {50, 50}, {200, 50}}), "polygon[3]");
  ExpectInvalid(RegionOfInterest::Polygon({{0, 0}, {50, 0}, {50, 0}, {0, 50}}), "coincide");
  ExpectInvalid(RegionOfInterest::Polygon({{0, 0}, {NAN, 0}, {0, 50}}), "polygon[1] is not a finite point");
  EXPECT_TRUE(ValidateRoi(RegionOfInterest::Rectangle(0, 0, 100, 80), cv::Size(100, 80), 1.0, "roi").ok());
  // um rounding at the image edge: 74 um / 0.74 um = 100.00000000000001 px is still inside.
  EXPECT_TRUE(
      ValidateRoi(RegionOfInterest::Rectangle(0, 0, 74, 59.2, RoiUnit::kMicrometre), cv::Size(100, 80), 0.74, "roi")
          .ok());
}

TEST(SurfaceRoiTest, ShapeAndUnitNamesRoundTrip) {
  for (RoiShape s : {RoiShape::kWholeField, RoiShape::kRectangle, RoiShape::kPolygon}) {
    auto p = ParseRoiShape(RoiShapeName(s));
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(*p, s);
  }
  EXPECT_EQ(*ParseRoiUnit("um"), RoiUnit::kMicrometre);
  EXPECT_EQ(ParseRoiShape("circle").status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ParseRoiUnit("mm").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
