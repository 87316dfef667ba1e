// aif-edges: do all-in-focus images repeat edges? A measure of duplicated edges (ghost contours
// of an unaligned focus-rail stack), for any all-in-focus image beside the frames it came from,
// so that ours and focus-stack's are scored the same way.
//
// Per tile (default 128 px, tiles within --margin of the border left out: an aligned result
// masks the pixels some frame did not see): Canny edge pixels of the all-in-focus image against
// the most any single frame has in that tile (frames as captured: a focus rail moves them by a
// few px per frame, which a 128 px tile absorbs). A clean composite has about as many edges as
// the sharpest frame in a tile, somewhat more where the tile holds parts sharp in different
// frames; every ghost contour adds its own. Tiles where the sharpest frame has edges on under 1 %
// of its pixels (untextured) are left out. Prints, per image: tiles, median and 90th percentile
// of the ratio, the share of tiles over 1.5, and the same for the gradient energy (sum of
// squared Sobel responses), whose ratio a ghost raises less (a ghost edge is a blurred one).
//
//   aif-edges --frames DIR [--tile 128] [--margin 64] [--crop X,Y,W,H,OUT.png] NAME=IMAGE [NAME=IMAGE ...]
// --crop: the same region of every named image, side by side at 2x (nearest), to look at.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

struct Maps {
  cv::Mat edges;   // CV_8U, 255 on an edge
  cv::Mat energy;  // CV_64F, squared gradient magnitude
};

Maps MapsOf(const cv::Mat& bgr_or_grey) {
  cv::Mat grey;
  if (bgr_or_grey.channels() == 3) {
    cv::cvtColor(bgr_or_grey, grey, cv::COLOR_BGR2GRAY);
  } else {
    grey = bgr_or_grey;
  }
  if (grey.depth() != CV_8U) grey.convertTo(grey, CV_8U, 255.0 / 65535.0);
  cv::Mat smooth;
  cv::GaussianBlur(grey, smooth, cv::Size(0, 0), 1.0);
  Maps m;
  cv::Canny(smooth, m.edges, 40, 100, 3, true);
  cv::Mat gx, gy;
  cv::Sobel(smooth, gx, CV_64F, 1, 0);
  cv::Sobel(smooth, gy, CV_64F, 0, 1);
  m.energy = gx.mul(gx) + gy.mul(gy);
  return m;
}

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5))];
}

}  // namespace

