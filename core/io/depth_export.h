// Depth map exports: float32 TIFF (µm), confidence TIFF, colour preview with scale bar,
// 16-bit PNG with recorded scale/offset, PLY point cloud and ISO 25178-72 x3p.
// Every writer writes to "<path>.tmp" and renames, so a failed export leaves nothing behind.
#pragma once

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <string_view>

#include "core/util/status.h"

namespace inspection {

struct DepthExportMeta {
  double pixel_size_um = 0.0;  // lateral sampling in x and y; 0 = unknown scale
  std::string description;     // free text stored where the format allows (TIFF ImageDescription, x3p comment)
  // > 0: pixels with a depth and confidence below this were inferred (dense depth, fill), not
  // measured; the depth preview hatches them.
  double inferred_below_confidence = 0.0;
};

// float32 single-channel TIFF, values in µm, NaN where no depth. Pixel size stored as resolution.
Status WriteDepthTiff(const std::filesystem::path& path, const cv::Mat& depth_um, const DepthExportMeta& meta);
// Reads back a float32 TIFF written by WriteDepthTiff (or ground_truth_depth.tiff).
// Also reads float32 (or float64, converted) TIFFs written by cv::imwrite, striped or tiled.
StatusOr<cv::Mat> ReadDepthTiff(const std::filesystem::path& path);
// As above; when meta is not null it receives the pixel size (from the resolution tags,
// 0 if absent) and the ImageDescription.
StatusOr<cv::Mat> ReadDepthTiff(const std::filesystem::path& path, DepthExportMeta* meta);
// float32 TIFF of confidence values in [0, 1].
Status WriteConfidenceTiff(const std::filesystem::path& path, const cv::Mat& confidence, const DepthExportMeta& meta);
// 8-bit colour PNG: depth through a perceptual colour map, NaN in black, with a scale bar
// labelled in µm along the right edge.
// inferred: optional CV_8UC1 mask (non-zero = depth inferred by dense depth or fill, not
// measured) of depth_um's size; those pixels are drawn at 55 % brightness with a grey diagonal
// hatch every 4 px, and the panel says so.
Status WriteDepthPreviewPng(const std::filesystem::path& path, const cv::Mat& depth_um,
                            const cv::Mat& inferred = cv::Mat());
// The same preview in memory (CV_8UC3, BGR), e.g. for the inspection report: the map at its own
// size on the left, the colour bar panel (kDepthPreviewPanelWidthPx wide) on the right, at least
// kDepthPreviewMinHeightPx tall. INVALID_ARGUMENT when depth_um is empty or not CV_32FC1.
inline constexpr int kDepthPreviewPanelWidthPx = 110;
inline constexpr int kDepthPreviewMinHeightPx = 200;
StatusOr<cv::Mat> RenderDepthPreview(const cv::Mat& depth_um, const cv::Mat& inferred = cv::Mat());
// 16-bit PNG: value = round((depth_um - offset_um) / scale_um), 0 reserved for NaN; scale and
// offset go into a tEXt chunk and a sidecar "<path>.json".
Status WriteDepthPng16(const std::filesystem::path& path, const cv::Mat& depth_um, const DepthExportMeta& meta);
// Binary little-endian PLY (float x, y, z): x, y = pixel column/row * pixel_size_um, z =
// depth_um; NaN points are skipped. pixel_size_um 0 = unknown scale: x, y are the column/row
// and a header comment says "unknown scale".
Status WriteDepthPly(const std::filesystem::path& path, const cv::Mat& depth_um, const DepthExportMeta& meta);
// ISO 25178-72 x3p: zip holding main.xml (Record1 axes: CX/CY incremental with the pixel size
// in metres, CZ absolute float64; Record2 creator/instrument; Record3 matrix size and the md5 of
// bindata), bindata/data.bin (float64 metres, x fastest, NaN = not measured) and md5checksum.hex
// ("<md5 of main.xml> *main.xml", as md5sum writes it). Checked against Gwyddion's reader.
// pixel_size_um 0 = unknown scale: 1e-6 m increments (one unit per pixel) and Record2's
// Comment starts with "unknown scale".
Status WriteDepthX3p(const std::filesystem::path& path, const cv::Mat& depth_um, const DepthExportMeta& meta);

// Scale and offset chosen by WriteDepthPng16 for a map (value 1 = the smallest finite depth,
// 65535 = the largest); also what its tEXt chunk and sidecar record.
struct DepthPng16Scaling {
  double scale_um = 1.0;
  double offset_um = 0.0;
};
DepthPng16Scaling ChooseDepthPng16Scaling(const cv::Mat& depth_um);

// MD5 (RFC 1321) of a byte buffer as 32 lower-case hex digits, as x3p records it.
std::string Md5Hex(const void* data, size_t size);

// Text for XML or HTML element content and attribute values: & < > " ' as character references
// (&#39; for the apostrophe, which XML and every HTML version read). The x3p comment and the
// HTML report's text (server/results) both use it.
std::string XmlEscape(std::string_view text);

}  // namespace inspection
