// chain-evaluate's own renderer (chain_lens_renderer.h).
#include "tests/bench/chain_lens_renderer.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace chain_bench {

namespace {

constexpr int kLevels = 7;

// Level j of the blur: j times pyrDown, then pyrUp back to the image's size (blur ~ 2^j px).
cv::Mat PyramidBlur(const cv::Mat& image, int j) {
  std::vector<cv::Mat> down{image};
  for (int k = 0; k < j; ++k) {
    cv::Mat d;
    cv::pyrDown(down.back(), d);
    down.push_back(d);
  }
  cv::Mat up = down.back();
  for (int k = j - 1; k >= 0; --k) {
    cv::Mat u;
    cv::pyrUp(up, u, down[size_t(k)].size());
    up = u;
  }
  return up;
}

cv::Matx23d SimilarityAbout(double scale, double rot, double tx, double ty, cv::Point2d c) {
  const double a = scale * std::cos(rot), b = scale * std::sin(rot);
  // p' = c + [a -b; b a] (p - c) + t
  return cv::Matx23d(a, -b, c.x - a * c.x + b * c.y + tx, b, a, c.y - b * c.x - a * c.y + ty);
}

cv::Matx23d Inverse(const cv::Matx23d& m) {
  cv::Matx23d out;
  cv::invertAffineTransform(m, out);
  return out;
}

cv::Matx23d After(const cv::Matx23d& a, const cv::Matx23d& b) {  // a(b(p))
  const cv::Matx33d A(a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2), 0, 0, 1);
  const cv::Matx33d B(b(0, 0), b(0, 1), b(0, 2), b(1, 0), b(1, 1), b(1, 2), 0, 0, 1);
  const cv::Matx33d C = A * B;
  return cv::Matx23d(C(0, 0), C(0, 1), C(0, 2), C(1, 0), C(1, 1), C(1, 2));
}

// frame: the frame's size (ellipse size, and their count per frame area, as on a frame-sized scene).
cv::Mat Albedo(cv::Size size, cv::Size frame, cv::RNG& rng) {
  cv::Mat a(size, CV_32F, cv::Scalar(0.0));
  const int gratings = rng.uniform(2, 7);
  cv::Mat xs(size, CV_32F), ys(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) xs.at<float>(y, x) = float(x), ys.at<float>(y, x) = float(y);
  for (int g = 0; g < gratings; ++g) {
    const double th = rng.uniform(0.0, CV_PI), f = rng.uniform(0.02, 0.3) * 2 * CV_PI, ph = rng.uniform(0.0, 6.3);
    cv::Mat arg = xs * std::cos(th) * f + ys * std::sin(th) * f + ph, s(size, CV_32F);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) s.at<float>(y, x) = std::sin(arg.at<float>(y, x));
    a += s * rng.uniform(0.02, 0.12);
  }
  const int ellipses = int(rng.uniform(40, 401) * (double(size.area()) / double(frame.area())));
  const double scale = std::max(frame.width, frame.height) / 480.0;
  for (int e = 0; e < ellipses; ++e) {
    const cv::Point c(rng.uniform(0, size.width), rng.uniform(0, size.height));
    const cv::Size axes(int(scale * rng.uniform(2, 40)), int(scale * rng.uniform(2, 40)));
    cv::ellipse(a, c, axes, rng.uniform(0.0, 180.0), 0, 360, cv::Scalar(rng.uniform(-0.35, 0.35)), cv::FILLED,
                cv::LINE_AA);
  }
  for (int l = rng.uniform(3, 12); l > 0; --l) {
    cv::line(a, {rng.uniform(0, size.width), rng.uniform(0, size.height)},
             {rng.uniform(0, size.width), rng.uniform(0, size.height)}, cv::Scalar(rng.uniform(-0.4, 0.4)),
             rng.uniform(1, 4), cv::LINE_AA);
  }
  // Contrast drawn per seed (some scenes low-contrast), mean ~0.45.
  cv::Scalar mean, sd;
  cv::meanStdDev(a, mean, sd);
  const double contrast = rng.uniform(0.03, 0.2);
  a = (a - mean[0]) * (contrast / std::max(1e-6, sd[0])) + rng.uniform(0.3, 0.6);
  cv::max(a, 0.01, a);
  cv::min(a, 1.0, a);
  return a;
}

