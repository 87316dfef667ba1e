// Guided push-pull fill of pixels without depth (core/sff/depth_fill.h).
#include "core/sff/depth_fill.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/sff/depth_refinement.h"  // NormalisedGuide

namespace inspection {
namespace {

constexpr int kMaxChannels = 3;

// One pyramid level: depth, weight in [0, 1], mean guide colour of the measured pixels below a
// cell (measured) and of all its pixels (own).
struct Level {
  int width = 0, height = 0, cn = 1;
  std::vector<float> depth, weight, measured, own;
  void Allocate(int w, int h, int channels) {
    width = w;
    height = h;
    cn = channels;
    const size_t n = size_t(w) * h;
    depth.assign(n, 0.f);
    weight.assign(n, 0.f);
    measured.assign(n * cn, 0.f);
    own.assign(n * cn, 0.f);
  }
};

void Push(const Level& fine, Level* coarse) {
  const int cn = fine.cn;
  coarse->Allocate((fine.width + 1) / 2, (fine.height + 1) / 2, cn);
  for (int y = 0; y < coarse->height; ++y)
    for (int x = 0; x < coarse->width; ++x) {
      float sw = 0.f, swd = 0.f, swg[kMaxChannels] = {0, 0, 0}, sg[kMaxChannels] = {0, 0, 0};
      int n = 0;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int fx = 2 * x + dx, fy = 2 * y + dy;
          if (fx >= fine.width || fy >= fine.height) continue;
          const size_t i = size_t(fy) * fine.width + fx;
          const float w = fine.weight[i];
          sw += w;
          swd += w * fine.depth[i];
          for (int c = 0; c < cn; ++c) {
            swg[c] += w * fine.measured[i * cn + c];
            sg[c] += fine.own[i * cn + c];
          }
          ++n;
        }
      const size_t o = size_t(y) * coarse->width + x;
      coarse->weight[o] = std::min(sw, 1.f);
      if (sw > 0.f) coarse->depth[o] = swd / sw;
      for (int c = 0; c < cn; ++c) {
        coarse->measured[o * cn + c] = sw > 0.f ? swg[c] / sw : 0.f;
        coarse->own[o * cn + c] = sg[c] / float(n);
      }
    }
}

// Completes `fine` from the (complete) coarser level: cells with weight < 1 blend in the
// bilinear, guide-weighted interpolation of the coarser depths.
void Pull(const Level& coarse, double guide_sigma, Level* fine) {
  const int cn = fine->cn;
  const float inv2s2 = guide_sigma > 0 ? float(1.0 / (2.0 * guide_sigma * guide_sigma)) : 0.f;
  for (int y = 0; y < fine->height; ++y) {
    const float cy = (y + 0.5f) / 2.f - 0.5f;
    const int y0 = int(std::floor(cy));
    const float fy = cy - y0;
    for (int x = 0; x < fine->width; ++x) {
      const size_t i = size_t(y) * fine->width + x;
      const float w = fine->weight[i];
      if (w >= 1.f) continue;
      const float cx = (x + 0.5f) / 2.f - 0.5f;
      const int x0 = int(std::floor(cx));
      const float fx = cx - x0;
      float sb = 0.f, sbd = 0.f, sbg[kMaxChannels] = {0, 0, 0};
      float sp = 0.f, spd = 0.f, spg[kMaxChannels] = {0, 0, 0};  // plain bilinear, the fallback
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int qx = std::clamp(x0 + dx, 0, coarse.width - 1), qy = std::clamp(y0 + dy, 0, coarse.height - 1);
          const size_t q = size_t(qy) * coarse.width + qx;
          const float b = (dx ? fx : 1.f - fx) * (dy ? fy : 1.f - fy);
          float s = 1.f;
          if (inv2s2 > 0.f) {
            float d2 = 0.f;
            for (int c = 0; c < cn; ++c) {
              const float diff = fine->own[i * cn + c] - coarse.measured[q * cn + c];
              d2 += diff * diff;
            }
            s = std::exp(-d2 * inv2s2);
          }
          sp += b;
          spd += b * coarse.depth[q];
          sb += b * s;
          sbd += b * s * coarse.depth[q];
          for (int c = 0; c < cn; ++c) {
            sbg[c] += b * s * coarse.measured[q * cn + c];
            spg[c] += b * coarse.measured[q * cn + c];
          }
        }
      const bool guided = sb > 1e-6f * sp;
      const float cand = guided ? sbd / sb : spd / sp;
      fine->depth[i] = w * fine->depth[i] + (1.f - w) * cand;
      for (int c = 0; c < cn; ++c) {
        const float g = guided ? sbg[c] / sb : spg[c] / sp;
        fine->measured[i * cn + c] = w * fine->measured[i * cn + c] + (1.f - w) * g;
      }
      fine->weight[i] = 1.f;
    }
  }
}

}  // namespace

