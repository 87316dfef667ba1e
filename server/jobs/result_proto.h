// Domain -> proto for a job's result, in one home (the way back, proto -> domain, is
// server/api/request_mapping.h): the DepthSummary of a scan or a reconstruction with its method,
// alignment, post-processing and automatic z range figures.
#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "core/io/stack.h"
#include "core/registration/stack_alignment.h"
#include "core/sff/depth_postprocess.h"
#include "core/sff/halo_suppression.h"
#include "inspection/v1/inspection.pb.h"
#include "server/procedures/reconstruction_method.h"
#include "server/results/result_publisher.h"

namespace inspection {

// What one depth result's summary is made of. The pointers may be null: that part is then left
// at the proto's defaults.
struct DepthSummaryParts {
  DepthSummaryParts(const DepthResult& depth, double pixel_size_um, const cv::Mat& ground_truth_um, int window_px)
      : depth(depth), pixel_size_um(pixel_size_um), ground_truth_um(ground_truth_um), window_px(window_px) {}

  const DepthResult& depth;
  double pixel_size_um = 0.0;      // 0: unknown lateral scale
  const cv::Mat& ground_truth_um;  // empty: no error figures
  int window_px = 0;
  double engine_seconds = 0.0;
  const ReconstructionMethodSettings* method = nullptr;
  const IntegralSffFigures* integral = nullptr;  // with `method`
  const AlignmentFigures* alignment = nullptr;
  const DepthPostProcessFigures* postprocess = nullptr;
  const HaloSuppressionFigures* halo = nullptr;  // when halo suppression ran
  std::string illumination;                            // scans: the mode that ran
  std::string illumination_decision;                   // scans: why, for AUTO
  const ZRangeSearchRecord* z_range_search = nullptr;  // scans with the automatic z range
};

v1::DepthSummary DepthSummaryProto(const DepthSummaryParts& parts);

// The automatic z range of one scan as the API reports it.
v1::ZRangeSearchResult ZRangeSearchProto(const ZRangeSearchRecord& record);

}  // namespace inspection
