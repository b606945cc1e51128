#include "fusionloc/importers/kitti.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <sstream>
#include <stdexcept>

#include "bot_core/images_t.hpp"
#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/laser_scan_3d_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"

namespace fl::importers {
namespace fs = std::filesystem;
namespace {

[[noreturn]] void Fail(const std::string& what) { throw std::runtime_error(what); }

std::string Join(const std::string& a, const std::string& b) { return (fs::path(a) / b).string(); }

bool IsDir(const std::string& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}
bool IsFile(const std::string& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

// Sorted files of a folder with extension `ext` (lower case, with the dot; error if the folder
// is missing).
std::vector<std::string> ListFiles(const std::string& dir, const std::string& ext_wanted) {
  if (!IsDir(dir)) Fail(dir + ": folder missing (expected the KITTI image folder here)");
  std::vector<std::string> out;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const fs::path& p = it->path();
    std::string ext = p.extension().string();
    for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ext_wanted) out.push_back(p.string());
  }
  if (ec) Fail(dir + ": cannot list folder: " + ec.message());
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> ListPngs(const std::string& dir) { return ListFiles(dir, ".png"); }

// A whole text file.
std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  if (!in) Fail(path + ": cannot open (missing or unreadable)");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) Fail(path + ": read error");
  return ss.str();
}

// Non-empty lines of a text with their 1-based line numbers.
std::vector<std::pair<int, std::string>> SplitLines(const std::string& text) {
  std::vector<std::pair<int, std::string>> out;
  std::istringstream in(text);
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (!line.empty()) out.emplace_back(n, line);
  }
  return out;
}

std::vector<std::pair<int, std::string>> ReadLines(const std::string& path) {
  return SplitLines(ReadText(path));
}

// Parses exactly `count` finite numbers from `text`; else a FILE:LINE error.
std::vector<double> ParseNumbers(const std::string& text, size_t count, const std::string& path,
                                 int line, const std::string& what) {
  std::vector<double> v;
  std::istringstream ss(text);
  std::string tok;
  while (ss >> tok) {
    char* end = nullptr;
    const double x = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0' || !std::isfinite(x)) {
      Fail(path + ":" + std::to_string(line) + ": " + what + ": '" + tok +
           "' is not a finite number");
    }
    v.push_back(x);
  }
  if (v.size() != count) {
    Fail(path + ":" + std::to_string(line) + ": " + what + ": expected " + std::to_string(count) +
         " numbers, found " + std::to_string(v.size()));
  }
  return v;
}

// "KEY: numbers" calibration text -> key -> (line, text after the colon).
std::map<std::string, std::pair<int, std::string>> ParseCalibText(const std::string& text,
                                                                  const std::string& path) {
  std::map<std::string, std::pair<int, std::string>> out;
  for (const auto& [n, line] : SplitLines(text)) {
    const size_t colon = line.find(':');
    if (colon == std::string::npos) {
      Fail(path + ":" + std::to_string(n) + ": expected 'KEY: values', found '" + line + "'");
    }
    out[line.substr(0, colon)] = {n, line.substr(colon + 1)};
  }
  return out;
}

std::map<std::string, std::pair<int, std::string>> ReadCalibFile(const std::string& path) {
  return ParseCalibText(ReadText(path), path);
}

std::vector<double> CalibValue(const std::map<std::string, std::pair<int, std::string>>& calib,
                               const std::string& path, const std::string& key, size_t count) {
  const auto it = calib.find(key);
  if (it == calib.end()) {
    Fail(path + ": no '" + key + ":' entry (is this the right calibration file?)");
  }
  return ParseNumbers(it->second.second, count, path, it->second.first, key);
}

struct Projection {
  double fx, fy, cx, cy;
  Eigen::Vector3d center;  // optical centre in the rectified reference (cam0) frame
};

// P = K [I | t] (rectified): checks the form, returns K and the centre c = -t.
Projection DecomposeProjection(const std::vector<double>& p, const std::string& path,
                               const std::string& key) {
  const double fx = p[0], fy = p[5], cx = p[2], cy = p[6];
  const bool form = std::abs(p[1]) < 1e-9 && std::abs(p[4]) < 1e-9 && std::abs(p[8]) < 1e-9 &&
                    std::abs(p[9]) < 1e-9 && std::abs(p[10] - 1.0) < 1e-9;
  if (!form || !(fx > 0) || !(fy > 0)) {
    Fail(path + ": " + key +
         " is not a rectified projection matrix [fx 0 cx tx; 0 fy cy ty; 0 0 1 tz] with fx, "
         "fy > 0 (are the images rectified?)");
  }
  const double tz = p[11];
  const double ty = (p[7] - cy * tz) / fy;
  const double tx = (p[3] - cx * tz) / fx;
  return {fx, fy, cx, cy, Eigen::Vector3d(-tx, -ty, -tz)};
}