Status DepthFillOptions::Validate() const {
  if (!(guide_sigma >= 0.0) || !std::isfinite(guide_sigma)) {
    return Status::InvalidArgument("fill guide_sigma must be >= 0 (0 = no guide)");
  }
  return Status::Ok();
}

StatusOr<cv::Mat> FillDepth(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& guide,
                            const DepthFillOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.empty() || depth_um.type() != CV_32FC1) return Status::InvalidArgument("depth_um must be CV_32FC1");
  if (!confidence.empty() && (confidence.type() != CV_32FC1 || confidence.size() != depth_um.size())) {
    return Status::InvalidArgument("confidence must be CV_32FC1 of the depth map's size");
  }
  cv::Mat g;
  if (options.guide_sigma > 0.0 || !guide.empty()) {
    INSPECT_ASSIGN_OR_RETURN(g, NormalisedGuide(guide, depth_um.size()));
  }
  const int cn = g.empty() ? 1 : g.channels();
  std::vector<Level> levels(1);  // (references into it die when it grows)
  Level& l0 = levels[0];
  l0.Allocate(depth_um.cols, depth_um.rows, cn);
  size_t measured = 0;
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    const float* c = confidence.empty() ? nullptr : confidence.ptr<float>(y);
    const float* gp = g.empty() ? nullptr : g.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      const size_t i = size_t(y) * depth_um.cols + x;
      const float cw = c ? c[x] : 1.f;
      if (std::isfinite(d[x])) {
        // A measured pixel of confidence 0 still counts a little: it passed the caller's threshold.
        l0.weight[i] = std::clamp(std::isfinite(cw) ? cw : 0.f, 1e-3f, 1.f);
        l0.depth[i] = d[x];
        ++measured;
      }
      for (int ch = 0; ch < cn; ++ch) {
        const float v = gp ? gp[cn * x + ch] : 0.f;
        l0.own[i * cn + ch] = v;
        l0.measured[i * cn + ch] = v;
      }
    }
  }
  if (measured == 0 || measured == depth_um.total()) return depth_um.clone();
  while (levels.back().width > 1 || levels.back().height > 1) {
    Level next;
    Push(levels.back(), &next);
    levels.push_back(std::move(next));
  }
  // The 1x1 top holds the weighted mean of everything measured: complete by construction.
  levels.back().weight[0] = 1.f;
  for (int l = int(levels.size()) - 2; l >= 0; --l)
    Pull(levels[size_t(l) + 1], options.guide_sigma, &levels[size_t(l)]);

  cv::Mat out = depth_um.clone();
  for (int y = 0; y < out.rows; ++y) {
    float* o = out.ptr<float>(y);
    for (int x = 0; x < out.cols; ++x) {
      if (!std::isfinite(o[x])) o[x] = levels[0].depth[size_t(y) * out.cols + x];
    }
  }
  return out;
}

}  // namespace inspection
