// z linearity of the SFF depth (ISO 25178-600's linearity deviation l_z, as a function of where
// a height falls between two frames): the peak interpolation of thesis 3.1.4 (eq. 3.23-3.34)
// is exact only for an ideal focus curve, so the depth error is a periodic function of the
// height's fractional position f in the z grid ("peak locking"): zero on a frame and half-way
// between frames by symmetry, of opposite signs in between. On the simulated rig (Gaussian
// interpolation, Tenengrad 7x7, 5 um steps) it reaches +-0.23 um (4.6 % of the step), the same
// on the SKEW5/SKEW10 planes and within ~20 % on the ground-metal wedge, so it is a property of
// the instrument and reconstruction settings, not of the specimen: it is characterised once on a
// tilted flat (CharacteriseZLinearity) and enters every uncertainty (core/metrology/depth_noise_model.h).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

// The stack's z positions, sorted, and where a height falls between them.
class ZGrid {
 public:
  ZGrid() = default;
  // >= 2 finite, distinct positions in any order. INVALID_ARGUMENT naming `field` otherwise.
  static StatusOr<ZGrid> Create(std::vector<double> z_positions_um, const std::string& field = "z_positions_um");

  struct Position {
    int lower = 0;          // index of the frame at or below z (the grid is extended beyond its ends by its end steps)
    double fraction = 0.0;  // f in [0, 1): (z - z_lower) / step
    double step_um = 0.0;   // local frame spacing
    int nearest = 0;        // index of the nearest frame, clamped to the grid
  };
  Position Locate(double z_um) const;
  const std::vector<double>& positions_um() const { return z_; }
  double median_step_um() const;

 private:
  std::vector<double> z_;
};

// Depth bias as a fraction of the local z step, tabulated at fractional positions f = i / n
// (i = 0 .. n-1), periodic in f, zero mean. bias_um(z) = step_um * At(f(z)).
struct ZLinearity {
  std::vector<double> bias_of_step;
  double characterised_step_um = 0.0;  // z step of the characterisation scan; 0 = not characterised
  std::string source;                  // how it was obtained (for reports)

  // Not characterised: the peak-locking bound of the discrete maximum (eq. 3.23-3.24), a sawtooth
  // of +-1/2 step (standard deviation step / sqrt 12). Every interpolation lies within it, so it is
  // safe, and large: characterise the rig to get realistic uncertainties.
  static ZLinearity Uncharacterised();
  // Not characterised, for a three-point vertex interpolation (Gaussian eq. 3.30-3.34 or the
  // defocus parabola): the discrete maximum's sawtooth bounds the frame the peak is found at, not
  // the interpolated depth, whose error is continuous in f, zero on a frame and half-way between
  // frames. Each of the two three-point fits is exact for one family of focus curves (ln F a
  // parabola: Gaussian; F^-1/2 a parabola: the defocus curve F = (1 + (u / w)^2)^-2 of a
  // gradient measure); a real curve lies near them, so the prior is the analytic error of one
  // fit on the other family, at the narrowest curve the three samples still resolve (half-width
  // w = step / 2: a narrower peak falls off by > 16x within one step and leaves the flank frames
  // in the noise). That error, Gaussian fit on the defocus curve, peaks at 0.109 of the step
  // (the defocus parabola on a Gaussian: 0.093); wider curves give less (w = 1 step: 0.057,
  // 2 steps: 0.020). Tabulated at 64 fractions, zero-mean by antisymmetry. The simulated rig's
  // characterised tables reach 0.012 (5 um steps) and 0.018 (2 um) of the step.
  static ZLinearity UncharacterisedThreePointPeak();
  // Periodic linear interpolation in the table (f taken modulo 1).
  double At(double fraction) const;
  // Root mean square of the table (fraction of a step).
  double Rms() const;
  // Largest absolute value of the table (fraction of a step): l_z / step.
  double MaxAbs() const;
};

// JSON text for storing a characterisation (e.g. beside a calibration bundle):
//   {"bias_of_step": [...], "characterised_step_um": 5.0, "source": "..."}
std::string ZLinearityToJson(const ZLinearity& linearity);
// INVALID_ARGUMENT naming the key for malformed text, fewer than 2 entries, or |entries| > 1.
StatusOr<ZLinearity> ZLinearityFromJson(const std::string& text);

struct ZLinearityOptions {
  int bins = 20;                 // table size, 4..200
  int min_pixels_per_bin = 500;  // every bin must be sampled this often (a tilt covering >= 1 step)
  Status Validate() const;
};

// Characterises the z linearity from a scan of a smooth tilted flat: fits a least-squares plane
// to the pixels where mask (CV_8UC1) is non-zero, bins the residual by the fractional position
// of the *fitted* height (free of the periodic error) and returns the mean residual per bin as a
// fraction of the local step (mean removed). The flat must be tilted enough for its heights to
// span at least one z step over the region (better several: the plane then cannot absorb the
// periodic error). FAILED_PRECONDITION naming the emptiest bin otherwise.
StatusOr<ZLinearity> CharacteriseZLinearity(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                            const ZGrid& grid, const ZLinearityOptions& options = {});

}  // namespace inspection
