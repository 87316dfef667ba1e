// High-frequency texture projection (thesis 5.2): the checkerboard period chosen from the
// projector influence radius sigma_p and the focus window (eq. 5.15), the checkerboard of
// eq. 5.16, and the modified pattern added to an adapted pattern (eq. 5.17-5.18), in grey levels or
// mean-preserving for an adapted irradiance.
#pragma once

#include <opencv2/core.hpp>

#include "core/calibration/projector_response.h"
#include "core/util/status.h"

namespace inspection {

// Checker cell size for eq. 5.15: the half period t/2 (camera px) must satisfy
// 2 sigma_p < t/2 < m + 2. t/2 is a whole number of projector pixels times the projector-to-
// camera pixel ratio (thesis: t = {3.4, 6.8, ...}).
struct TexturePeriod {
  int cell_projector_px = 0;         // projector pixels per checker cell (= t/2 in projector px)
  double half_period_camera_px = 0;  // t/2 in camera px
};

// influence_radius_px: sigma_p (camera px, core/calibration/psf_calibration.h); camera_px_per_projector_px:
// ratio of the geometric calibration (> 0); focus_window_px: m of the focus measure (odd >= 3).
// Takes the smallest cell with t/2 > 2 sigma_p. FAILED_PRECONDITION when that cell's t/2 is not
// below m + 2 (the window is too small for the projector's blur: enlarge window_px).
StatusOr<TexturePeriod> ChooseTexturePeriod(double influence_radius_px, double camera_px_per_projector_px,
                                            int focus_window_px);

// Binary checkerboard CB(x, y) of eq. 5.16: 1 where (x / cell + y / cell) is even. CV_8UC1 0/1.
cv::Mat CheckerboardMask(cv::Size projector_size, int cell_projector_px);

// Eq. 5.16: 255 gamma where CB = 1, 255 (1 - gamma) where CB = 0, gamma in [0, 0.5]
// (0 = full contrast for textureless surfaces, 0.5 = uniform 128). CV_8UC1.
StatusOr<cv::Mat> MakeHfPattern(cv::Size projector_size, int cell_projector_px, double gamma);

// Eq. 5.17-5.18: adapted + 255 psi where CB = 1 and - 255 psi where CB = 0, clamped to [0, 255].
// adapted: CV_8UC1 or CV_32FC1 (grey levels); cb: CheckerboardMask of the same size; psi in
// [0, 1]. Returns CV_8UC1.
StatusOr<cv::Mat> AddHfPattern(const cv::Mat& adapted, const cv::Mat& cb, double psi);

// Eq. 5.17-5.18 for an adapted projector irradiance (CV_32FC1, prf units; e.g. the output of
// the compensation): per pixel the grey g + 255 psi where CB = 1 and g - 255 psi where CB = 0
// (clamped to [0, 255]), with g chosen so that the pair's mean irradiance,
// (prf(g + 255 psi) + prf(g - 255 psi)) / 2, is the adapted irradiance. g is at most
// 255 - 255 psi: where the compensation asks for more light than that pair gives (dark parts of
// the specimen), the pair stays at 255 / 255 - 2 * 255 psi, keeping the texture's full swing,
// instead of clamping g + 255 psi at 255 as eq. 5.18 would (which shrinks the swing where the
// texture is needed most: on the weld bead's dark flanks HF+ADAPT measured 62 % of the pixels
// with the clamp and 71 % without). Adding the same grey
// offsets to prf^-1(adapted) instead (AddHfPattern) adds mean light through the convex prf, so the
// camera image misses the compensation's target (mean grey 160-180 for a target of 140 with the
// simulated gamma-2 projector) and texture peaks saturate at focus. Returns CV_8UC1.
StatusOr<cv::Mat> AddHfPatternToIrradiance(const cv::Mat& adapted_irradiance, const cv::Mat& cb, double psi,
                                           const ProjectorResponseFunction& prf);

// Section 5.3.2: the desired camera image for ADAPTED-HF, a checkerboard in camera pixels with
// half period half_period_camera_px at low / high grey (thesis: 25 % / 75 % of full scale,
// 60 and 190 for 8 bit). CV_32FC1 grey levels of the camera.
cv::Mat CameraCheckerboard(cv::Size camera_size, double half_period_camera_px, double low_grey, double high_grey);

}  // namespace inspection
