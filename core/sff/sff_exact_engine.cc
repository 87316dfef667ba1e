// Streaming SFF engine with exact 32-bit per-pixel state (thesis 3.1; layout StatePlanes in
// core/sff/sff_state.h): the line fit (eq. 3.25-3.29) and every focus measure of 3.1.3 but 8-bit
// Tenengrad with maximum / Gaussian interpolation (that case: sff_compact_engine.cc).
// Per frame: the fused Tenengrad kernel over tiles (8-bit Tenengrad, line fit), or the whole
// focus map of core/sff/focus_measure.h (normalised by the light with illumination_invariant) and the
// same state update over row bands (all others): computed band by band where the measure allows it
// bit for bit (FocusMeasureIsRowLocal), so that no full-frame float temporaries exist.
#include <algorithm>
#include <atomic>
#include <string>
#include <type_traits>

#include "core/sff/focus_measure.h"
#include "core/util/parallel_for.h"
#include "core/sff/internal/sff_engine_internal.h"
#include "core/sff/internal/tenengrad_kernel.h"

namespace inspection::sff_internal {
namespace {

// T: focus value type (int32_t: the fused 8-bit Tenengrad; float: a focus map of another
// measure or of 16-bit frames). P: pixel type of the frames.
template <typename T, typename P>
class ExactEngine final : public SffEngine {
 public:
  static constexpr bool kFused = std::is_same_v<T, int32_t>;

  ExactEngine(const SffOptions& o, cv::Size size, int type) : options_(o), size_(size), type_(type) {
    const int j = o.interpolation == DepthInterpolation::kLineFit ? o.linefit_half_width : 1;
    state_.Allocate(size.width, size.height, j, o.use_simd);
    threads_ = ResolveThreads(o.threads);
    if constexpr (kFused) {
      scratch_.resize(size_t(threads_));
      for (auto& s : scratch_) s.Reserve(o.window_px);
    }
  }

  Status PushFrame(const cv::Mat& frame, double z_um) override {
    const int k = int(z_.size());
    INSPECT_RETURN_IF_ERROR(CheckPush(frame, z_um, z_, finished_, size_, type_));
    if constexpr (kFused) {
      const int tiles_x = (size_.width + kTileW - 1) / kTileW, tiles_y = (size_.height + kTileH - 1) / kTileH;
      ParallelFor(tiles_x * tiles_y, threads_, [&](int t, int worker) {
        const int x0 = (t % tiles_x) * kTileW, y0 = (t / tiles_x) * kTileH;
        const int tw = std::min(kTileW, size_.width - x0), th = std::min(kTileH, size_.height - y0);
        FusedTileFrame(frame, k, x0, y0, tw, th, options_.window_px, scratch_[size_t(worker)], state_, x0, y0);
      });
    } else if (FocusMeasureIsRowLocal(options_.focus_measure)) {
      // The focus map band by band (each band's rows plus a halo), on the engine's threads: the
      // float temporaries of the map (about 28 bytes per pixel for a whole frame) are band-sized,
      // and the state update follows each band while it is in cache. Same values bit for bit.
      const int bands = (size_.height + kFocusBandRows - 1) / kFocusBandRows;
      const int halo = FocusMeasureHaloRows(options_.window_px);
      std::vector<Status> errors(size_t(bands), Status::Ok());
      ParallelFor(bands, threads_, [&](int b, int) {
        const int y_begin = b * kFocusBandRows, y_end = std::min(size_.height, y_begin + kFocusBandRows);
        const int h0 = std::max(0, y_begin - halo), h1 = std::min(size_.height, y_end + halo);
        cv::Mat focus;
        errors[size_t(b)] = FocusOf(frame.rowRange(h0, h1), &focus);
        if (errors[size_t(b)].ok()) UpdateExactRowsFromFocus(state_, k, focus, h0, frame, y_begin, y_end);
      });
      for (const Status& e : errors) INSPECT_RETURN_IF_ERROR(e.WithContext("frame " + std::to_string(k)));
    } else {
      cv::Mat focus;
      INSPECT_RETURN_IF_ERROR(FocusOf(frame, &focus).WithContext("frame " + std::to_string(k)));
      const int bands = std::min(size_.height, threads_ * 4);
      ParallelFor(bands, threads_, [&](int b, int) {
        const int y_begin = size_.height * b / bands, y_end = size_.height * (b + 1) / bands;
        UpdateExactRowsFromFocus(state_, k, focus, 0, frame, y_begin, y_end);
      });
    }
    z_.push_back(z_um);
    return Status::Ok();
  }

  StatusOr<DepthResult> Finish() override {
    const int n = int(z_.size());
    INSPECT_RETURN_IF_ERROR(CheckFinish(finished_, n));
    finished_ = true;
    DepthOutputs out;
    out.depth.create(size_, CV_32F);
    out.confidence.create(size_, CV_32F);
    out.aif.create(size_, type_);
    std::atomic<size_t> valid{0};
    ParallelFor(size_.height, threads_, [&](int y, int) {
      valid += FinishExactSpan(state_, size_t(y) * size_.width, size_.width, z_, options_, out, 0, y);
    });
    state_ = {};  // release the O(pixels) state
    return MakeDepthResult(out.depth, out.confidence, out.aif, n, valid.load());
  }

  int frames_pushed() const override { return int(z_.size()); }
  size_t state_bytes() const override { return state_.Bytes(); }

 private:
  // Rows per band of the banded focus map: 128 rows of a 6000 px frame keep a band's float
  // temporaries near 25 MB per thread, and the halo (window_px / 2 + 1 rows each side) adds
  // under 10 % of recomputed rows for windows up to 9 px.
  static constexpr int kFocusBandRows = 128;

  // The (illumination-normalised) focus map of frame (or of a band of it).
  Status FocusOf(const cv::Mat& frame, cv::Mat* focus) const {
    INSPECT_RETURN_IF_ERROR(ComputeFocusMeasure(frame, options_.focus_measure, options_.window_px, focus));
    if (options_.illumination_invariant) {
      INSPECT_RETURN_IF_ERROR(NormaliseFocusByIllumination(frame, options_.focus_measure, options_.window_px, focus));
    }
    return Status::Ok();
  }

  SffOptions options_;
  cv::Size size_;
  int type_;
  int threads_ = 1;
  bool finished_ = false;
  std::vector<double> z_;
  StatePlanes<T, P> state_;
  std::vector<TenengradScratch> scratch_;
};

}  // namespace

std::unique_ptr<SffEngine> NewExactEngine(const SffOptions& options, cv::Size frame_size, int frame_type) {
  if (UseFused(options, frame_type)) {
    return std::make_unique<ExactEngine<int32_t, uint8_t>>(options, frame_size, frame_type);
  }
  if (frame_type == CV_8UC1) return std::make_unique<ExactEngine<float, uint8_t>>(options, frame_size, frame_type);
  return std::make_unique<ExactEngine<float, uint16_t>>(options, frame_size, frame_type);
}

}  // namespace inspection::sff_internal
