// Integral SFF (thesis 5.4, 6.4): integral image and noise of a stack, IPSF restoration of the
// all-in-focus texture (eq. 5.23) with a noise-weighted Wiener shrinkage, and the ISFF,
// ISFF-FAST and ISFF-GT reconstructions.
#include "core/sff/integral_sff.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <ctime>
#include <opencv2/imgproc.hpp>
#include <string>

#include "core/io/stack.h"

namespace inspection {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

template <typename P>
double NoiseSigmaOf(const cv::Mat& f, bool integer_valued) {
  double lo = 0, hi = 0;
  cv::minMaxLoc(f, &lo, &hi);
  std::vector<float> r;
  r.reserve(size_t(f.rows / 2 + 1) * size_t(f.cols / 2 + 1));
  for (int y = 1; y + 1 < f.rows; y += 2) {
    const P* a = f.ptr<P>(y - 1);
    const P* b = f.ptr<P>(y);
    const P* c = f.ptr<P>(y + 1);
    for (int x = 1; x + 1 < f.cols; x += 2) {
      const double centre = double(b[x]);
      if (integer_valued && (centre <= 0.0 || centre >= hi)) continue;  // black or saturated
      const double v = double(a[x - 1]) - 2.0 * a[x] + double(a[x + 1]) - 2.0 * b[x - 1] + 4.0 * centre -
                       2.0 * b[x + 1] + double(c[x - 1]) - 2.0 * c[x] + double(c[x + 1]);
      r.push_back(float(std::abs(v)));
    }
  }
  if (r.empty()) return 0.0;
  const size_t half = r.size() / 2;
  std::nth_element(r.begin(), r.begin() + half, r.end());
  double median = r[half];
  if (integer_valued) {
    // Integer responses: the median lies in the bin [m - 0.5, m + 0.5); interpolate inside it.
    size_t below = 0, equal = 0;
    for (float v : r) {
      below += v < r[half];
      equal += v == r[half];
    }
    const double lower = std::max(0.0, median - 0.5), width = median > 0 ? 1.0 : 0.5;
    median = lower + width * (double(half) + 0.5 - double(below)) / double(std::max<size_t>(equal, 1));
  }
  return median / (0.6745 * 6.0);
}

// |K(wx, wy)|^2 averaged over (wx, +-wy) (what one DCT coefficient sees of a convolution) on a
// (g + 1) x (g + 1) grid of w = 0..pi; bilinear lookup. The kernel is small, so its response is
// smooth in frequency and the coarse grid is exact to well below the spectrum's own scatter.
class KernelPower {
 public:
  KernelPower(const cv::Mat& kernel, int g) : g_(g), p_(g + 1, g + 1, CV_64FC1) {
    const int n = kernel.rows, r = n / 2;
    std::vector<std::complex<double>> inner(size_t(n) * (g + 1));  // [row][wx]
    for (int j = 0; j <= g; ++j) {
      const double wx = CV_PI * j / g;
      for (int y = 0; y < n; ++y) {
        std::complex<double> s = 0;
        for (int x = 0; x < n; ++x) s += double(kernel.at<float>(y, x)) * std::polar(1.0, -wx * (x - r));
        inner[size_t(y) * (g + 1) + j] = s;
      }
    }
    for (int i = 0; i <= g; ++i) {
      const double wy = CV_PI * i / g;
      for (int j = 0; j <= g; ++j) {
        std::complex<double> plus = 0, minus = 0;
        for (int y = 0; y < n; ++y) {
          const std::complex<double> v = inner[size_t(y) * (g + 1) + j];
          plus += v * std::polar(1.0, -wy * (y - r));
          minus += v * std::polar(1.0, wy * (y - r));
        }
        p_.at<double>(i, j) = 0.5 * (std::norm(plus) + std::norm(minus));
      }
    }
  }
  // fx, fy in [0, 1]: w / pi.
  double At(double fy, double fx) const {
    const double y = fy * g_, x = fx * g_;
    const int y0 = std::min(int(y), g_ - 1), x0 = std::min(int(x), g_ - 1);
    const double ty = y - y0, tx = x - x0;
    return (1 - ty) * ((1 - tx) * p_.at<double>(y0, x0) + tx * p_.at<double>(y0, x0 + 1)) +
           ty * ((1 - tx) * p_.at<double>(y0 + 1, x0) + tx * p_.at<double>(y0 + 1, x0 + 1));
  }