KittiCalibration CheckStereo(const Projection& l, const Projection& r, const std::string& path,
                             const std::string& lk, const std::string& rk) {
  auto same = [](double a, double b) {
    return std::abs(a - b) <= 1e-6 * std::max(1.0, std::abs(a));
  };
  if (!same(l.fx, r.fx) || !same(l.fy, r.fy) || !same(l.cx, r.cx) || !same(l.cy, r.cy)) {
    std::ostringstream ss;
    ss << path << ": inconsistent stereo calibration: " << lk << " has fx fy cx cy = " << l.fx
       << " " << l.fy << " " << l.cx << " " << l.cy << " but " << rk << " has " << r.fx << " "
       << r.fy << " " << r.cx << " " << r.cy
       << "; a rectified pair shares them (use the rectified P_rect/P matrices)";
    Fail(ss.str());
  }
  const Eigen::Vector3d d = r.center - l.center;
  if (!(d.x() > 0.01)) {
    std::ostringstream ss;
    ss << path << ": inconsistent stereo calibration: the right camera (" << rk
       << ") is not to the right of the left (" << lk << "): baseline " << d.x()
       << " m (left and right swapped?)";
    Fail(ss.str());
  }
  if (std::hypot(d.y(), d.z()) > 0.01 * d.x()) {
    std::ostringstream ss;
    ss << path << ": inconsistent stereo calibration: " << rk << " is offset by (" << d.y() << ", "
       << d.z() << ") m in y/z from " << lk << " (more than 1% of the baseline " << d.x()
       << " m); the pair is not row-rectified";
    Fail(ss.str());
  }
  KittiCalibration c;
  c.fx = l.fx;
  c.fy = l.fy;
  c.cx = l.cx;
  c.cy = l.cy;
  c.baseline = d.x();
  c.left_center_in_cam0 = l.center;
  return c;
}

// The nearest rotation to a printed 3x3 matrix (6 to 10 significant digits, so R^T R is
// only nearly I); an error naming `what` if it is not nearly a rotation at all.
Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& m, const std::string& what) {
  if ((m.transpose() * m - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3 ||
      m.determinant() < 0.0) {
    Fail(what + ": the 3x3 part is not a rotation (R^T R != I or det < 0)");
  }
  return fl::NearestRotation(m);
}

// "R: 9 numbers" + "T: 3 numbers" calibration file -> T_to_from.
Eigen::Isometry3d ReadRigidCalib(const std::string& path) {
  if (!IsFile(path)) Fail(path + ": missing (needed to convert OXTS to camera poses)");
  const auto calib = ReadCalibFile(path);
  const auto r = CalibValue(calib, path, "R", 9);
  const auto t = CalibValue(calib, path, "T", 3);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) T.linear()(i, j) = r[static_cast<size_t>(3 * i + j)];
    T.translation()(i) = t[static_cast<size_t>(i)];
  }
  T.linear() = NearestRotation(T.linear(), path + " (R)");
  return T;
}

// Checks that right images pair up with left images by file name.
void CheckPairs(const std::vector<std::string>& left, const std::vector<std::string>& right,
                const std::string& left_dir, const std::string& right_dir) {
  std::set<std::string> lnames, rnames;
  for (const auto& p : left) lnames.insert(fs::path(p).filename().string());
  for (const auto& p : right) rnames.insert(fs::path(p).filename().string());
  for (const auto& n : lnames) {
    if (!rnames.count(n)) {
      Fail(Join(right_dir, n) + ": missing right image (the left image " + Join(left_dir, n) +
           " has no partner; " + std::to_string(left.size()) + " left vs " +
           std::to_string(right.size()) + " right images)");
    }
  }
  for (const auto& n : rnames) {
    if (!lnames.count(n)) {
      Fail(Join(left_dir, n) + ": missing left image (the right image " + Join(right_dir, n) +
           " has no partner; " + std::to_string(left.size()) + " left vs " +
           std::to_string(right.size()) + " right images)");
    }
  }
}

