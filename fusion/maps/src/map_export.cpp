#include "fusionloc/maps/map_export.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "fusionloc/common/log.hpp"

namespace fl::maps {
namespace {

std::string BaseName(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

void CommitFile(const std::string& tmp, const std::string& path) {
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw MapExportError("cannot rename '" + tmp + "' to '" + path + "'");
  }
}

void WriteBytesAtomically(const std::string& path, const void* data, size_t size) {
  const std::string tmp = path + ".partial";
  {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw MapExportError("cannot write '" + path + "': does the folder exist?");
    out.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
    if (!out.good()) {
      out.close();
      std::remove(tmp.c_str());
      throw MapExportError("error writing '" + tmp + "' (disk full?)");
    }
  }
  CommitFile(tmp, path);
}

void WritePngAtomically(const cv::Mat& img, const std::string& path) {
  std::vector<uchar> buffer;
  if (!cv::imencode(".png", img, buffer)) throw MapExportError("PNG encoding failed: " + path);
  WriteBytesAtomically(path, buffer.data(), buffer.size());
}

}  // namespace

void ValidateGrid(const fusionloc::occupancy_grid_t& g) {
  if (g.width <= 0 || g.height <= 0) {
    throw MapExportError("occupancy grid has size " + std::to_string(g.width) + " x " +
                         std::to_string(g.height) + " cells; both must be > 0 (empty map?)");
  }
  const int64_t n = static_cast<int64_t>(g.width) * g.height;
  if (g.num_cells != n || static_cast<int64_t>(g.cells.size()) != n) {
    throw MapExportError("occupancy grid is inconsistent: width*height = " + std::to_string(n) +
                         " but num_cells = " + std::to_string(g.num_cells) + " and " +
                         std::to_string(g.cells.size()) + " cells; fix the map producer");
  }
  if (!(g.resolution > 0) || !std::isfinite(g.resolution)) {
    throw MapExportError("occupancy grid resolution must be > 0 m, got " +
                         std::to_string(g.resolution));
  }
  if (!std::isfinite(g.origin_x) || !std::isfinite(g.origin_y)) {
    throw MapExportError("occupancy grid origin is NaN or infinite");
  }
  for (size_t i = 0; i < g.cells.size(); ++i) {
    if (g.cells[i] < -1 || g.cells[i] > 100) {
      throw MapExportError("occupancy grid cell " + std::to_string(i) + " (row " +
                           std::to_string(i / static_cast<size_t>(g.width)) + ", column " +
                           std::to_string(i % static_cast<size_t>(g.width)) + ") is " +
                           std::to_string(g.cells[i]) + "; cells must be -1 (unknown) or 0..100");
    }
  }
}

std::vector<std::string> SaveOccupancyGrid(const fusionloc::occupancy_grid_t& g,
                                           const std::string& base_path,
                                           const GridExportOptions& options) {
  ValidateGrid(g);
  if (options.free_max_percent < 0 || options.occupied_min_percent > 100 ||
      options.free_max_percent >= options.occupied_min_percent) {
    throw MapExportError(
        "grid export thresholds must satisfy 0 <= free_max_percent < "
        "occupied_min_percent <= 100");
  }
  if (base_path.empty()) throw MapExportError("empty output path for the occupancy grid");
  const int w = g.width, h = g.height;
  // Image row 0 is the top of the map (largest y): grid row h-1.
  cv::Mat trinary(h, w, CV_8UC1), gray(h, w, CV_8UC1);
  for (int r = 0; r < h; ++r) {
    const int8_t* row = &g.cells[static_cast<size_t>(r) * static_cast<size_t>(w)];
    uchar* tri = trinary.ptr<uchar>(h - 1 - r);
    uchar* gr = gray.ptr<uchar>(h - 1 - r);
    for (int c = 0; c < w; ++c) {
      const int v = row[c];
      if (v < 0) {
        tri[c] = 205;
        gr[c] = 205;
        continue;
      }
      tri[c] = v >= options.occupied_min_percent ? 0 : v <= options.free_max_percent ? 254 : 205;
      gr[c] = static_cast<uchar>(std::lround(255.0 * (1.0 - v / 100.0)));
    }
  }
  const std::string pgm_path = base_path + ".pgm";
  const std::string yaml_path = base_path + ".yaml";
  const std::string png_path = base_path + ".png";

  std::ostringstream pgm;
  pgm << "P5\n# fusionloc occupancy grid, " << g.resolution << " m/cell\n"
      << w << " " << h << "\n255\n";
  std::string bytes = pgm.str();
  bytes.append(reinterpret_cast<const char*>(trinary.data), static_cast<size_t>(w) * h);
  WriteBytesAtomically(pgm_path, bytes.data(), bytes.size());

  std::ostringstream yaml;
  yaml << std::setprecision(12);
  yaml << "image: " << BaseName(pgm_path) << "\n"
       << "mode: trinary\n"
       << "resolution: " << g.resolution << "\n"
       << "origin: [" << g.origin_x << ", " << g.origin_y << ", 0.0]\n"
       << "negate: 0\n"
       << "occupied_thresh: " << options.occupied_thresh << "\n"
       << "free_thresh: " << options.free_thresh << "\n";
  const std::string y = yaml.str();
  WriteBytesAtomically(yaml_path, y.data(), y.size());
  WritePngAtomically(gray, png_path);
  return {pgm_path, yaml_path, png_path};
}

std::vector<Eigen::Vector3f> PointsFromMessage(const fusionloc::point_cloud_t& msg) {
  if (msg.num_points < 0 || static_cast<size_t>(msg.num_points) != msg.points.size()) {
    throw MapExportError("point cloud: num_points = " + std::to_string(msg.num_points) +
                         " but the message has " + std::to_string(msg.points.size()) + " points");
  }
  if (msg.num_intensities != 0 && msg.num_intensities != msg.num_points) {
    throw MapExportError("point cloud: num_intensities must be 0 or num_points (" +
                         std::to_string(msg.num_points) + "), got " +
                         std::to_string(msg.num_intensities));
  }
  std::vector<Eigen::Vector3f> points;
  points.reserve(msg.points.size());
  for (const auto& p : msg.points) points.emplace_back(p[0], p[1], p[2]);
  return points;
}

void SavePointCloudTopView(const std::vector<Eigen::Vector3f>& points, const std::string& png_path,
                           double resolution_m) {
  if (!(resolution_m > 0) || !std::isfinite(resolution_m)) {
    throw MapExportError("top-view resolution must be > 0 m/pixel, got " +
                         std::to_string(resolution_m));
  }
  float xmin = std::numeric_limits<float>::max(), ymin = xmin, zmin = xmin;
  float xmax = std::numeric_limits<float>::lowest(), ymax = xmax, zmax = xmax;
  size_t finite = 0;
  for (const auto& p : points) {
    if (!p.allFinite()) continue;
    ++finite;
    xmin = std::min(xmin, p.x());
    xmax = std::max(xmax, p.x());
    ymin = std::min(ymin, p.y());
    ymax = std::max(ymax, p.y());
    zmin = std::min(zmin, p.z());
    zmax = std::max(zmax, p.z());
  }
  if (finite == 0) {
    throw MapExportError("point cloud for '" + png_path + "' has no finite points (" +
                         std::to_string(points.size()) + " points in total)");
  }
  if (finite < points.size()) {
    FL_LOG(WARN) << "top view '" << png_path << "': " << points.size() - finite
                 << " non-finite point(s) not drawn";
  }
  const int margin = 20;
  const double wd = std::ceil((xmax - xmin) / resolution_m) + 1;
  const double hd = std::ceil((ymax - ymin) / resolution_m) + 1;
  if (wd > 8000 || hd > 8000) {
    throw MapExportError("top view at " + std::to_string(resolution_m) + " m/pixel would be " +
                         std::to_string(static_cast<long>(wd)) + " x " +
                         std::to_string(static_cast<long>(hd)) +
                         " pixels (max 8000); choose a coarser --resolution");
  }
  const int w = static_cast<int>(wd) + 2 * margin, h = static_cast<int>(hd) + 2 * margin + 30;
  // Highest z per pixel, then colour.
  cv::Mat zimg(h, w, CV_32FC1, cv::Scalar(std::numeric_limits<float>::lowest()));
  for (const auto& p : points) {
    if (!p.allFinite()) continue;
    const int c = margin + static_cast<int>(std::floor((p.x() - xmin) / resolution_m));
    const int r = margin + static_cast<int>(hd) - 1 -
                  static_cast<int>(std::floor((p.y() - ymin) / resolution_m));
    float& z = zimg.at<float>(r, c);
    z = std::max(z, p.z());
  }
  const float zspan = std::max(zmax - zmin, 1e-6f);
  cv::Mat level(h, w, CV_8UC1, cv::Scalar(0));
  cv::Mat mask(h, w, CV_8UC1, cv::Scalar(0));
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const float z = zimg.at<float>(r, c);
      if (z == std::numeric_limits<float>::lowest()) continue;
      level.at<uchar>(r, c) = static_cast<uchar>(std::lround(255.0f * (z - zmin) / zspan));
      mask.at<uchar>(r, c) = 255;
    }
  }
  cv::Mat colored;
  cv::applyColorMap(level, colored, cv::COLORMAP_VIRIDIS);
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
  colored.copyTo(img, mask);
  // Scale bar: a 1/2/5 x 10^n length about a quarter of the width.
  const double target = 0.25 * (w - 2 * margin) * resolution_m;
  double bar = std::pow(10.0, std::floor(std::log10(target)));
  if (5 * bar <= target) {
    bar *= 5;
  } else if (2 * bar <= target) {
    bar *= 2;
  }
  const int bar_px = std::max(1, static_cast<int>(std::lround(bar / resolution_m)));
  const cv::Point a(margin, h - 12), b(margin + bar_px, h - 12);
  cv::line(img, a, b, cv::Scalar(40, 40, 40), 2);
  std::ostringstream label;
  label << bar << " m  (z " << std::setprecision(3) << zmin << " .. " << zmax << " m)";
  cv::putText(img, label.str(), cv::Point(b.x + 8, h - 7), cv::FONT_HERSHEY_SIMPLEX, 0.4,
              cv::Scalar(40, 40, 40), 1, cv::LINE_AA);
  WritePngAtomically(img, png_path);
}

}  // namespace fl::maps
