// Projector response prf (thesis eq. 5.1) and camera exposure/response/noise (eq. 5.3, 5.4).
#include "devices/sim/radiometry.h"

#include <algorithm>
#include <cmath>
#include <opencv2/core/utility.hpp>
#include <vector>

namespace inspection {

uint64_t MixSeed(uint64_t a, uint64_t b) {
  uint64_t z = a + 0x9E3779B97F4A7C15ull * (b + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

Status ProjectorResponse::Validate() const {
  if (!(gamma >= 0.5 && gamma <= 4.0)) return Status::InvalidArgument("projector gamma must be in [0.5, 4]");
  if (!(black_irradiance >= 0.0 && black_irradiance < 0.5)) {
    return Status::InvalidArgument("projector black_irradiance must be in [0, 0.5)");
  }
  return Status::Ok();
}

double ProjectorResponse::Irradiance(int grey) const {
  const double g = std::clamp(grey, 0, 255) / 255.0;
  return black_irradiance + (1.0 - black_irradiance) * std::pow(g, gamma);
}

std::array<float, 256> ProjectorResponse::Table() const {
  std::array<float, 256> t{};
  for (int i = 0; i < 256; ++i) t[i] = static_cast<float>(Irradiance(i));
  return t;
}

Status CameraResponse::Validate() const {
  if (bit_depth != 8 && bit_depth != 12) return Status::InvalidArgument("camera_bit_depth must be 8 or 12");
  if (!(full_well_e >= 100.0)) return Status::InvalidArgument("camera full_well_e must be >= 100");
  if (!(sensitivity_e_per_us > 0.0)) return Status::InvalidArgument("camera sensitivity_e_per_us must be > 0");
  if (!(response_exponent > 0.2 && response_exponent <= 2.0)) {
    return Status::InvalidArgument("camera response_exponent must be in (0.2, 2]");
  }
  if (!(black_level_dn8 >= 0.0 && black_level_dn8 < 64.0)) {
    return Status::InvalidArgument("camera black_level_dn8 must be in [0, 64)");
  }
  if (!(read_noise_dn8 >= 0.0 && read_noise_dn8 <= 50.0)) {
    return Status::InvalidArgument("read_noise_dn must be in [0, 50]");
  }
  return Status::Ok();
}

double CameraResponse::GreyForRelativeExposure(double x) const {
  const double black = black_level_dn8 * max_dn() / 255.0;
  const double y = x <= 0.0 ? 0.0 : (x >= 1.0 ? 1.0 : std::pow(x, response_exponent));
  return black + (max_dn() - black) * y;
}

double CameraResponse::RelativeExposureForGrey(double grey) const {
  const double black = black_level_dn8 * max_dn() / 255.0;
  const double y = std::clamp((grey - black) / (max_dn() - black), 0.0, 1.0);
  return std::pow(y, 1.0 / response_exponent);
}

namespace {

constexpr int kBandRows = 16;    // noise bands: fixed, so the noise does not depend on threads
constexpr int kLutSize = 16384;  // response samples over x in [0, 1]
constexpr int kNormalBits = 16;

// 2^16 standard normal quantiles (midpoints of equal-probability bins): a per-pixel normal
// deviate is one table look-up at a random index, several times faster than sampling.
const std::vector<float>& NormalQuantiles() {
  static const std::vector<float>* table = [] {
    auto* t = new std::vector<float>(1 << kNormalBits);
    const double n = static_cast<double>(t->size());
    for (size_t i = 0; i < t->size(); ++i) {
      // Inverse normal CDF by Newton iteration on erfc.
      const double p = (i + 0.5) / n;
      double x = 0.0;
      for (int it = 0; it < 60; ++it) {
        const double cdf = 0.5 * std::erfc(-x / std::sqrt(2.0));
        const double pdf = std::exp(-0.5 * x * x) / std::sqrt(2.0 * CV_PI);
        const double dx = (cdf - p) / std::max(pdf, 1e-300);
        x -= std::clamp(dx, -1.0, 1.0);
        if (std::abs(dx) < 1e-12) break;
      }
      (*t)[i] = static_cast<float>(x);
    }
    return t;
  }();
  return *table;
}

}  // namespace

cv::Mat ExposeAndDigitise(const cv::Mat& irradiance, double exposure_us, double gain_db, const CameraResponse& response,
                          uint64_t noise_seed) {
  CV_Assert(irradiance.type() == CV_32FC1);
  const int max_dn = response.max_dn();
  // Response look-up table over the relative exposure, interpolated linearly.
  std::vector<float> lut(kLutSize + 2);
  for (int i = 0; i <= kLutSize + 1; ++i) {
    lut[i] = static_cast<float>(response.GreyForRelativeExposure(static_cast<double>(i) / kLutSize));
  }
  const double gain = std::pow(10.0, gain_db / 20.0);
  const float e_per_unit = static_cast<float>(exposure_us * response.sensitivity_e_per_us * gain);
  const float inv_full_well = static_cast<float>(1.0 / response.full_well_e);
  // Read noise is specified in 8-bit grey levels on the linear part of the range.
  const float read_e =
      static_cast<float>(response.read_noise_dn8 / (255.0 - response.black_level_dn8) * response.full_well_e);
  const float read_var = read_e * read_e;
  const bool shot = response.shot_noise;
  const bool any_noise = shot || read_e > 0.0f;

  const std::vector<float>& normal = NormalQuantiles();
  cv::Mat out(irradiance.size(), response.output_type());
  const int bands = (irradiance.rows + kBandRows - 1) / kBandRows;
  cv::parallel_for_(cv::Range(0, bands), [&](const cv::Range& r) {
    for (int band = r.start; band < r.end; ++band) {
      uint64_t state = MixSeed(noise_seed, static_cast<uint64_t>(band));
      uint64_t bits = 0;
      int bits_left = 0;
      const int y1 = std::min(irradiance.rows, (band + 1) * kBandRows);
      for (int y = band * kBandRows; y < y1; ++y) {
        const float* src = irradiance.ptr<float>(y);
        uint8_t* o8 = out.depth() == CV_8U ? out.ptr<uint8_t>(y) : nullptr;
        uint16_t* o16 = out.depth() == CV_16U ? out.ptr<uint16_t>(y) : nullptr;
        for (int x = 0; x < irradiance.cols; ++x) {
          float e = std::max(0.0f, src[x]) * e_per_unit;
          if (any_noise) {
            const float var = (shot ? e : 0.0f) + read_var;
            if (bits_left == 0) {  // splitmix64 stream: four 16-bit indices per draw
              state += 0x9E3779B97F4A7C15ull;
              bits = MixSeed(state, 0);
              bits_left = 4;
            }
            e += std::sqrt(var) * normal[bits & 0xFFFF];
            bits >>= 16;
            --bits_left;
          }
          const float xr = std::max(0.0f, e * inv_full_well) * kLutSize;
          float grey;
          if (xr >= kLutSize) {
            grey = static_cast<float>(max_dn);
          } else {
            const int i = static_cast<int>(xr);
            const float t = xr - i;
            grey = lut[i] + t * (lut[i + 1] - lut[i]);
          }
          const int v = std::min(static_cast<int>(grey + 0.5f), max_dn);  // grey >= 0
          if (o8)
            o8[x] = static_cast<uint8_t>(v);
          else
            o16[x] = static_cast<uint16_t>(v);
        }
      }
    }
  });
  return out;
}

}  // namespace inspection