cv::Mat Depth(cv::Size size, int n, cv::RNG& rng) {
  cv::Mat d(size, CV_32F);
  const double gx = rng.uniform(-1.0, 1.0), gy = rng.uniform(-1.0, 1.0);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      d.at<float>(y, x) = float(gx * x / size.width + gy * y / size.height);
  for (int r = rng.uniform(2, 6); r > 0; --r) {
    const int w = rng.uniform(size.width / 8, size.width / 2), h = rng.uniform(size.height / 8, size.height / 2);
    const cv::Rect box(rng.uniform(0, size.width - w), rng.uniform(0, size.height - h), w, h);
    d(box) += rng.uniform(-0.8, 0.8);
  }
  double lo, hi;
  cv::minMaxLoc(d, &lo, &hi);
  return (d - lo) * ((n - 1) * 0.8 / std::max(1e-6, hi - lo)) + (n - 1) * 0.1;
}

}  // namespace

LensStack RenderLensStack(const LensStackOptions& o) {
  cv::RNG rng(o.seed * 2654435761u + 17u);
  const cv::Size frame_size = o.size;
  const int n = std::max(3, o.frames);
  const int ref = (n - 1) / 2;
  const cv::Point2d centre((frame_size.width - 1) * 0.5, (frame_size.height - 1) * 0.5);
  std::vector<cv::Matx23d> world;  // frame px -> scene px (before the scene's margin)
  for (int k = 0; k < n; ++k) {
    const double u = double(k) / (n - 1);
    world.push_back(SimilarityAbout(1.0 + o.scale_total * std::pow(u, 1.4), o.rotation_total_rad * u,
                                    o.shift_x_total_px * u, o.shift_y_total_px * u, centre));
  }
  // The scene's margin around the frame-sized area: every frame's footprint plus the cubic
  // kernel's reach.
  int margin_x = 0, margin_y = 0;
  if (o.scene_covers_motion) {
    for (const cv::Matx23d& w : world) {
      for (cv::Point2d p : {cv::Point2d(0, 0), cv::Point2d(frame_size.width - 1, 0),
                            cv::Point2d(0, frame_size.height - 1),
                            cv::Point2d(frame_size.width - 1, frame_size.height - 1)}) {
        const cv::Vec2d q = w * cv::Vec3d(p.x, p.y, 1);
        margin_x = std::max({margin_x, int(std::ceil(-q[0])), int(std::ceil(q[0] - (frame_size.width - 1)))});
        margin_y = std::max({margin_y, int(std::ceil(-q[1])), int(std::ceil(q[1] - (frame_size.height - 1)))});
      }
    }
    margin_x += 4, margin_y += 4;
    for (cv::Matx23d& w : world) w(0, 2) += margin_x, w(1, 2) += margin_y;
  }
  const cv::Size size(frame_size.width + 2 * margin_x, frame_size.height + 2 * margin_y);  // the scene's
  const double blur = o.blur_px_per_frame > 0 ? o.blur_px_per_frame : rng.uniform(0.4, 1.5);
  const double full_well = o.full_well > 0 ? o.full_well : rng.uniform(2000.0, 20000.0);
  const cv::Mat albedo = Albedo(size, frame_size, rng);
  const cv::Mat depth = Depth(size, n, rng);

  // Pyramid levels of the albedo, each brought back to full size.
  std::vector<cv::Mat> level(kLevels);
  level[0] = albedo;
  for (int j = 1; j < kLevels && !o.scatter; ++j) level[size_t(j)] = PyramidBlur(albedo, j);
  // Fixed across frames: vignetting and pixel gain (the sensor's, frame-sized).
  cv::Mat gain(frame_size, CV_32F);
  rng.fill(gain, cv::RNG::NORMAL, 1.0, o.prnu);
  const double half_diag = 0.5 * std::hypot(frame_size.width, frame_size.height);
  for (int y = 0; y < frame_size.height; ++y)
    for (int x = 0; x < frame_size.width; ++x) {
      const double r = std::hypot(x - 0.5 * frame_size.width, y - 0.5 * frame_size.height) / half_diag;
      const double c = std::cos(std::atan(0.6 * r));
      gain.at<float>(y, x) *= float(c * c * c * c);
    }

  const bool moving = o.scale_total != 0 || o.rotation_total_rad != 0 || o.shift_x_total_px != 0 ||
                      o.shift_y_total_px != 0;
  LensStack out;
  cv::warpAffine(depth, out.depth_reference, world[size_t(ref)], frame_size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                 cv::BORDER_REFLECT_101);
  cv::Mat sharp(size, CV_32F), noise(frame_size, CV_32F), read(frame_size, CV_32F);
  for (int k = 0; k < n; ++k) {
    // The scene pixels frame k samples (all of them on a frame-sized scene).
    cv::Rect box(0, 0, size.width, size.height);
    if (o.scene_covers_motion) {
      double x0 = 1e18, y0 = 1e18, x1 = -1e18, y1 = -1e18;
      for (cv::Point2d p : {cv::Point2d(0, 0), cv::Point2d(frame_size.width - 1, 0),
                            cv::Point2d(0, frame_size.height - 1),
                            cv::Point2d(frame_size.width - 1, frame_size.height - 1)}) {
        const cv::Vec2d q = world[size_t(k)] * cv::Vec3d(p.x, p.y, 1);
        x0 = std::min(x0, q[0]), y0 = std::min(y0, q[1]), x1 = std::max(x1, q[0]), y1 = std::max(y1, q[1]);
      }
      const int bx = int(std::floor(x0)) - 3, by = int(std::floor(y0)) - 3;
      box = cv::Rect(bx, by, int(std::ceil(x1)) + 4 - bx, int(std::ceil(y1)) + 4 - by) & box;
    }
    if (o.scatter) {
      // Each scene pixel's albedo split between the two levels of its own blur radius, each
      // part blurred by its level, the parts summed.
      std::vector<cv::Mat> part(kLevels);
      for (cv::Mat& p : part) p = cv::Mat::zeros(size, CV_32F);
      for (int y = 0; y < size.height; ++y) {
        const float* d = depth.ptr<float>(y);
        const float* a = albedo.ptr<float>(y);
        for (int x = 0; x < size.width; ++x) {
          const double r = blur * std::abs(d[x] - k);
          const double l = std::min(kLevels - 1.001, std::log2(1.0 + r / 1.8));
          const int j = int(l);
          const double w = l - j;
          part[size_t(j)].at<float>(y, x) += float((1 - w) * a[x]);
          part[size_t(j + 1)].at<float>(y, x) += float(w * a[x]);
        }
      }
      sharp = part[0].clone();
      for (int j = 1; j < kLevels; ++j) sharp += PyramidBlur(part[size_t(j)], j);
    }
    // Per pixel: the pyramid level of its blur radius, blended between the two neighbours.
    for (int y = box.y; y < box.y + box.height && !o.scatter; ++y) {
      const float* d = depth.ptr<float>(y);
      float* s = sharp.ptr<float>(y);
      for (int x = box.x; x < box.x + box.width; ++x) {
        const double r = blur * std::abs(d[x] - k);
        const double l = std::min(kLevels - 1.001, std::log2(1.0 + r / 1.8));
        const int j = int(l);
        const double w = l - j;
        s[x] = float((1 - w) * level[size_t(j)].at<float>(y, x) + w * level[size_t(j + 1)].at<float>(y, x));
      }
    }
    cv::Mat frame = sharp;
    if (moving || size != frame_size) {
      cv::warpAffine(sharp, frame, world[size_t(k)], frame_size, cv::INTER_CUBIC | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT_101);
    }
    const double exposure = 1.0 + rng.uniform(-0.01, 0.01);
    cv::Mat electrons = frame.mul(gain) * (full_well * exposure);
    cv::Mat sd;
    cv::sqrt(cv::max(electrons, 0.0), sd);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
    rng.fill(read, cv::RNG::NORMAL, 0.0, o.read_noise_electrons);
    cv::Mat e = electrons + noise.mul(sd) + read;
    cv::Mat v = cv::max(e * (1.0 / full_well), 0.0);
    cv::pow(v, 1.0 / 2.2, v);
    cv::Mat out8;
    v.convertTo(out8, CV_8U, 255.0);
    out.frames.push_back(out8);
    out.frame_from_reference.push_back(After(Inverse(world[size_t(k)]), world[size_t(ref)]));
  }
  return out;
}

}  // namespace chain_bench