// Reads an 8-bit image as gray; checks its size.
cv::Mat ReadGray(const std::string& path, int width, int height) {
  cv::Mat img = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (img.empty()) Fail(path + ": cannot read image (missing, unreadable or not a PNG)");
  if (img.depth() != CV_8U) {
    Fail(path + ": image is not 8-bit (depth code " + std::to_string(img.depth()) +
         "); KITTI stereo images are 8-bit gray or colour");
  }
  if (img.channels() == 3) {
    cv::Mat g;
    cv::cvtColor(img, g, cv::COLOR_BGR2GRAY);
    img = g;
  } else if (img.channels() == 4) {
    cv::Mat g;
    cv::cvtColor(img, g, cv::COLOR_BGRA2GRAY);
    img = g;
  } else if (img.channels() != 1) {
    Fail(path + ": image has " + std::to_string(img.channels()) + " channels");
  }
  if (img.cols != width || img.rows != height) {
    Fail(path + ": image is " + std::to_string(img.cols) + "x" + std::to_string(img.rows) +
         " but the calibration says " + std::to_string(width) + "x" + std::to_string(height) +
         " (wrong calibration file, or unrectified images?)");
  }
  if (!img.isContinuous()) img = img.clone();
  return img;
}

bot_core::image_t MakeImage(const cv::Mat& gray, Utime utime) {
  bot_core::image_t im{};
  im.utime = utime;
  im.width = gray.cols;
  im.height = gray.rows;
  im.row_stride = gray.cols;
  const int32_t gray_format = bot_core::image_t::PIXEL_FORMAT_GRAY;
  im.pixelformat = gray_format;
  im.size = gray.cols * gray.rows;
  im.data.assign(gray.data, gray.data + im.size);
  im.nmetadata = 0;
  return im;
}

}  // namespace

Status KittiOptions::Validate() const {
  if (start_frame < 0) return Status::Error("start_frame must be >= 0");
  if (max_frames == 0 || max_frames < -1) {
    return Status::Error("max_frames must be -1 (all) or > 0, not " + std::to_string(max_frames));
  }
  if (cameras != "auto" && cameras != "gray" && cameras != "color") {
    return Status::Error("cameras = '" + cameras + "' must be auto, gray or color");
  }
  if (!(calibration_period_s >= 0.0) || !std::isfinite(calibration_period_s)) {
    return Status::Error("calibration_period_s must be >= 0 s");
  }
  return Status::Ok();
}

Eigen::Matrix3d RotationBaseCamera() {
  Eigen::Matrix3d r;
  // base x = camera z, base y = -camera x, base z = -camera y.
  r << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return r;
}

bool ParseKittiTimestamp(const std::string& text, Utime* utime) {
  int Y, M, D, h, m;
  char frac[32] = {0};
  int sec = 0;
  int consumed = 0;
  if (std::sscanf(text.c_str(), "%4d-%2d-%2d %2d:%2d:%2d%n", &Y, &M, &D, &h, &m, &sec, &consumed) !=
      6) {
    return false;
  }
  std::string rest = text.substr(static_cast<size_t>(consumed));
  int64_t micros = 0;
  if (!rest.empty()) {
    if (rest[0] != '.' || rest.size() < 2 || rest.size() > 20) return false;
    std::snprintf(frac, sizeof(frac), "%s", rest.c_str() + 1);
    // Round the fraction to microseconds.
    double f = 0.0, scale = 0.1;
    for (const char* c = frac; *c; ++c) {
      if (!std::isdigit(static_cast<unsigned char>(*c))) return false;
      f += (*c - '0') * scale;
      scale *= 0.1;
    }
    micros = static_cast<int64_t>(std::llround(f * 1e6));
  }
  if (M < 1 || M > 12 || D < 1 || D > 31 || h > 23 || m > 59 || sec > 60) return false;
  std::tm tm{};
  tm.tm_year = Y - 1900;
  tm.tm_mon = M - 1;
  tm.tm_mday = D;
  tm.tm_hour = h;
  tm.tm_min = m;
  tm.tm_sec = sec;
  const time_t t = timegm(&tm);
  *utime = static_cast<Utime>(t) * kUtimePerSecond + micros;
  return true;
}

