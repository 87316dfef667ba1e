// Layered natural scene rendered through focus (model: devices/sim/natural_scene.h): materials,
// layer shapes and depths from the seed, per-layer spatially varying defocus, back-to-front
// "over" compositing of blurred premultiplied colour and alpha, camera noise and sRGB encoding.
#include "devices/sim/natural_scene.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>

#include "devices/sim/defocus.h"

namespace inspection {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kLadderRatio = 1.15;  // PSF sigma ratio between blurred copies of a layer

// Portable draws (std distributions differ between standard libraries; the stacks must not).
struct Rng {
  std::mt19937 gen;
  explicit Rng(uint32_t seed) : gen(seed) {}
  double Uniform(double a = 0.0, double b = 1.0) { return a + (b - a) * (double(gen()) + 0.5) / 4294967296.0; }
  int Int(int a, int b) { return a + int(gen() % uint32_t(b - a + 1)); }
  double Normal() {  // Box-Muller
    const double u1 = Uniform(), u2 = Uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
  }
};

// Zero-mean, unit-deviation noise whose amplitude spectrum falls as 1/f^beta (natural images:
// beta ~ 1), rolled off above the frequency 1/min_period_px.
cv::Mat PinkNoise(cv::Size size, double beta, double min_period_px, Rng& rng) {
  const int w = cv::getOptimalDFTSize(size.width), h = cv::getOptimalDFTSize(size.height);
  cv::Mat white(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) white.at<float>(y, x) = float(rng.Normal());
  cv::Mat spec;
  cv::dft(white, spec, cv::DFT_COMPLEX_OUTPUT);
  for (int v = 0; v < h; ++v) {
    const double fv = double(v <= h / 2 ? v : v - h) / h;
    for (int u = 0; u < w; ++u) {
      const double fu = double(u <= w / 2 ? u : u - w) / w;
      const double f = std::hypot(fu, fv);
      const double g = f > 0 ? std::pow(f, -beta) * std::exp(-std::pow(f * min_period_px, 2)) : 0.0;
      spec.at<cv::Vec2f>(v, u) *= float(g);
    }
  }
  cv::Mat out;
  cv::idft(spec, out, cv::DFT_REAL_OUTPUT | cv::DFT_SCALE);
  out = out(cv::Rect(0, 0, size.width, size.height)).clone();
  cv::Scalar mean, dev;
  cv::meanStdDev(out, mean, dev);
  out = (out - mean[0]) / std::max(dev[0], 1e-12);
  return out;
}

// A natural colour (BGR, linear) of lightness around `lightness`.
cv::Vec3f RandomColour(Rng& rng, double lightness, double saturation) {
  cv::Vec3f c;
  for (int i = 0; i < 3; ++i) c[i] = float(lightness * std::exp(saturation * rng.Normal()));
  return c;
}

struct Material {
  cv::Mat radiance;  // CV_32FC3, linear BGR
  cv::Mat textured;  // CV_8UC1
  std::string name;
};

// Dead leaves: discs and boxes with radii ~ r^-3 in [r_min, r_max] px, painted until the frame
// is covered ~6 times; drawn at 2x and reduced, so edges are anti-aliased.
cv::Mat DeadLeaves(cv::Size size, double r_min, double r_max, double lightness, double contrast, Rng& rng) {
  constexpr int kSuper = 2;
  cv::Mat canvas(size * kSuper, CV_32FC3, cv::Scalar::all(lightness));
  std::vector<cv::Vec3f> palette;
  const int n_hues = rng.Int(2, 5);
  for (int i = 0; i < n_hues; ++i) palette.push_back(RandomColour(rng, lightness, 0.35));
  const double a = std::pow(r_min, -2.0), b = std::pow(r_max, -2.0);
  double area = 0.0;
  const double target = 6.0 * size.area();
  for (int n = 0; n < 300000 && area < target; ++n) {
    const double r = std::pow(a - rng.Uniform() * (a - b), -0.5);
    const cv::Point2d c(rng.Uniform(-r, size.width + r), rng.Uniform(-r, size.height + r));
    const cv::Vec3f base = palette[rng.Int(0, n_hues - 1)];
    const float shade = float(std::exp(contrast * rng.Normal()));
    const cv::Scalar colour(base[0] * shade, base[1] * shade, base[2] * shade);
    if (rng.Uniform() < 0.7) {
      cv::circle(canvas, c * kSuper, std::max(1, int(std::lround(r * kSuper))), colour, cv::FILLED, cv::LINE_8);
    } else {
      const cv::RotatedRect box(c * kSuper,
                                cv::Size2f(float(2 * r * kSuper), float(2 * r * kSuper * rng.Uniform(0.3, 1.0))),
                                float(rng.Uniform(0, 180)));
      cv::Point2f p[4];
      box.points(p);
      std::vector<cv::Point> poly(p, p + 4);
      cv::fillConvexPoly(canvas, poly, colour, cv::LINE_8);
    }
    area += kPi * r * r;
  }
  cv::Mat out;
  cv::resize(canvas, out, size, 0, 0, cv::INTER_AREA);
  return out;
}

// 1/f noise in lightness with weaker per-channel (chroma) noise: rock, bark, sand, fabric.
cv::Mat PinkMaterial(cv::Size size, double lightness, double contrast, Rng& rng) {
  const cv::Vec3f base = RandomColour(rng, lightness, 0.3);
  const double beta = rng.Uniform(0.8, 1.3);
  const cv::Mat lum = PinkNoise(size, beta, 0.8, rng);
  cv::Mat out(size, CV_32FC3);
  std::vector<cv::Mat> chroma;
  for (int c = 0; c < 3; ++c) chroma.push_back(PinkNoise(size, beta, 2.0, rng));
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      for (int c = 0; c < 3; ++c)
        out.at<cv::Vec3f>(y, x)[c] =
            base[c] * float(std::exp(contrast * (lum.at<float>(y, x) + 0.3 * chroma[c].at<float>(y, x))));
  return out;
}

// Flat paint or sky: one colour and a gradient far wider than any focus window.
cv::Mat FlatMaterial(cv::Size size, double lightness, Rng& rng) {
  const cv::Vec3f base = RandomColour(rng, lightness, 0.4);
  const cv::Mat slow = PinkNoise(size, 3.0, size.width / 3.0, rng);
  const double gx = rng.Uniform(-0.15, 0.15), gy = rng.Uniform(-0.25, 0.25);
  cv::Mat out(size, CV_32FC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double g = 1.0 + gx * (double(x) / size.width - 0.5) + gy * (double(y) / size.height - 0.5) +
                       0.05 * slow.at<float>(y, x);
      out.at<cv::Vec3f>(y, x) = base * float(g);
    }
  return out;
}

// Text-like strokes: lines of random words (Hershey fonts, glyphs glyph_px high) inside `area`,
// ink over `out` (drawn at 2x with anti-aliasing).
void DrawText(cv::Mat& out, cv::Rect area, double glyph_px, const cv::Vec3f& ink, Rng& rng) {
  constexpr int kSuper = 2;
  static const int kFonts[] = {cv::FONT_HERSHEY_SIMPLEX, cv::FONT_HERSHEY_DUPLEX, cv::FONT_HERSHEY_COMPLEX,
                               cv::FONT_HERSHEY_TRIPLEX, cv::FONT_HERSHEY_PLAIN};
  static const char kLetters[] = "abcdefghijklmnopqrstuvwxyzABCDEFGHIKLMNOPRSTUVWXYZ0123456789";
  const int font = kFonts[rng.Int(0, 4)];
  int base_line = 0;
  const double h1 = cv::getTextSize("Hg", font, 1.0, 1, &base_line).height;
  const double scale = glyph_px * kSuper / h1;
  const int thickness = std::max(1, int(std::lround(scale * rng.Uniform(1.0, 2.2))));
  cv::Mat mask(out.size() * kSuper, CV_8UC1, cv::Scalar(0));
  const double line_px = glyph_px * rng.Uniform(1.4, 2.0);
  for (double y = area.y + glyph_px; y < area.y + area.height; y += line_px) {
    std::string line;
    for (int misses = 0; misses < 12;) {  // words until the line is full
      std::string word;
      const int n = rng.Int(1, 9);
      for (int i = 0; i < n; ++i) word += kLetters[rng.Int(0, int(sizeof(kLetters)) - 2)];
      const std::string next = line.empty() ? word : line + " " + word;
      if (cv::getTextSize(next, font, scale, thickness, &base_line).width > area.width * kSuper) {
        ++misses;
        continue;
      }
      line = next;
    }
    if (!line.empty()) {
      cv::putText(mask, line, cv::Point(area.x * kSuper, int(y * kSuper)), font, scale, cv::Scalar(255), thickness,
                  cv::LINE_AA);
    }
  }
  cv::Mat m;
  cv::resize(mask, m, out.size(), 0, 0, cv::INTER_AREA);
  for (int y = 0; y < out.rows; ++y)
    for (int x = 0; x < out.cols; ++x) {
      const float a = m.at<uint8_t>(y, x) / 255.f;
      cv::Vec3f& p = out.at<cv::Vec3f>(y, x);
      p = p * (1.f - a) + ink * a;
    }
}

// A sign or poster: paper (flat, faint 1/f) with words, glyphs 6..22 px.
void DrawSign(cv::Mat& out, cv::Rect area, Rng& rng) {
  const bool dark_on_light = rng.Uniform() < 0.75;
  const cv::Vec3f paper = RandomColour(rng, dark_on_light ? rng.Uniform(0.45, 0.8) : rng.Uniform(0.03, 0.1), 0.2);
  const cv::Vec3f ink = RandomColour(rng, dark_on_light ? rng.Uniform(0.02, 0.08) : rng.Uniform(0.4, 0.8), 0.3);
  const cv::Mat grain = PinkNoise(area.size(), 1.0, 1.0, rng);
  for (int y = 0; y < area.height; ++y)
    for (int x = 0; x < area.width; ++x)
      out.at<cv::Vec3f>(area.y + y, area.x + x) = paper * float(1.0 + 0.03 * grain.at<float>(y, x));
  const int margin = std::max(2, area.width / 12);
  const cv::Rect inner(area.x + margin, area.y + margin / 2, area.width - 2 * margin, area.height - margin);
  if (inner.width > 8 && inner.height > 8) DrawText(out, inner, rng.Uniform(6.0, 22.0), ink, rng);
}

Material MakeMaterial(int kind, cv::Size size, Rng& rng) {
  Material m;
  const double lightness = rng.Uniform(0.08, 0.45);
  const double contrast = std::exp(rng.Uniform(std::log(0.06), std::log(0.6)));  // low-contrast ones too
  m.textured = cv::Mat(size, CV_8UC1, cv::Scalar(255));
  switch (kind) {
    case 0:
      m.radiance = DeadLeaves(size, 1.5, size.width / 5.0, lightness, contrast, rng);
      m.name = "leaves";
      break;
    case 1:
      m.radiance = PinkMaterial(size, lightness, contrast, rng);
      m.name = "pink";
      break;
    case 2:
      m.radiance = FlatMaterial(size, lightness, rng);
      DrawSign(m.radiance, cv::Rect(0, 0, size.width, size.height), rng);
      m.name = "text";
      break;
    default:
      m.radiance = FlatMaterial(size, lightness, rng);
      m.textured.setTo(0);
      m.name = "flat";
      break;
  }
  return m;
}

// Background: textured ground (leaves or 1/f) with flat regions (sky, walls) covering 25-50 %
// of the frame, mostly at the top, and 0..2 posters with text on the textured part.
Material BackgroundMaterial(cv::Size size, Rng& rng) {
  Material m = MakeMaterial(rng.Uniform() < 0.65 ? 0 : 1, size, rng);
  const Material flat = MakeMaterial(3, size, rng);
  const cv::Mat field = PinkNoise(size, 2.5, size.width / 8.0, rng);
  const double flat_fraction = rng.Uniform(0.25, 0.5);
  cv::Mat score(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      score.at<float>(y, x) = float(0.6 * field.at<float>(y, x) + 2.0 * (1.0 - double(y) / size.height));
  std::vector<float> sorted(score.begin<float>(), score.end<float>());
  std::nth_element(sorted.begin(), sorted.begin() + size_t((1.0 - flat_fraction) * sorted.size()), sorted.end());
  const float threshold = sorted[size_t((1.0 - flat_fraction) * sorted.size())];
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      if (score.at<float>(y, x) >= threshold) {
        m.radiance.at<cv::Vec3f>(y, x) = flat.radiance.at<cv::Vec3f>(y, x);
        m.textured.at<uint8_t>(y, x) = 0;
      }
  const int posters = rng.Int(0, 2);
  for (int i = 0; i < posters; ++i) {
    const int w = int(size.width * rng.Uniform(0.15, 0.35)), h = int(size.height * rng.Uniform(0.1, 0.25));
    const cv::Rect r(rng.Int(0, size.width - w), rng.Int(size.height / 3, size.height - h), w, h);
    DrawSign(m.radiance, r, rng);
    m.textured(r).setTo(255);
  }
  m.name += "+flat" + std::to_string(int(flat_fraction * 100)) + "%" + (posters ? "+text" : "");
  return m;
}

// Shape of an object layer as an implicit function g (> 0 inside, ~ distance in px), anti-aliased
// alpha = clamp(0.5 + g, 0, 1).
cv::Mat ObjectAlpha(int shape, cv::Size size, Rng& rng, std::string* name) {
  const double w = size.width, h = size.height;
  const cv::Point2d c(rng.Uniform(0.2, 0.8) * w, rng.Uniform(0.25, 0.85) * h);
  const double angle = rng.Uniform(0, kPi), ca = std::cos(angle), sa = std::sin(angle);
  const double ax = rng.Uniform(0.1, 0.28) * w, ay = rng.Uniform(0.08, 0.22) * h;
  cv::Mat g(size, CV_32F);
  cv::Mat wobble;
  if (shape == 0) wobble = PinkNoise(size, 2.0, 4.0, rng);
  const double pole_half_width = rng.Uniform(0.025, 0.07) * w, corner = rng.Uniform(0.1, 0.5) * std::min(ax, ay);
  const double pole_end = rng.Uniform(-0.2, 0.6) * h;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double dx = x - c.x, dy = y - c.y;
      const double u = ca * dx + sa * dy, v = -sa * dx + ca * dy;
      double val;
      switch (shape) {
        case 0: {  // blob: ellipse with a wavy outline, field scaled to ~px by the ellipse size
          const double rho = std::hypot(u / ax, v / ay);
          val = (1.0 - rho + 0.12 * wobble.at<float>(y, x)) * std::min(ax, ay);
          break;
        }
        case 1:  // ellipse
          val = (1.0 - std::hypot(u / ax, v / ay)) * std::min(ax, ay);
          break;
        case 2: {  // rounded box
          const double qx = std::abs(u) - (ax - corner), qy = std::abs(v) - (ay - corner);
          val = -(std::hypot(std::max(qx, 0.0), std::max(qy, 0.0)) + std::min(std::max(qx, qy), 0.0) - corner);
          break;
        }
        default: {  // pole: a near-vertical bar from the bottom edge up to pole_end
          const double tilt = (angle - kPi / 2) * 0.3;
          const double px = (x - c.x) - std::tan(tilt) * (y - h);
          val = std::min(pole_half_width - std::abs(px), y - pole_end);
          break;
        }
      }
      g.at<float>(y, x) = float(val);
    }
  static const char* kNames[] = {"blob", "ellipse", "box", "pole"};
  *name = kNames[shape];
  cv::Mat alpha;
  cv::min(cv::max(g + 0.5, 0.0), 1.0, alpha);
  return alpha;
}

struct Layer {
  cv::Mat premultiplied;  // CV_32FC4: a B, a G, a R, a
  cv::Mat depth;          // CV_32FC1, defined everywhere
  cv::Mat alpha;          // CV_32FC1
  cv::Mat textured;       // CV_8UC1
};

// Depth of a layer: plane + dome + (background) undulation, mapped into [lo, hi] over the
// pixels where the layer exists.
cv::Mat LayerDepth(cv::Size size, const cv::Mat& alpha, double lo, double hi, bool background, Rng& rng) {
  const double gx = rng.Uniform(-1, 1), gy = background ? rng.Uniform(0.5, 1.5) : rng.Uniform(-1, 1);
  const double dome = rng.Uniform(-1, 1) * (background ? 0.2 : 0.8);
  const cv::Point2d c(rng.Uniform(0.3, 0.7) * size.width, rng.Uniform(0.3, 0.7) * size.height);
  cv::Mat undulation;
  if (background) undulation = PinkNoise(size, 3.0, size.width / 4.0, rng);
  cv::Mat d(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double u = (x - c.x) / size.width, v = (y - c.y) / size.height;
      // Background: far (large depth) at the top, like ground receding to the horizon.
      double val = gx * u - gy * v + dome * (1.0 - 4.0 * (u * u + v * v));
      if (background) val += 0.08 * undulation.at<float>(y, x);
      d.at<float>(y, x) = float(val);
    }
  double dmin, dmax;
  cv::minMaxLoc(d, &dmin, &dmax, nullptr, nullptr, alpha > 0.01);
  const double span = (hi - lo) * rng.Uniform(0.4, 1.0);
  const double start = lo + rng.Uniform(0.0, (hi - lo) - span);
  d = (d - dmin) * (span / std::max(dmax - dmin, 1e-9)) + start;
  // Outside the layer's footprint the extrapolated dome can run far off; only the blur of the
  // layer's own edge sees it there, so keep it within the band.
  cv::Mat clamped;
  cv::min(cv::max(d, lo), hi, clamped);
  return clamped;
}

// Blurred copies of a layer at sigma_0 * ratio^i (i = 0..n-1), premultiplied colour and alpha.
// Small kernels run directly; large ones as products of spectra of the reflect-padded layer,
// whose transform is computed once for all rungs.
std::vector<cv::Mat> Ladder(const Layer& layer, const DefocusModel& model, double max_sigma,
                            std::vector<double>* sigmas) {
  sigmas->clear();
  for (double s = model.in_focus_sigma_px;; s *= kLadderRatio) {
    sigmas->push_back(s);
    if (s >= max_sigma) break;
  }
  if (sigmas->size() < 2) sigmas->push_back(model.in_focus_sigma_px * kLadderRatio);
  std::vector<cv::Mat> kernels;
  int pad = 1;
  for (double s : *sigmas) {
    cv::Mat k;
    model.Kernel(s).convertTo(k, CV_32F);
    pad = std::max(pad, k.rows / 2 + 1);
    kernels.push_back(k);
  }
  const cv::Size size = layer.premultiplied.size();
  const cv::Size dft_size(cv::getOptimalDFTSize(size.width + 2 * pad), cv::getOptimalDFTSize(size.height + 2 * pad));
  std::vector<cv::Mat> spectra;  // per channel, computed on first use
  std::vector<cv::Mat> rungs;
  for (const cv::Mat& k : kernels) {
    cv::Mat out;
    if (k.rows <= 7) {
      cv::filter2D(layer.premultiplied, out, CV_32F, k, cv::Point(-1, -1), 0, cv::BORDER_REFLECT_101);
      rungs.push_back(out);
      continue;
    }
    if (spectra.empty()) {
      cv::Mat padded;
      cv::copyMakeBorder(layer.premultiplied, padded, pad, dft_size.height - size.height - pad, pad,
                         dft_size.width - size.width - pad, cv::BORDER_REFLECT_101);
      std::vector<cv::Mat> chans;
      cv::split(padded, chans);
      for (const cv::Mat& c : chans) {
        cv::Mat f;
        cv::dft(c, f, cv::DFT_COMPLEX_OUTPUT);
        spectra.push_back(f);
      }
    }
    // Kernel centred on (0, 0) with wrap-around, so the product is a correlation = convolution
    // (the kernels are symmetric).
    cv::Mat kp(dft_size, CV_32F, cv::Scalar(0));
    const int h = k.rows / 2;
    for (int y = 0; y < k.rows; ++y)
      for (int x = 0; x < k.cols; ++x)
        kp.at<float>((y - h + dft_size.height) % dft_size.height, (x - h + dft_size.width) % dft_size.width) =
            k.at<float>(y, x);
    cv::Mat kf;
    cv::dft(kp, kf, cv::DFT_COMPLEX_OUTPUT);
    std::vector<cv::Mat> chans;
    for (const cv::Mat& f : spectra) {
      cv::Mat prod, back;
      cv::mulSpectrums(f, kf, prod, 0);
      cv::idft(prod, back, cv::DFT_REAL_OUTPUT | cv::DFT_SCALE);
      chans.push_back(back(cv::Rect(pad, pad, size.width, size.height)).clone());
    }
    cv::merge(chans, out);
    rungs.push_back(out);
  }
  return rungs;
}

// accum = blurred layer + (1 - blurred alpha) accum, the PSF of each pixel given by its defocus.
void CompositeOver(const Layer& layer, const std::vector<cv::Mat>& rungs, const std::vector<double>& sigmas,
                   const DefocusModel& model, double focus_frame, cv::Mat* accum) {
  const double log_ratio = std::log(kLadderRatio);
  const int n = int(sigmas.size());
  for (int y = 0; y < accum->rows; ++y) {
    const float* d = layer.depth.ptr<float>(y);
    cv::Vec3f* acc = accum->ptr<cv::Vec3f>(y);
    for (int x = 0; x < accum->cols; ++x) {
      const double s = model.SigmaPx(d[x] - focus_frame);
      int i = std::clamp(int(std::floor(std::log(s / sigmas[0]) / log_ratio)), 0, n - 2);
      const double s0 = sigmas[i], s1 = sigmas[i + 1];
      const float w = float(std::clamp((s * s - s0 * s0) / (s1 * s1 - s0 * s0), 0.0, 1.0));
      const cv::Vec4f p = rungs[i].at<cv::Vec4f>(y, x) * (1.f - w) + rungs[i + 1].at<cv::Vec4f>(y, x) * w;
      const float a = std::clamp(p[3], 0.f, 1.f);
      acc[x] = cv::Vec3f(p[0], p[1], p[2]) + acc[x] * (1.f - a);
    }
  }
}

double SrgbEncode(double v) { return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055; }

// Noise (shot + read), saturation, sRGB curve, quantisation; grey = BT.709 luminance.
cv::Mat Expose(const cv::Mat& radiance, const NaturalSceneOptions& o, Rng* rng) {
  const int depth = o.bit_depth == 8 ? CV_8U : CV_16U;
  const double full = o.bit_depth == 8 ? 255.0 : 65535.0;
  const int cn = o.colour ? 3 : 1;
  cv::Mat out(radiance.size(), CV_MAKETYPE(depth, cn));
  for (int y = 0; y < radiance.rows; ++y)
    for (int x = 0; x < radiance.cols; ++x) {
      const cv::Vec3f r = radiance.at<cv::Vec3f>(y, x);
      double v[3] = {r[0], r[1], r[2]};
      if (!o.colour) v[0] = 0.0722 * r[0] + 0.7152 * r[1] + 0.2126 * r[2];  // BGR
      for (int c = 0; c < cn; ++c) {
        double e = std::max(v[c], 0.0) * o.full_well_electrons;
        if (rng) e += std::sqrt(e + o.read_noise_electrons * o.read_noise_electrons) * rng->Normal();
        const double q = std::round(SrgbEncode(std::clamp(e / o.full_well_electrons, 0.0, 1.0)) * full);
        if (depth == CV_8U)
          out.ptr<uint8_t>(y)[cn * x + c] = uint8_t(q);
        else
          out.ptr<uint16_t>(y)[cn * x + c] = uint16_t(q);
      }
    }
  return out;
}

}  // namespace

