// Filling pixels without depth (below the confidence threshold, NaN) from measured neighbours:
// optional post-processing for users who want a complete surface (photography, previews,
// meshes). Off by default: metrology reports NaN where nothing was measured (docs/reconstruction.md: depth
// convention), and a filled value is an interpolation, not a measurement; the confidence map
// still tells which pixels were measured.
//
// Method: push-pull (Gortler et al. 1996), guided by the all-in-focus image. Push: a pyramid of
// 2x2 reductions carries, per cell, the confidence-weighted mean depth of the measured pixels
// below it, their weight (clamped to 1) and their mean guide colour. Pull: from the coarsest
// level down, each cell that is not fully measured blends in the depths of the 2x2 nearest
// coarser cells, weighted bilinearly and, with guide_sigma > 0, by how close the cell's own
// guide colour is to the colour of the measured pixels behind each coarser cell
// (exp(-d^2 / (2 guide_sigma^2)), guide scaled to [0, 1]). So a textureless region takes its
// depth from the measured pixels around it that look like it (the edge of the same object), not
// from a different surface next to it. O(pixels); fills holes of any size.
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"

namespace inspection {

struct DepthFillOptions {
  // Guide colour difference (fraction of full scale) at which a coarser cell's weight falls to
  // e^-1/2; 0 = plain push-pull (no guide).
  double guide_sigma = 0.05;

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

// depth_um: CV_32FC1, NaN = no depth. confidence: CV_32FC1 weights of the measured pixels (empty:
// all 1). guide: the all-in-focus image (8/16-bit, 1 or 3 channels) of the same size; may be
// empty when guide_sigma is 0. Returns depth_um with every NaN pixel filled; measured pixels are
// unchanged. Without a single measured pixel the map is returned as it is (all NaN).
StatusOr<cv::Mat> FillDepth(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& guide,
                            const DepthFillOptions& options);

}  // namespace inspection