std::vector<Eigen::Isometry3d> PosesFromOxts(const std::string& folder) {
  const std::string dir = Join(folder, "oxts/data");
  if (!IsDir(dir)) Fail(dir + ": folder missing (no OXTS records)");
  std::vector<std::string> files;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->path().extension() == ".txt") files.push_back(it->path().string());
  }
  if (ec) Fail(dir + ": cannot list folder: " + ec.message());
  std::sort(files.begin(), files.end());
  if (files.empty()) Fail(dir + ": no .txt OXTS records (empty folder)");
  const Eigen::Isometry3d T_velo_imu = ReadRigidCalib(Join(folder, "calib_imu_to_velo.txt"));
  const Eigen::Isometry3d T_cam0_velo = ReadRigidCalib(Join(folder, "calib_velo_to_cam.txt"));
  // The images are rectified: express the poses in the rectified cam0 frame (R_rect_00).
  const std::string cpath = Join(folder, "calib_cam_to_cam.txt");
  const auto rr = CalibValue(ReadCalibFile(cpath), cpath, "R_rect_00", 9);
  Eigen::Isometry3d T_rect0_cam0 = Eigen::Isometry3d::Identity();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) T_rect0_cam0.linear()(i, j) = rr[static_cast<size_t>(3 * i + j)];
  }
  T_rect0_cam0.linear() = NearestRotation(T_rect0_cam0.linear(), cpath + " (R_rect_00)");
  const Eigen::Isometry3d T_cam0_imu = T_rect0_cam0 * T_cam0_velo * T_velo_imu;
  constexpr double kEarthRadius = 6378137.0;  // [m] WGS84 equatorial radius, as the devkit
  double scale = 0.0;
  Eigen::Isometry3d T_imu0_world = Eigen::Isometry3d::Identity();
  std::vector<Eigen::Isometry3d> out;
  for (size_t i = 0; i < files.size(); ++i) {
    const auto lines = ReadLines(files[i]);
    if (lines.empty()) Fail(files[i] + ": empty OXTS record");
    const auto v = ParseNumbers(lines[0].second, 30, files[i], lines[0].first,
                                "OXTS record (lat lon alt roll pitch yaw ...)");
    const double lat = v[0], lon = v[1], alt = v[2];
    if (std::abs(lat) > 85.0 || std::abs(lon) > 180.0) {
      Fail(files[i] + ":" + std::to_string(lines[0].first) + ": latitude " + std::to_string(lat) +
           " / longitude " + std::to_string(lon) + " out of range");
    }
    if (i == 0) scale = std::cos(lat * M_PI / 180.0);
    // Mercator projection with the first frame's scale (KITTI devkit convertOxtsToPose).
    const Eigen::Vector3d t(scale * lon * M_PI * kEarthRadius / 180.0,
                            scale * kEarthRadius * std::log(std::tan((90.0 + lat) * M_PI / 360.0)),
                            alt);
    Eigen::Isometry3d T_world_imu = Eigen::Isometry3d::Identity();
    T_world_imu.linear() = RotationFromRollPitchYaw(v[3], v[4], v[5]);
    T_world_imu.translation() = t;
    if (i == 0) T_imu0_world = T_world_imu.inverse();
    out.push_back(T_cam0_imu * (T_imu0_world * T_world_imu) * T_cam0_imu.inverse());
  }
  return out;
}

KittiCalibration ParseKittiCalibration(const std::string& text, const std::string& name,
                                       bool raw_layout, bool color) {
  const auto calib = ParseCalibText(text, name);
  if (raw_layout) {
    const auto s0 = CalibValue(calib, name, "S_rect_00", 2);
    const auto s1 = CalibValue(calib, name, "S_rect_01", 2);
    if (s0 != s1) {
      Fail(name + ": inconsistent stereo calibration: S_rect_00 (" + std::to_string(s0[0]) + "x" +
           std::to_string(s0[1]) + ") and S_rect_01 (" + std::to_string(s1[0]) + "x" +
           std::to_string(s1[1]) + ") differ; rectified images share one size");
    }
    if (!(s0[0] >= 1 && s0[0] <= 100000 && s0[1] >= 1 && s0[1] <= 100000) ||
        s0[0] != std::floor(s0[0]) || s0[1] != std::floor(s0[1])) {
      Fail(name + ": S_rect_00 is not a positive integer image size (at most 100000 px)");
    }
    const Projection l =
        DecomposeProjection(CalibValue(calib, name, "P_rect_00", 12), name, "P_rect_00");
    const Projection r =
        DecomposeProjection(CalibValue(calib, name, "P_rect_01", 12), name, "P_rect_01");
    KittiCalibration c = CheckStereo(l, r, name, "P_rect_00", "P_rect_01");
    c.width = static_cast<int>(s0[0]);
    c.height = static_cast<int>(s0[1]);
    return c;
  }
  const std::string lk = color ? "P2" : "P0", rk = color ? "P3" : "P1";
  const Projection l = DecomposeProjection(CalibValue(calib, name, lk, 12), name, lk);
  const Projection r = DecomposeProjection(CalibValue(calib, name, rk, 12), name, rk);
  return CheckStereo(l, r, name, lk, rk);
}