Status NaturalSceneOptions::Validate() const {
  if (size.width < 64 || size.height < 64 || size.width > 2048 || size.height > 2048) {
    return Status::InvalidArgument("size must be 64..2048 px per side");
  }
  if (frames < 5 || frames > 100) return Status::InvalidArgument("frames must be 5..100");
  if (blur_radius_px_per_frame > 10.0) return Status::InvalidArgument("blur_radius_px_per_frame must be <= 10");
  if (!(in_focus_sigma_px >= 0.2 && in_focus_sigma_px <= 3.0)) {
    return Status::InvalidArgument("in_focus_sigma_px must be 0.2..3");
  }
  if (!(full_well_electrons >= 100.0)) return Status::InvalidArgument("full_well_electrons must be >= 100");
  if (!(read_noise_electrons >= 0.0)) return Status::InvalidArgument("read_noise_electrons must be >= 0");
  if (bit_depth != 8 && bit_depth != 16) return Status::InvalidArgument("bit_depth must be 8 or 16");
  return Status::Ok();
}

StatusOr<NaturalScene> RenderNaturalScene(const NaturalSceneOptions& o) {
  INSPECT_RETURN_IF_ERROR(o.Validate());
  Rng rng(o.seed * 2654435761u + 17u);
  const cv::Size size = o.size;
  const double n = o.frames;
  NaturalScene scene;
  scene.blur_radius_px_per_frame = o.blur_radius_px_per_frame > 0 ? o.blur_radius_px_per_frame : rng.Uniform(0.5, 1.2);
  DefocusModel model;
  model.in_focus_sigma_px = o.in_focus_sigma_px;
  model.blur_radius_px_per_um = scene.blur_radius_px_per_frame;  // "um" = frames here
  model.gaussian_until_sigma_px = 1.0;                           // a camera's defocus is a disc already at a few px
  model.pillbox_from_sigma_px = 4.0;
  std::ostringstream desc;
  desc.precision(3);
  desc << "blur " << scene.blur_radius_px_per_frame << " px/frame;";

  // Layers, back to front.
  std::vector<Layer> layers;
  {
    Material m = BackgroundMaterial(size, rng);
    Layer l;
    l.alpha = cv::Mat(size, CV_32F, cv::Scalar(1.f));
    const double lo = n * rng.Uniform(0.48, 0.6), hi = n * rng.Uniform(0.75, 0.92);
    l.depth = LayerDepth(size, l.alpha, lo, hi, true, rng);
    l.textured = m.textured;
    cv::Mat chans[3];
    cv::split(m.radiance, chans);
    cv::merge(std::vector<cv::Mat>{chans[0], chans[1], chans[2], l.alpha}, l.premultiplied);
    desc << " background " << m.name;
    layers.push_back(std::move(l));
  }
  const int objects = rng.Int(2, 4);
  const double band_far = 0.46 * n, band_near = 0.06 * n, band = (band_far - band_near) / objects;
  for (int i = 0; i < objects; ++i) {
    std::string shape;
    Layer l;
    l.alpha = ObjectAlpha(rng.Int(0, 3), size, rng, &shape);
    const int kind = rng.Uniform() < 0.2 ? 3 : rng.Int(0, 2);  // 1 in 5 objects is textureless
    Material m = MakeMaterial(kind, size, rng);
    const double hi = band_far - i * band - 0.1 * band, lo = band_far - (i + 1) * band + 0.1 * band;
    l.depth = LayerDepth(size, l.alpha, lo, hi, false, rng);
    l.textured = m.textured;
    std::vector<cv::Mat> chans(3);
    cv::split(m.radiance, chans.data());
    for (auto& ch : chans) ch = ch.mul(l.alpha);
    chans.push_back(l.alpha);
    cv::merge(chans, l.premultiplied);
    desc << "; " << shape << " " << m.name;
    layers.push_back(std::move(l));
  }
  // Smooth illumination over the whole scene (one light, soft shadows).
  const cv::Mat shading_field = PinkNoise(size, 3.0, size.width / 6.0, rng);
  cv::Mat shading;
  cv::min(cv::max(0.85 + 0.2 * shading_field, 0.5), 1.2, shading);

  // Ground truth: the frontmost layer with alpha >= 0.5.
  scene.depth_frames = cv::Mat(size, CV_32F);
  scene.textured = cv::Mat(size, CV_8UC1);
  for (const Layer& l : layers) {
    const cv::Mat front = l.alpha >= 0.5;
    l.depth.copyTo(scene.depth_frames, front);
    l.textured.copyTo(scene.textured, front);
  }
  double dmin, dmax;
  cv::minMaxLoc(scene.depth_frames, &dmin, &dmax);
  desc << "; depth " << dmin << ".." << dmax << " of " << o.frames << " frames";
  scene.description = desc.str();
  cv::Mat dil, ero;
  const cv::Mat k7 = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(7, 7));
  cv::dilate(scene.depth_frames, dil, k7);
  cv::erode(scene.depth_frames, ero, k7);
  scene.occlusion_edge = (dil - ero) > 1.0;

  // Render: every layer's ladder once, composited into every frame (and the in-focus image).
  std::vector<cv::Mat> accum(o.frames + 1);
  for (auto& a : accum) a = cv::Mat(size, CV_32FC3, cv::Scalar::all(0));
  for (const Layer& l : layers) {
    double lmin, lmax;
    cv::minMaxLoc(l.depth, &lmin, &lmax);
    const double max_defocus = std::max(std::abs(lmin), std::abs(lmax - (n - 1))) + 1.0;
    std::vector<double> sigmas;
    const std::vector<cv::Mat> rungs = Ladder(l, model, model.SigmaPx(max_defocus), &sigmas);
    for (int k = 0; k < o.frames; ++k) CompositeOver(l, rungs, sigmas, model, k, &accum[k]);
    // In-focus image: every pixel at its own layer's focus (defocus 0).
    Layer focused = l;
    focused.depth = cv::Mat(size, CV_32F, cv::Scalar(0.f));
    CompositeOver(focused, rungs, sigmas, model, 0.0, &accum[o.frames]);
  }
  // Exposure: the 99.5th percentile of the in-focus luminance at 0.92 of full scale.
  cv::Mat aif = accum[o.frames];
  for (auto& a : accum) {
    std::vector<cv::Mat> ch(3);
    cv::split(a, ch.data());
    for (auto& c : ch) c = c.mul(shading);
    cv::merge(ch, a);
  }
  std::vector<float> lum;
  lum.reserve(size.area());
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const cv::Vec3f p = aif.at<cv::Vec3f>(y, x);
      lum.push_back(0.0722f * p[0] + 0.7152f * p[1] + 0.2126f * p[2]);
    }
  const size_t q = size_t(0.995 * (lum.size() - 1));
  std::nth_element(lum.begin(), lum.begin() + q, lum.end());
  const double exposure = 0.92 / std::max(double(lum[q]), 1e-6);
  for (int k = 0; k <= o.frames; ++k) {
    accum[k] *= exposure;
    Rng noise(o.seed * 7919u + uint32_t(k) * 104729u + 3u);
    if (k < o.frames)
      scene.frames.push_back(Expose(accum[k], o, &noise));
    else
      scene.all_in_focus = Expose(accum[k], o, nullptr);
  }
  return scene;
}

}  // namespace inspection
