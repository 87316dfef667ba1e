// Point spread function of one projector pixel seen by the camera, at several defocus steps
// (thesis 4.3.3, Fig. 4.17/4.18), and the projector influence radius sigma_p of thesis 5.2.1
// (Fig. 5.9: the radius where a focused projector pixel's light has fallen to ~5 % of its
// centre value), which texture projection uses (eq. 5.15).
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/util/status.h"

namespace inspection {

struct PsfAtDefocus {
  double defocus_um = 0.0;  // stage offset from the focused position
  cv::Mat psf;              // CV_32FC1, odd square, centred, sums to 1
  double sigma_px = 0.0;    // Gaussian sigma from the second moment (camera px)
  int dot_count = 0;        // dots averaged into psf
};

// Plain data.
struct PsfCalibration {
  std::vector<PsfAtDefocus> steps;   // sorted by defocus_um
  double influence_radius_px = 0.0;  // sigma_p (camera px), from the step closest to focus

  Status Validate() const;
  // The step whose |defocus_um| is smallest.
  const PsfAtDefocus* Focused() const;
};

// One capture of a sparse dot grid at a known defocus.
struct PsfCapture {
  double defocus_um = 0.0;
  cv::Mat signal;                        // CV_32FC1 background-subtracted, linear in light
  std::vector<cv::Point2d> dot_centres;  // camera positions of the lit projector pixels
};

struct PsfOptions {
  int patch_radius_px = 10;          // psf is (2r+1)^2; keep below half the dot distance
  double influence_fraction = 0.05;  // sigma_p: where the profile falls to this of its peak

  Status Validate() const;
};

// Averages the sub-pixel-centred patches of every dot (thesis: "the mean of the circular
// patch at different surface positions"), removes the residual background (median of the
// patch border), normalises, and measures sigma and, for the focused step, sigma_p.
StatusOr<PsfCalibration> EstimatePsf(const std::vector<PsfCapture>& captures, const PsfOptions& options);

// Second-moment Gaussian sigma of a centred PSF (iteratively windowed to 4 sigma).
double PsfSigmaPx(const cv::Mat& psf);

}  // namespace inspection