std::vector<Utime> ParseKittiTimes(const std::string& text, const std::string& name) {
  std::vector<Utime> out;
  for (const auto& [n, line] : SplitLines(text)) {
    const double s = ParseNumbers(line, 1, name, n, "time [s]")[0];
    if (s < 0 || s > 1e9) {
      Fail(name + ":" + std::to_string(n) + ": time " + line + " s is not in [0, 1e9]");
    }
    out.push_back(kKittiOdometryEpochUtime + SecondsToUtime(s));
  }
  return out;
}

std::vector<Utime> ParseKittiTimestamps(const std::string& text, const std::string& name) {
  std::vector<Utime> out;
  for (const auto& [n, line] : SplitLines(text)) {
    Utime t = 0;
    if (!ParseKittiTimestamp(line, &t)) {
      Fail(name + ":" + std::to_string(n) + ": '" + line.substr(0, 80) +
           "' is not a time stamp 'YYYY-MM-DD HH:MM:SS.fraction'");
    }
    out.push_back(t);
  }
  return out;
}

VelodyneScan ReadVelodyneBin(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) Fail(path + ": cannot open Velodyne scan (missing or unreadable)");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  in.seekg(0, std::ios::beg);
  if (size < 0) Fail(path + ": cannot read the size of the Velodyne scan");
  if (size % 16 != 0) {
    Fail(path + ": " + std::to_string(size) +
         " bytes is not a multiple of 16 (a KITTI Velodyne scan is N x 4 float32: x, y, z, "
         "reflectance); truncated or not a Velodyne .bin file");
  }
  const size_t n = static_cast<size_t>(size / 16);
  std::vector<float> raw(4 * n);
  if (n > 0 && !in.read(reinterpret_cast<char*>(raw.data()), size)) {
    Fail(path + ": read error after " + std::to_string(in.gcount()) + " of " +
         std::to_string(size) + " bytes");
  }
  VelodyneScan scan;
  scan.points.reserve(n);
  scan.intensities.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const float* p = &raw[4 * i];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]) ||
        !std::isfinite(p[3])) {
      ++scan.dropped_non_finite;
      continue;
    }
    scan.points.emplace_back(p[0], p[1], p[2]);
    scan.intensities.push_back(p[3]);
  }
  return scan;
}

Eigen::Isometry3d ParseKittiVelodyneToCamera(const std::string& text, const std::string& name) {
  const auto calib = ParseCalibText(text, name);
  if (!calib.count("Tr")) {
    Fail(name +
         ": no 'Tr:' entry (the Velodyne -> camera 0 transform, 12 numbers, needed with "
         "velodyne/ scans; use the calib.txt of the odometry sequence's data_odometry_calib)");
  }
  const auto v = CalibValue(calib, name, "Tr", 12);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) T.linear()(r, c) = v[static_cast<size_t>(4 * r + c)];
    T.translation()(r) = v[static_cast<size_t>(4 * r + 3)];
  }
  T.linear() = NearestRotation(T.linear(), name + " (Tr)");
  return T;
}

std::vector<Eigen::Isometry3d> ParseKittiPoses(const std::string& text, const std::string& name) {
  std::vector<Eigen::Isometry3d> out;
  for (const auto& [n, line] : SplitLines(text)) {
    const std::vector<double> v = ParseNumbers(line, 12, name, n, "pose (3x4 row-major)");
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) t.linear()(r, c) = v[static_cast<size_t>(4 * r + c)];
      t.translation()(r) = v[static_cast<size_t>(4 * r + 3)];
    }
    t.linear() = NearestRotation(t.linear(), name + ":" + std::to_string(n));
    out.push_back(t);
  }
  if (out.empty()) Fail(name + ": pose file is empty");
  return out;
}