 private:
  int g_;
  cv::Mat p_;
};

Status CheckFrames(const std::vector<cv::Mat>& frames, const std::vector<double>& z_um) {
  if (frames.size() < 3) {
    return Status::InvalidArgument("a stack needs at least 3 frames, got " + std::to_string(frames.size()));
  }
  if (z_um.size() != frames.size()) {
    return Status::InvalidArgument("z_um has " + std::to_string(z_um.size()) + " values for " +
                                   std::to_string(frames.size()) + " frames");
  }
  for (size_t i = 0; i < frames.size(); ++i) {
    const cv::Mat& f = frames[i];
    if (f.type() != CV_8UC1 && f.type() != CV_16UC1) {
      return Status::InvalidArgument("frame " + std::to_string(i) + ": must be 8-bit or 16-bit single channel");
    }
    if (f.size() != frames[0].size() || f.type() != frames[0].type()) {
      return Status::InvalidArgument("frame " + std::to_string(i) + ": size or type differs from frame 0");
    }
  }
  return CheckMonotonicZ(z_um);
}

// Pass 2 (or the only pass, with a given template): NCC focus over the frames.
template <typename GetFrame>
StatusOr<IsffResult> CorrelateFrames(size_t count, GetFrame&& get_frame, const std::vector<double>& z_um,
                                     const cv::Mat& focused_template, int frame_type, const IsffOptions& options) {
  const auto t0 = Clock::now();
  INSPECT_ASSIGN_OR_RETURN(auto engine, NccFocusEngine::Create(options.ncc, focused_template, frame_type));
  const double setup_s = SecondsSince(t0);
  double search_s = 0.0, search_cpu_s = 0.0;
  for (size_t i = 0; i < count; ++i) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, get_frame(i));
    const auto t_push = Clock::now();
    const std::clock_t c_push = std::clock();
    INSPECT_RETURN_IF_ERROR(engine->PushFrame(frame, z_um[i]));
    search_cpu_s += double(std::clock() - c_push) / CLOCKS_PER_SEC;
    search_s += SecondsSince(t_push);
  }
  const auto t_finish = Clock::now();
  INSPECT_ASSIGN_OR_RETURN(DepthResult depth, engine->Finish());
  IsffResult r;
  r.search_setup_seconds = setup_s;
  r.search_seconds = search_s;
  r.search_cpu_seconds = search_cpu_s;
  r.search_finish_seconds = SecondsSince(t_finish);
  r.depth = std::move(depth);
  r.work = engine->work();
  r.max_index = engine->max_index();
  r.frames_searched = engine->frames_searched();
  focused_template.convertTo(r.focused_template, CV_32F);
  r.focus_seconds = SecondsSince(t0);
  return r;
}

}  // namespace

double EstimateFrameNoiseSigma(const cv::Mat& frame) {
  if (frame.empty() || frame.channels() != 1 || frame.rows < 3 || frame.cols < 3) return 0.0;
  switch (frame.depth()) {
    case CV_8U:
      return NoiseSigmaOf<uint8_t>(frame, true);
    case CV_16U:
      return NoiseSigmaOf<uint16_t>(frame, true);
    case CV_32F:
      return NoiseSigmaOf<float>(frame, false);
    default: {
      cv::Mat f;
      frame.convertTo(f, CV_32F);
      return NoiseSigmaOf<float>(f, false);
    }
  }
}

