// Small synthetic inputs for the importer tests: CARMEN log text and tiny KITTI folders, plus a
// reader that loads an LCM log back into per-channel lists.
#pragma once

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "fusionloc/common/lcm_interface.hpp"

namespace fl::test {

inline void WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// One FLASER line with `n` beams, all of range `r`, at pose (x, y, th) = odom, time t.
inline std::string CarmenFlaser(int n, double r, double x, double y, double th, double t, double ox,
                                double oy, double oth) {
  std::ostringstream ss;
  ss.precision(10);
  ss << "FLASER " << n;
  for (int i = 0; i < n; ++i) ss << " " << r + 0.01 * (i % 7);
  ss << " " << x << " " << y << " " << th << " " << ox << " " << oy << " " << oth << " " << t
     << " testhost " << t + 0.001 << "\n";
  return ss.str();
}
inline std::string CarmenFlaser(int n, double r, double x, double y, double th, double t) {
  return CarmenFlaser(n, r, x, y, th, t, x, y, th);
}

// A small log: `scans` FLASER lines driving along a gentle arc at 10 Hz.
inline std::string CarmenArcLog(int scans, int beams = 181, double step_m = 0.1,
                                double turn_rad = 0.02) {
  std::string text = "# synthetic CARMEN log\nPARAM robot_front_laser_max 81.9 nohost 0\n";
  double x = 0, y = 0, th = 0;
  for (int k = 0; k < scans; ++k) {
    text += CarmenFlaser(beams, 2.0 + 0.001 * k, x, y, th, 100.0 + 0.1 * k);
    x += step_m * std::cos(th);
    y += step_m * std::sin(th);
    th += turn_rad;
  }
  return text;
}

// Events of an LCM log, by channel (raw bytes and log utimes).
struct LogContents {
  std::map<std::string, std::vector<std::vector<uint8_t>>> data;
  std::map<std::string, std::vector<Utime>> utimes;
  std::vector<std::string> channel_order;  // channel of each event, in log order
  size_t count(const std::string& channel) const {
    const auto it = data.find(channel);
    return it == data.end() ? 0 : it->second.size();
  }
  // Position in the log of the n-th event on `channel` (npos if there is none).
  size_t IndexOf(const std::string& channel, size_t n) const {
    for (size_t i = 0; i < channel_order.size(); ++i) {
      if (channel_order[i] == channel && n-- == 0) return i;
    }
    return std::string::npos;
  }
  template <class Msg>
  Msg Decode(const std::string& channel, size_t i) const {
    Msg msg;
    const auto& bytes = data.at(channel).at(i);
    const int size = static_cast<int>(bytes.size());
    if (msg.decode(bytes.data(), 0, size) != size) {
      throw std::runtime_error("test: message " + std::to_string(i) + " on " + channel +
                               " does not decode as " + Msg::getTypeName());
    }
    return msg;
  }
};

inline LogContents ReadLog(const std::string& path) {
  LogContents c;
  LcmLogReader reader(path);
  LcmLogEvent e;
  while (reader.Next(&e)) {
    c.data[e.channel].push_back(e.data);
    c.utimes[e.channel].push_back(e.utime);
    c.channel_order.push_back(e.channel);
  }
  return c;
}

inline std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// A tiny KITTI raw drive: `frames` gray stereo pairs of w x h pixels, 10 Hz time stamps,
// calib_cam_to_cam.txt (fx = 100, cx = w/2, cy = h/2, baseline 0.5 m) and a pose file in
// which the left camera moves 1 m forward (optical +z) per frame.
struct KittiRawFixture {
  int frames = 3;
  int width = 16;
  int height = 8;
  double fx = 100.0;
  double right_fx = 100.0;  // set != fx to make the calibration inconsistent
  bool write_poses = true;
  // OXTS records (oxts/data/*.txt) in which the vehicle drives 1 m east per frame at latitude
  // 49 deg, heading east, plus calib_imu_to_velo.txt (identity) and calib_velo_to_cam.txt
  // (velo x forward -> camera z forward), so the base moves +1 m along x per frame.
  bool write_oxts = false;

  void Write(const std::string& root) const {
    namespace fs = std::filesystem;
    fs::create_directories(root + "/image_00/data");
    fs::create_directories(root + "/image_01/data");
    std::ostringstream ts, poses;
    for (int i = 0; i < frames; ++i) {
      char name[32];
      std::snprintf(name, sizeof(name), "%010d.png", i);
      cv::Mat left(height, width, CV_8UC1), right(height, width, CV_8UC1);
      for (int r = 0; r < height; ++r) {
        for (int c = 0; c < width; ++c) {
          left.at<uint8_t>(r, c) = static_cast<uint8_t>((r * width + c + i) & 0xff);
          right.at<uint8_t>(r, c) = static_cast<uint8_t>((r * width + c + 2 * i + 1) & 0xff);
        }
      }
      cv::imwrite(root + "/image_00/data/" + name, left);
      cv::imwrite(root + "/image_01/data/" + name, right);
      char t[64];
      std::snprintf(t, sizeof(t), "2011-09-26 13:02:25.%09d\n", 100000000 * i + 5);
      ts << t;
      poses << "1 0 0 0 0 1 0 0 0 0 1 " << i << "\n";
    }
    WriteText(root + "/image_00/timestamps.txt", ts.str());
    WriteText(root + "/image_01/timestamps.txt", ts.str());
    if (write_poses) WriteText(root + "/poses_cam0_from_oxts.txt", poses.str());
    std::ostringstream calib;
    calib << "calib_time: 09-Jan-2012 13:57:47\n";
    calib << "S_rect_00: " << width << " " << height << "\n";
    calib << "P_rect_00: " << fx << " 0 " << width / 2.0 << " 0 0 " << fx << " " << height / 2.0
          << " 0 0 0 1 0\n";
    calib << "S_rect_01: " << width << " " << height << "\n";
    calib << "P_rect_01: " << right_fx << " 0 " << width / 2.0 << " " << -0.5 * right_fx << " 0 "
          << right_fx << " " << height / 2.0 << " 0 0 0 1 0\n";
    calib << "R_rect_00: 1 0 0 0 1 0 0 0 1\n";
    WriteText(root + "/calib_cam_to_cam.txt", calib.str());
    if (write_oxts) {
      fs::create_directories(root + "/oxts/data");
      const double lat = 49.0, lon0 = 8.4;
      const double metre_in_deg = 180.0 / (M_PI * 6378137.0 * std::cos(lat * M_PI / 180.0));
      for (int i = 0; i < frames; ++i) {
        char name[32];
        std::snprintf(name, sizeof(name), "%010d.txt", i);
        std::ostringstream rec;
        rec.precision(17);
        rec << lat << " " << lon0 + i * metre_in_deg << " 116.0 0 0 0";
        for (int k = 6; k < 30; ++k) rec << " 0";
        WriteText(root + "/oxts/data/" + name, rec.str() + "\n");
      }
      WriteText(root + "/calib_imu_to_velo.txt", "R: 1 0 0 0 1 0 0 0 1\nT: 0 0 0\n");
      WriteText(root + "/calib_velo_to_cam.txt", "R: 0 -1 0 0 0 -1 1 0 0\nT: 0 0 0\n");
    }
  }
};

}  // namespace fl::test