KittiSequence ScanKittiFolder(const KittiOptions& options, const std::string& folder) {
  const Status valid = options.Validate();
  if (!valid.ok()) throw std::invalid_argument("KITTI options: " + valid.message());
  if (!IsDir(folder))
    Fail(folder + ": no such folder (give a KITTI raw drive or odometry sequence)");
  KittiSequence seq;
  seq.folder = folder;
  const bool raw = IsDir(Join(folder, "image_00"));
  const bool odo_gray = IsDir(Join(folder, "image_0"));
  const bool odo_color = IsDir(Join(folder, "image_2"));
  if (!raw && !odo_gray && !odo_color) {
    Fail(folder +
         ": not a KITTI folder: found neither image_00/ (raw drive) nor image_0/ or "
         "image_2/ (odometry sequence)");
  }
  seq.raw_layout = raw;
  std::string left_dir, right_dir;
  int width = 0, height = 0;
  if (raw) {
    left_dir = Join(folder, "image_00/data");
    right_dir = Join(folder, "image_01/data");
    const std::string cpath = Join(folder, "calib_cam_to_cam.txt");
    if (!IsFile(cpath)) Fail(cpath + ": missing (the raw drive's calibration is needed)");
    seq.calibration = ParseKittiCalibration(ReadText(cpath), cpath, true, false);
    width = seq.calibration.width;
    height = seq.calibration.height;
  } else {
    bool color = options.cameras == "color" || (options.cameras == "auto" && !odo_gray);
    if (options.cameras == "gray" && !odo_gray)
      Fail(Join(folder, "image_0") + ": folder missing (cameras: gray)");
    if (color && !odo_color) Fail(Join(folder, "image_2") + ": folder missing (cameras: color)");
    left_dir = Join(folder, color ? "image_2" : "image_0");
    right_dir = Join(folder, color ? "image_3" : "image_1");
    const std::string cpath = Join(folder, "calib.txt");
    if (!IsFile(cpath))
      Fail(cpath + ": missing (the sequence's calibration with P0..P3 is needed)");
    seq.calibration = ParseKittiCalibration(ReadText(cpath), cpath, false, color);
  }
  seq.left_images = ListPngs(left_dir);
  seq.right_images = ListPngs(right_dir);
  if (seq.left_images.empty()) Fail(left_dir + ": no .png images (empty folder)");
  if (seq.right_images.empty()) Fail(right_dir + ": no .png images (empty folder)");
  CheckPairs(seq.left_images, seq.right_images, left_dir, right_dir);
  const size_t frames = seq.left_images.size();

  // Time stamps: one per image; a longer file (images trimmed, times.txt not) gives its
  // first `frames` entries, with a warning.
  const auto use_first = [&](std::vector<Utime> all, const std::string& path) {
    if (all.size() < frames) {
      Fail(path + ": " + std::to_string(all.size()) + " time stamps for " +
           std::to_string(frames) + " images in " + left_dir + " (one line per image needed)");
    }
    if (all.size() > frames) {
      seq.warnings.push_back(path + ": " + std::to_string(all.size()) + " time stamps for " +
                             std::to_string(frames) + " images in " + left_dir +
                             "; using the first " + std::to_string(frames));
      FL_LOG(WARN) << seq.warnings.back();
      all.resize(frames);
    }
    return all;
  };
  if (raw) {
    const std::string tpath = Join(folder, "image_00/timestamps.txt");
    seq.utimes = use_first(ParseKittiTimestamps(ReadText(tpath), tpath), tpath);
    const std::string rpath = Join(folder, "image_01/timestamps.txt");
    if (IsFile(rpath)) {
      const size_t n = ParseKittiTimestamps(ReadText(rpath), rpath).size();
      if (n < seq.right_images.size()) {
        Fail(rpath + ": " + std::to_string(n) + " time stamps for " +
             std::to_string(seq.right_images.size()) + " images in " + right_dir);
      }
    }
  } else {
    const std::string tpath = Join(folder, "times.txt");
    seq.utimes = use_first(ParseKittiTimes(ReadText(tpath), tpath), tpath);
    // The size comes from the first left image (calib.txt has none); every image is checked.
    const cv::Mat first = cv::imread(seq.left_images[0], cv::IMREAD_UNCHANGED);
    if (first.empty())
      Fail(seq.left_images[0] + ": cannot read image (missing, unreadable or not a PNG)");
    width = first.cols;
    height = first.rows;
  }
  seq.calibration.width = width;
  seq.calibration.height = height;

  // Ground truth.
  std::string ppath = options.poses_file;
  if (ppath.empty() && IsFile(Join(folder, "poses_cam0_from_oxts.txt"))) {
    ppath = Join(folder, "poses_cam0_from_oxts.txt");
  }
  // An odometry sequence copied with its poses/NN.txt beside the images (as the shared
  // lidar_stereo snippet is): the folder's own poses.txt.
  if (ppath.empty() && !raw && IsFile(Join(folder, "poses.txt"))) {
    ppath = Join(folder, "poses.txt");
  }
  if (!ppath.empty()) {
    if (!IsFile(ppath)) Fail(ppath + ": pose file missing (check --poses)");
    seq.T_cam0start_cam0 = ParseKittiPoses(ReadText(ppath), ppath);
    if (seq.T_cam0start_cam0.size() > frames) {
      seq.warnings.push_back(ppath + ": " + std::to_string(seq.T_cam0start_cam0.size()) +
                             " poses for " + std::to_string(frames) + " frames in " + folder +
                             "; using the first " + std::to_string(frames));
      FL_LOG(WARN) << seq.warnings.back();
      seq.T_cam0start_cam0.resize(frames);
    }
    if (seq.T_cam0start_cam0.size() != frames) {
      Fail(ppath + ": " + std::to_string(seq.T_cam0start_cam0.size()) + " poses for " +
           std::to_string(frames) + " frames in " + folder +
           " (the pose file must have one line per frame; wrong sequence?)");
    }
    seq.poses_path = ppath;
  } else if (raw && IsDir(Join(folder, "oxts"))) {
    seq.T_cam0start_cam0 = PosesFromOxts(folder);
    if (seq.T_cam0start_cam0.size() != frames) {
      Fail(Join(folder, "oxts/data") + ": " + std::to_string(seq.T_cam0start_cam0.size()) +
           " OXTS records for " + std::to_string(frames) +
           " frames (one per frame needed; give --poses FILE instead)");
    }
    seq.poses_path = Join(folder, "oxts");
  } else if (!options.allow_no_ground_truth) {
    Fail(folder +
         ": no ground truth: neither poses_cam0_from_oxts.txt, poses.txt nor oxts/ here; give "
         "--poses FILE (12 numbers a line, e.g. KITTI odometry poses/NN.txt) or "
         "--no-ground-truth");
  }
  // Velodyne scans (optional): one per image, with the transform to camera 0.
  const std::string vdir = Join(folder, raw ? "velodyne_points/data" : "velodyne");
  if (IsDir(vdir)) {
    seq.velodyne_scans = ListFiles(vdir, ".bin");
    if (seq.velodyne_scans.size() < frames) {
      Fail(vdir + ": " + std::to_string(seq.velodyne_scans.size()) + " .bin scans for " +
           std::to_string(frames) + " images in " + left_dir +
           " (one scan per image needed; remove the folder to convert without laser)");
    }
    seq.velodyne_scans.resize(frames);
    if (raw) {
      const std::string cpath = Join(folder, "calib_cam_to_cam.txt");
      const auto rr = CalibValue(ReadCalibFile(cpath), cpath, "R_rect_00", 9);
      Eigen::Isometry3d T_rect0_cam0 = Eigen::Isometry3d::Identity();
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j)
          T_rect0_cam0.linear()(i, j) = rr[static_cast<size_t>(3 * i + j)];
      }
      T_rect0_cam0.linear() = NearestRotation(T_rect0_cam0.linear(), cpath + " (R_rect_00)");
      seq.T_cam0_velo = T_rect0_cam0 * ReadRigidCalib(Join(folder, "calib_velo_to_cam.txt"));
    } else {
      const std::string cpath = Join(folder, "calib.txt");
      seq.T_cam0_velo = ParseKittiVelodyneToCamera(ReadText(cpath), cpath);
    }
  }
  if (static_cast<size_t>(options.start_frame) >= frames) {
    Fail(folder + ": start_frame " + std::to_string(options.start_frame) + " but the folder has " +
         std::to_string(frames) + " frames");
  }
  return seq;
}