Status IntegralImageAccumulator::Add(const cv::Mat& frame) {
  const std::string name = "frame " + std::to_string(frame_count());
  if (frame.empty() || (frame.type() != CV_8UC1 && frame.type() != CV_16UC1 && frame.type() != CV_32FC1)) {
    return Status::InvalidArgument(name + ": must be a non-empty 8-bit, 16-bit or float single-channel image");
  }
  if (sum_.empty()) {
    sum_ = cv::Mat::zeros(frame.size(), CV_64FC1);
    type_ = frame.type();
  } else if (frame.size() != sum_.size() || frame.type() != type_) {
    return Status::InvalidArgument(name + ": size or type differs from frame 0");
  }
  cv::accumulate(frame, sum_);
  noise_.push_back(EstimateFrameNoiseSigma(frame));
  return Status::Ok();
}

StatusOr<cv::Mat> IntegralImageAccumulator::IntegralImage() const {
  if (noise_.empty()) return Status::FailedPrecondition("integral image: no frames added");
  cv::Mat out;
  sum_.convertTo(out, CV_32F, 1.0 / double(noise_.size()));
  return out;
}

double IntegralImageAccumulator::FrameNoiseSigma() const {
  if (noise_.empty()) return 0.0;
  std::vector<double> v = noise_;
  const size_t half = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + half, v.end());
  if (v.size() % 2 == 1) return v[half];
  const double upper = v[half];
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + half));
}


Status IpsfRestorationOptions::Validate() const {
  if (!std::isnan(frame_noise_sigma) && !(frame_noise_sigma >= 0.0 && std::isfinite(frame_noise_sigma))) {
    return Status::InvalidArgument("restoration.frame_noise_sigma must be >= 0 (or NaN = estimate)");
  }
  if (spectrum_smoothing_bins < 0 || spectrum_smoothing_bins > 16) {
    return Status::InvalidArgument("restoration.spectrum_smoothing_bins must be 0..16");
  }
  return Status::Ok();
}

StatusOr<cv::Mat> RestoreFocusedImage(const cv::Mat& integral_image, int frame_count, double frame_noise_sigma,
                                      const IntegralPsf& ipsf, const IpsfRestorationOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  INSPECT_RETURN_IF_ERROR(ipsf.Validate());
  if (integral_image.empty() || integral_image.channels() != 1) {
    return Status::InvalidArgument("integral image must be a non-empty single-channel image");
  }
  if (frame_count < 1) return Status::InvalidArgument("frame_count must be >= 1");
  if (!(frame_noise_sigma >= 0.0) || !std::isfinite(frame_noise_sigma)) {
    return Status::InvalidArgument("frame_noise_sigma must be finite and >= 0");
  }
  cv::Mat restored = ipsf.Apply(integral_image);  // eq. 5.23
  const double noise_var = frame_noise_sigma * frame_noise_sigma / frame_count;
  const double cal_var = ipsf.integral_noise_sigma * ipsf.integral_noise_sigma;
  if (options.method == IpsfRestoration::kPlain || noise_var <= cal_var) return restored;

  // The DCT's even extension makes the image periodic without edges; cv::dct needs even sizes.
  const int W = restored.cols + (restored.cols % 2), H = restored.rows + (restored.rows % 2);
  if (W < 2 || H < 2) return restored;
  cv::Mat padded;
  cv::copyMakeBorder(restored, padded, 0, H - restored.rows, 0, W - restored.cols, cv::BORDER_REPLICATE);
  cv::Mat coeff;
  cv::dct(padded, coeff);
  cv::Mat power = coeff.mul(coeff), smooth;
  const int s = 2 * options.spectrum_smoothing_bins + 1;
  cv::boxFilter(power, smooth, CV_32F, {s, s}, {-1, -1}, true, cv::BORDER_REFLECT);
  const KernelPower kp(ipsf.kernel, 64);
  // Orthonormal DCT: white noise of variance v has variance v in every coefficient, and R's
  // noise at f is v |IPSF(f)|^2. Comparing it with R's power is comparing the integral image's
  // noise with the integral image's power.
  for (int v = 0; v < H; ++v) {
    float* c = coeff.ptr<float>(v);
    const float* p = smooth.ptr<float>(v);
    const double fy = double(v) / H;
    for (int u = 0; u < W; ++u) {
      const double k2 = kp.At(fy, double(u) / W);
      const double power_r = double(p[u]);
      double gain = 0.0;
      if (power_r > 0) {
        const double w_scan = std::max(0.0, 1.0 - noise_var * k2 / power_r);
        const double w_cal = std::max(0.0, 1.0 - cal_var * k2 / power_r);
        gain = w_cal > 0 ? std::min(1.0, w_scan / w_cal) : 0.0;
      }
      c[u] = float(c[u] * gain);
    }
  }
  cv::Mat out;
  cv::idct(coeff, out);
  return out(cv::Rect(0, 0, restored.cols, restored.rows)).clone();
}