int main(int argc, char** argv) {
  std::string frames_dir;
  int tile = 128, margin = 64;
  std::vector<std::pair<std::string, std::string>> images;
  cv::Rect crop;
  std::string crop_file;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--crop" && i + 1 < argc) {
      char out[512] = {0};
      if (std::sscanf(argv[++i], "%d,%d,%d,%d,%511s", &crop.x, &crop.y, &crop.width, &crop.height, out) != 5) {
        std::fprintf(stderr, "aif-edges: --crop wants X,Y,W,H,OUT.png\n");
        return 2;
      }
      crop_file = out;
    } else if (a == "--frames" && i + 1 < argc) {
      frames_dir = argv[++i];
    } else if (a == "--tile" && i + 1 < argc) {
      tile = std::atoi(argv[++i]);
    } else if (a == "--margin" && i + 1 < argc) {
      margin = std::atoi(argv[++i]);
    } else if (a.find('=') != std::string::npos) {
      images.emplace_back(a.substr(0, a.find('=')), a.substr(a.find('=') + 1));
    } else {
      std::fprintf(stderr, "aif-edges: unknown argument '%s'\n", a.c_str());
      return 2;
    }
  }
  if (frames_dir.empty() || images.empty() || tile < 16 || margin < 0) {
    std::fprintf(stderr, "usage: aif-edges --frames DIR [--tile 128] [--margin 64] NAME=IMAGE ...\n");
    return 2;
  }
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(frames_dir))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::vector<Maps> frames;
  for (const fs::path& f : files) {
    cv::Mat m = cv::imread(f.string(), cv::IMREAD_UNCHANGED);
    if (m.empty()) {
      std::fprintf(stderr, "aif-edges: %s is not an image\n", f.c_str());
      return 2;
    }
    frames.push_back(MapsOf(m));
    if (frames.back().edges.size() != frames.front().edges.size()) {
      std::fprintf(stderr, "aif-edges: %s differs in size from %s\n", f.c_str(), files.front().c_str());
      return 2;
    }
  }
  if (frames.empty()) {
    std::fprintf(stderr, "aif-edges: no frames in %s\n", frames_dir.c_str());
    return 2;
  }
  const cv::Size size = frames.front().edges.size();
  // Per tile: the sharpest frame's edge count and gradient energy.
  struct Tile {
    cv::Rect r;
    double edges = 0, energy = 0;
  };
  std::vector<Tile> tiles;
  for (int y = margin; y + tile <= size.height - margin; y += tile) {
    for (int x = margin; x + tile <= size.width - margin; x += tile) {
      Tile t{cv::Rect(x, y, tile, tile)};
      for (const Maps& f : frames) {
        t.edges = std::max(t.edges, double(cv::countNonZero(f.edges(t.r))));
        t.energy = std::max(t.energy, cv::sum(f.energy(t.r))[0]);
      }
      if (t.edges >= 0.01 * tile * tile) tiles.push_back(t);
    }
  }
  std::printf("%zu frames of %dx%d, %zu textured tiles of %d px (margin %d px)\n", frames.size(), size.width,
              size.height, tiles.size(), tile, margin);
  std::printf("%-24s %8s %8s %9s | %8s %8s %9s\n", "image", "edges", "p90", ">1.5", "energy", "p90", ">1.5");
  std::vector<cv::Mat> crops;
  for (const auto& [name, file] : images) {
    cv::Mat m = cv::imread(file, cv::IMREAD_UNCHANGED);
    if (m.empty()) {
      std::fprintf(stderr, "aif-edges: %s is not an image\n", file.c_str());
      return 2;
    }
    if (m.size() != size) {
      std::fprintf(stderr, "aif-edges: %s is %dx%d, the frames %dx%d\n", file.c_str(), m.cols, m.rows, size.width,
                   size.height);
      return 2;
    }
    if (!crop_file.empty()) {
      if ((crop & cv::Rect(0, 0, m.cols, m.rows)) != crop) {
        std::fprintf(stderr, "aif-edges: --crop lies outside %s\n", file.c_str());
        return 2;
      }
      cv::Mat c = m(crop).clone(), big;
      if (c.depth() != CV_8U) c.convertTo(c, CV_8U, 255.0 / 65535.0);
      if (c.channels() == 1) cv::cvtColor(c, c, cv::COLOR_GRAY2BGR);
      cv::resize(c, big, cv::Size(), 2, 2, cv::INTER_NEAREST);
      if (!crops.empty()) crops.push_back(cv::Mat(big.rows, 8, CV_8UC3, cv::Scalar(255, 255, 255)));
      crops.push_back(big);
    }
    const Maps a = MapsOf(m);
    std::vector<double> edge_ratio, energy_ratio;
    for (const Tile& t : tiles) {
      edge_ratio.push_back(double(cv::countNonZero(a.edges(t.r))) / t.edges);
      energy_ratio.push_back(cv::sum(a.energy(t.r))[0] / std::max(t.energy, 1.0));
    }
    auto over = [](const std::vector<double>& v) {
      return 100.0 * double(std::count_if(v.begin(), v.end(), [](double r) { return r > 1.5; })) /
             double(std::max<size_t>(v.size(), 1));
    };
    std::printf("%-24s %8.3f %8.3f %8.1f%% | %8.3f %8.3f %8.1f%%\n", name.c_str(), Quantile(edge_ratio, 0.5),
                Quantile(edge_ratio, 0.9), over(edge_ratio), Quantile(energy_ratio, 0.5), Quantile(energy_ratio, 0.9),
                over(energy_ratio));
  }
  if (!crop_file.empty()) {
    cv::Mat side;
    cv::hconcat(crops, side);
    if (!cv::imwrite(crop_file, side)) {
      std::fprintf(stderr, "aif-edges: cannot write %s\n", crop_file.c_str());
      return 2;
    }
    std::printf("crop %d,%d %dx%d of each image, left to right in the order given: %s\n", crop.x, crop.y, crop.width,
                crop.height, crop_file.c_str());
  }
  return 0;
}