ConvertSummary ConvertKitti(const KittiOptions& options, const std::string& folder,
                            const std::string& out_log) {
  const KittiSequence seq = ScanKittiFolder(options, folder);
  const size_t begin = static_cast<size_t>(options.start_frame);
  size_t end = seq.left_images.size();
  if (options.max_frames > 0) end = std::min(end, begin + static_cast<size_t>(options.max_frames));

  ConvertSummary summary;
  summary.input = folder;
  summary.output = out_log;
  summary.warnings = seq.warnings;
  const KittiCalibration& c = seq.calibration;
  const Eigen::Matrix3d R_bc = RotationBaseCamera();

  fusionloc::stereo_calibration_t cal{};
  cal.width = c.width;
  cal.height = c.height;
  cal.fx = c.fx;
  cal.fy = c.fy;
  cal.cx = c.cx;
  cal.cy = c.cy;
  cal.baseline = c.baseline;
  cal.rectified = true;
  // The mounting, from the drive's own calibration: the base frame is cam0's, with base axes.
  bot_core::rigid_transform_t camera_to_base{};
  {
    Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();
    T_base_camera.linear() = R_bc;
    T_base_camera.translation() = R_bc * c.left_center_in_cam0;
    IsometryToArrays(T_base_camera, camera_to_base.trans, camera_to_base.quat);
  }

  // The Velodyne's mounting: base = cam0 with base axes, so T_base_velo = [R_bc | 0] * Tr.
  const bool laser_3d = options.laser_3d && !seq.velodyne_scans.empty();
  bot_core::rigid_transform_t laser_3d_to_base{};
  {
    Eigen::Isometry3d T_base_cam0 = Eigen::Isometry3d::Identity();
    T_base_cam0.linear() = R_bc;
    IsometryToArrays(T_base_cam0 * seq.T_cam0_velo, laser_3d_to_base.trans,
                     laser_3d_to_base.quat);
  }

  int64_t backwards = 0;
  for (size_t i = begin + 1; i < end; ++i) {
    if (seq.utimes[i] <= seq.utimes[i - 1]) ++backwards;
  }
  if (backwards > 0) {
    summary.warnings.push_back(std::to_string(backwards) +
                               " frames have a time stamp not after the frame before; kept in "
                               "frame order");
  }
  if (seq.T_cam0start_cam0.empty()) {
    summary.warnings.push_back("no ground truth: GROUND_TRUTH not written");
  } else if (fs::path(seq.poses_path).filename() == "oxts") {
    summary.notes.push_back("ground truth computed from " + seq.poses_path +
                            " (KITTI devkit OXTS-to-pose method; no pose file given)");
  }

  LcmLogWriter writer(out_log);
  try {
    auto write = [&](const char* channel, const auto& msg, Utime utime) {
      writer.Write(channel, msg, utime);
      summary.Count(channel, utime);
    };
    Eigen::Isometry3d T_cam0_start_inv = Eigen::Isometry3d::Identity();
    if (!seq.T_cam0start_cam0.empty()) T_cam0_start_inv = seq.T_cam0start_cam0[begin].inverse();
    Utime last_cal = 0;
    bool cal_written = false;
    const Utime cal_period = SecondsToUtime(options.calibration_period_s);
    bot_core::images_t pair{};
    const int16_t kLeft = bot_core::images_t::LEFT, kRight = bot_core::images_t::RIGHT;
    for (size_t i = begin; i < end; ++i) {
      const Utime t = seq.utimes[i];
      if (!cal_written || (cal_period > 0 && t - last_cal >= cal_period)) {
        cal.utime = t;
        camera_to_base.utime = t;
        write(channels::kCameraToBase, camera_to_base, t);
        if (laser_3d) {
          laser_3d_to_base.utime = t;
          write(channels::kLaser3dToBase, laser_3d_to_base, t);
        }
        write(channels::kStereoCalibration, cal, t);
        last_cal = t;
        cal_written = true;
      }
      // The scan before its images: a subscriber (fl-stereo-vo --laser-aided) has it when the
      // frame arrives.
      if (laser_3d) {
        const VelodyneScan v = ReadVelodyneBin(seq.velodyne_scans[i]);
        if (v.dropped_non_finite > 0) {
          summary.warnings.push_back(seq.velodyne_scans[i] + ": " +
                                     std::to_string(v.dropped_non_finite) +
                                     " non-finite points dropped");
        }
        fusionloc::laser_scan_3d_t scan;
        scan.utime = t;
        scan.frame = "velodyne";
        scan.num_points = static_cast<int32_t>(v.points.size());
        scan.x.resize(v.points.size());
        scan.y.resize(v.points.size());
        scan.z.resize(v.points.size());
        scan.intensity = v.intensities;
        for (size_t k = 0; k < v.points.size(); ++k) {
          scan.x[k] = v.points[k].x();
          scan.y[k] = v.points[k].y();
          scan.z[k] = v.points[k].z();
        }
        write(channels::kLaser3d, scan, t);
      }
      const cv::Mat left = ReadGray(seq.left_images[i], c.width, c.height);
      const cv::Mat right = ReadGray(seq.right_images[i], c.width, c.height);
      pair.utime = t;
      pair.n_images = 2;
      pair.image_types = {kLeft, kRight};
      pair.images = {MakeImage(left, t), MakeImage(right, t)};
      write(channels::kStereo, pair, t);
      if (!seq.T_cam0start_cam0.empty()) {
        Eigen::Isometry3d T_c0_ci = T_cam0_start_inv * seq.T_cam0start_cam0[i];
        Eigen::Isometry3d T_world_base = Eigen::Isometry3d::Identity();
        T_world_base.linear() = R_bc * T_c0_ci.linear() * R_bc.transpose();
        T_world_base.translation() = R_bc * T_c0_ci.translation();
        bot_core::pose_t gt{};
        gt.utime = t;
        IsometryToArrays(T_world_base, gt.pos, gt.orientation);
        write(channels::kGroundTruth, gt, t);
      }
    }
    writer.Close();
  } catch (...) {
    writer.Abandon();
    throw;
  }
  return summary;
}

}  // namespace fl::importers