Status IsffOptions::Validate() const {
  INSPECT_RETURN_IF_ERROR(ncc.Validate());
  return restoration.Validate();
}

Status CheckIntegralPsfFor(const CalibrationBundle* bundle) {
  if (bundle == nullptr || !bundle->integral_psf.has_value()) {
    return Status::FailedPrecondition(
        "ISFF needs an integral PSF: run the calibration step integral_psf (CALIBRATION_STEP_INTEGRAL_PSF); the "
        "active calibration has none");
  }
  return Status::Ok();
}

namespace {

// Pass 1 of ISFF (thesis 5.4.1): the summed stack, its noise estimate and the restored focused
// image, from frames 0..count-1 as get_frame returns them.
struct RestoredTemplate {
  cv::Mat restored;
  double frame_noise_sigma = 0;
  double integral_seconds = 0;
  double restore_seconds = 0;
};

template <typename GetFrame>
StatusOr<RestoredTemplate> RestoreFromIntegralImage(size_t count, GetFrame&& get_frame, const IntegralPsf& ipsf,
                                                    const IsffOptions& options) {
  const auto t0 = Clock::now();
  IntegralImageAccumulator acc;
  for (size_t i = 0; i < count; ++i) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, get_frame(i));
    INSPECT_RETURN_IF_ERROR(acc.Add(f));
  }
  INSPECT_ASSIGN_OR_RETURN(cv::Mat integral, acc.IntegralImage());
  RestoredTemplate t;
  t.frame_noise_sigma =
      std::isnan(options.restoration.frame_noise_sigma) ? acc.FrameNoiseSigma() : options.restoration.frame_noise_sigma;
  t.integral_seconds = SecondsSince(t0);
  const auto t1 = Clock::now();
  INSPECT_ASSIGN_OR_RETURN(
      t.restored, RestoreFocusedImage(integral, acc.frame_count(), t.frame_noise_sigma, ipsf, options.restoration));
  t.restore_seconds = SecondsSince(t1);
  return t;
}

}  // namespace

StatusOr<IsffResult> ReconstructIntegralSff(const std::vector<cv::Mat>& frames, const std::vector<double>& z_um,
                                            const IntegralPsf* ipsf, const IsffOptions& options) {
  if (ipsf == nullptr) {
    return Status::FailedPrecondition(
        "ISFF needs an integral PSF: run the calibration step integral_psf (CALIBRATION_STEP_INTEGRAL_PSF)");
  }
  INSPECT_RETURN_IF_ERROR(options.Validate());
  INSPECT_RETURN_IF_ERROR(ipsf->Validate());
  INSPECT_RETURN_IF_ERROR(CheckFrames(frames, z_um));
  auto frame = [&](size_t i) -> StatusOr<cv::Mat> { return frames[i]; };
  INSPECT_ASSIGN_OR_RETURN(RestoredTemplate t, RestoreFromIntegralImage(frames.size(), frame, *ipsf, options));
  INSPECT_ASSIGN_OR_RETURN(IsffResult r,
                           CorrelateFrames(frames.size(), frame, z_um, t.restored, frames[0].type(), options));
  r.frame_noise_sigma = t.frame_noise_sigma;
  r.integral_seconds = t.integral_seconds;
  r.restore_seconds = t.restore_seconds;
  return r;
}

StatusOr<IsffResult> ReconstructIntegralSffWithTemplate(const std::vector<cv::Mat>& frames,
                                                        const std::vector<double>& z_um,
                                                        const cv::Mat& focused_template, const IsffOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  INSPECT_RETURN_IF_ERROR(CheckFrames(frames, z_um));
  if (focused_template.size() != frames[0].size() || focused_template.channels() != 1) {
    return Status::InvalidArgument("focused template must be single channel and of the frame size");
  }
  INSPECT_ASSIGN_OR_RETURN(IsffResult r, CorrelateFrames(
                                             frames.size(), [&](size_t i) -> StatusOr<cv::Mat> { return frames[i]; },
                                             z_um, focused_template, frames[0].type(), options));
  r.frame_noise_sigma = options.restoration.frame_noise_sigma;
  return r;
}

namespace {

Status CheckIntegralInputs(const IntegralPsf* ipsf, const IsffOptions& options) {
  if (ipsf == nullptr) {
    return Status::FailedPrecondition(
        "ISFF needs an integral PSF: run the calibration step integral_psf (CALIBRATION_STEP_INTEGRAL_PSF)");
  }
  INSPECT_RETURN_IF_ERROR(options.Validate());
  return ipsf->Validate();
}

}  // namespace

StatusOr<IsffResult> ReconstructIntegralSffStack(const std::filesystem::path& dir, const IntegralPsf* ipsf,
                                                 const IsffOptions& options) {
  INSPECT_RETURN_IF_ERROR(CheckIntegralInputs(ipsf, options));
  INSPECT_ASSIGN_OR_RETURN(StackManifest manifest, ReadStackManifest(dir));
  const StackFrameSource source{[&](int i) { return DecodeStackFrame(dir, manifest, size_t(i)); }, {}, {}};
  return ReconstructIntegralSffFrames(manifest, source, ipsf, options);
}

StatusOr<IsffResult> ReconstructIntegralSffFrames(const StackManifest& manifest, const StackFrameSource& source,
                                                  const IntegralPsf* ipsf, const IsffOptions& options) {
  INSPECT_RETURN_IF_ERROR(CheckIntegralInputs(ipsf, options));
  std::vector<double> z_um;
  for (const StackFrame& f : manifest.frames) z_um.push_back(f.z_um);
  int frame_type = -1;
  cv::Size size;
  // Pass 1 takes frame 0's type and size; every later read (pass 1 and 2) must match them. The
  // frames stay with the source for pass 2 (a decoder keeps what its budget allows).
  auto first_pass_frame = [&](size_t i) -> StatusOr<cv::Mat> {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, source.grey(int(i)));
    if (i == 0) {
      frame_type = f.type();
      size = f.size();
    } else if (f.type() != frame_type || f.size() != size) {
      return Status::InvalidArgument("frame " + std::to_string(i) + " (" + manifest.frames[i].file +
                                     "): size or bit depth differs from frame 0");
    }
    return f;
  };
  INSPECT_ASSIGN_OR_RETURN(RestoredTemplate t,
                           RestoreFromIntegralImage(manifest.frames.size(), first_pass_frame, *ipsf, options));
  auto second_pass_frame = [&](size_t i) -> StatusOr<cv::Mat> {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, source.grey(int(i)));
    if (source.release) source.release(int(i));  // its last use: the engine takes it now
    if (f.type() != frame_type || f.size() != size) {
      return Status::InvalidArgument("frame " + std::to_string(i) + " (" + manifest.frames[i].file +
                                     "): changed between the two passes");
    }
    return f;
  };
  INSPECT_ASSIGN_OR_RETURN(
      IsffResult r, CorrelateFrames(manifest.frames.size(), second_pass_frame, z_um, t.restored, frame_type, options));
  r.frame_noise_sigma = t.frame_noise_sigma;
  r.integral_seconds = t.integral_seconds;
  r.restore_seconds = t.restore_seconds;
  return r;
}

}  // namespace inspection
