// Tests of the LCM adapters (image decoding, message conversion) and of the fl-stereo-vo
// process replaying a log: calibration handling, outputs, status on bad input.
#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

#include <gtest/gtest.h>

#include <functional>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "stereo_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::vo {
namespace {

// The value of `key` in a status message; NaN when absent.
double StatusValue(const fusionloc::status_t& s, const std::string& key) {
  for (int k = 0; k < s.num_keys; ++k) {
    if (s.keys[static_cast<size_t>(k)] == key) return s.values[static_cast<size_t>(k)];
  }
  return std::numeric_limits<double>::quiet_NaN();
}

bot_core::image_t MakeImage(const cv::Mat& gray, int stride_pad = 0) {
  bot_core::image_t im{};
  im.width = gray.cols;
  im.height = gray.rows;
  im.row_stride = gray.cols + stride_pad;
  im.pixelformat = bot_core::image_t::PIXEL_FORMAT_GRAY;
  im.data.assign(static_cast<size_t>(im.row_stride) * gray.rows, 0);
  for (int r = 0; r < gray.rows; ++r) {
    std::copy(gray.ptr<uint8_t>(r), gray.ptr<uint8_t>(r) + gray.cols,
              im.data.begin() + static_cast<long>(r) * im.row_stride);
  }
  im.size = static_cast<int32_t>(im.data.size());
  return im;
}

bot_core::images_t MakeStereo(int64_t utime, const cv::Mat& l, const cv::Mat& r) {
  bot_core::images_t m{};
  m.utime = utime;
  m.n_images = 2;
  m.image_types = {bot_core::images_t::LEFT, bot_core::images_t::RIGHT};
  m.images = {MakeImage(l), MakeImage(r)};
  m.images[0].utime = m.images[1].utime = utime;
  return m;
}

fusionloc::stereo_calibration_t MakeCalibration(const StereoCalibration& c, bool rectified) {
  fusionloc::stereo_calibration_t m{};
  m.width = c.width;
  m.height = c.height;
  m.fx = c.fx;
  m.fy = c.fy;
  m.cx = c.cx;
  m.cy = c.cy;
  m.baseline = c.baseline;
  m.rectified = rectified;
  return m;
}

bot_core::rigid_transform_t MakeCameraToBase(const StereoCalibration& c) {
  bot_core::rigid_transform_t m{};
  fl::IsometryToArrays(c.T_base_camera, m.trans, m.quat);
  return m;
}

TEST(StereoVoLcm, ImageConversions) {
  cv::Mat gray(4, 5, CV_8UC1);
  for (int i = 0; i < 20; ++i) gray.data[i] = static_cast<uint8_t>(i * 10);
  cv::Mat out;
  ASSERT_TRUE(ImageToGray(MakeImage(gray, 3), &out).ok());
  EXPECT_EQ(cv::norm(out, gray, cv::NORM_INF), 0.0) << "row stride honoured";
  // RGB is converted to gray.
  bot_core::image_t rgb{};
  rgb.width = 2;
  rgb.height = 1;
  rgb.row_stride = 6;
  rgb.pixelformat = bot_core::image_t::PIXEL_FORMAT_RGB;
  rgb.data = {255, 0, 0, 0, 0, 255};
  rgb.size = 6;
  ASSERT_TRUE(ImageToGray(rgb, &out).ok());
  EXPECT_GT(out.at<uint8_t>(0, 0), out.at<uint8_t>(0, 1)) << "red is brighter than blue";
  // Errors name the problem.
  bot_core::image_t bad = MakeImage(gray);
  bad.pixelformat = bot_core::image_t::PIXEL_FORMAT_MJPEG;
  EXPECT_NE(ImageToGray(bad, &out).message().find("unsupported pixel format"), std::string::npos);
  bad = MakeImage(gray);
  bad.data.resize(10);
  bad.size = 10;
  EXPECT_NE(ImageToGray(bad, &out).message().find("bytes"), std::string::npos);
  bad = MakeImage(gray);
  bad.row_stride = 2;
  EXPECT_NE(ImageToGray(bad, &out).message().find("row_stride"), std::string::npos);
  bot_core::images_t one = MakeStereo(1, gray, gray);
  one.n_images = 1;
  one.image_types.resize(1);
  one.images.resize(1);
  cv::Mat l, r;
  EXPECT_NE(StereoImagesToGray(one, &l, &r).message().find("RIGHT"), std::string::npos);
}

TEST(StereoVoLcm, FactorAndCalibrationConversions) {
  KeyframeFactor f;
  f.utime_i = 10;
  f.utime_j = 20;
  f.keyframe_id_i = 3;
  f.keyframe_id_j = 4;
  f.T_i_j.translation() = Eigen::Vector3d(1, 2, 3);
  f.information = Eigen::Matrix<double, 6, 6>::Identity() * 5;
  f.information(0, 5) = f.information(5, 0) = 0.5;
  const fusionloc::relative_pose_factor_t m = FactorToLcm(f);
  const int vision = fusionloc::relative_pose_factor_t::SOURCE_VISION;
  EXPECT_EQ(m.source, vision);
  EXPECT_EQ(m.utime_i, 10);
  EXPECT_EQ(m.keyframe_id_j, 4);
  EXPECT_EQ(m.trans[2], 3.0);
  EXPECT_EQ(m.quat[0], 1.0);
  EXPECT_EQ(m.information[5], 0.5);   // row 0, col 5
  EXPECT_EQ(m.information[30], 0.5);  // row 5, col 0
  const StereoCalibration c = fl::test::stereo::TestCalibration();
  const StereoCalibration back = CalibrationFromLcm(MakeCalibration(c, true), MakeCameraToBase(c));
  EXPECT_TRUE(back.T_base_camera.isApprox(c.T_base_camera, 1e-12));
  EXPECT_EQ(back.width, c.width);
  EXPECT_TRUE(back.Validate().ok());
  EXPECT_FALSE(CalibrationFromLcm(MakeCalibration(c, false), MakeCameraToBase(c)).Validate().ok());
}

// Replays a log through the real process: a frame before the mounting (CAMERA_TO_BASE) waits,
// an unrectified calibration is refused (status), the valid one is used, a wrong-size frame
// and a repeated time stamp are dropped, and the outputs appear on VO_POSE / VO_FACTORS /
// VO_POINTS.
TEST(StereoVoLcm, ProcessReplaysALog) {
  const std::string bin = fl::test::BinDir() + "/fl-stereo-vo";
  if (!std::filesystem::exists(bin)) GTEST_SKIP() << "build fl-stereo-vo first: " << bin;
  fl::test::TempDir dir;
  const StereoCalibration calib = fl::test::stereo::TestCalibration();
  const cv::Mat tex = fl::test::stereo::Texture(900, 700, 5);
  {
    fl::LcmLogWriter log(dir.file("in.lcmlog"));
    const Utime t0 = 2000000000;
    cv::Mat l, r;
    fl::test::stereo::PlanePair(tex, calib, 5.0, 0.0, 0.0, &l, &r);
    log.Write(fl::channels::kStereoCalibration, MakeCalibration(calib, false), t0 - 5);
    log.Write(fl::channels::kStereo, MakeStereo(t0 - 4, l, r), t0 - 4);  // no CAMERA_TO_BASE yet
    log.Write(fl::channels::kCameraToBase, MakeCameraToBase(calib), t0 - 3);  // -> refused
    log.Write(fl::channels::kStereo, MakeStereo(t0 - 1, l, r), t0 - 1);  // no valid calibration
    log.Write(fl::channels::kStereoCalibration, MakeCalibration(calib, true), t0);
    for (int k = 0; k < 25; ++k) {
      fl::test::stereo::PlanePair(tex, calib, 5.0, 0.05 * k, 0.0, &l, &r);
      const Utime t = t0 + 100000 * k;
      log.Write(fl::channels::kStereo, MakeStereo(t, l, r), t);
      if (k == 3) log.Write(fl::channels::kStereo, MakeStereo(t, l, r), t);  // repeated
    }
    const cv::Mat small(240, 320, CV_8UC1, cv::Scalar(100));
    log.Write(fl::channels::kStereo, MakeStereo(t0 + 3000000, small, small), t0 + 3000000);
    log.Close();
  }
  const std::string cmd = bin + " --lcm-url log:" + dir.file("in.lcmlog") + "," +
                          dir.file("out.lcmlog") + " --log-level error > " +
                          dir.file("stdout.txt") + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  fl::LcmLogReader reader(dir.file("out.lcmlog"));
  fl::LcmLogEvent ev;
  std::map<std::string, int> counts;
  fusionloc::status_t last_status;
  bool saw_rectified_error = false;
  double last_y = 0;
  while (reader.Next(&ev)) {
    ++counts[ev.channel];
    const int size = static_cast<int>(ev.data.size());
    if (ev.channel == fl::channels::kVoFactors) {
      fusionloc::relative_pose_factor_t f;
      ASSERT_EQ(f.decode(ev.data.data(), 0, size), size);
      const int vision = fusionloc::relative_pose_factor_t::SOURCE_VISION;
      EXPECT_EQ(f.source, vision);
      EXPECT_GT(f.information[7], 0.0);  // (y, y)
    } else if (ev.channel == fl::channels::kVoPose) {
      bot_core::pose_t p;
      ASSERT_EQ(p.decode(ev.data.data(), 0, size), size);
      last_y = p.pos[1];
    } else if (ev.channel == fl::channels::kVoPoints) {
      fusionloc::point_cloud_t pc;
      ASSERT_EQ(pc.decode(ev.data.data(), 0, size), size);
      EXPECT_EQ(pc.frame, "camera");
      EXPECT_EQ(pc.num_intensities, pc.num_points);
    } else if (ev.channel.rfind("STATUS_", 0) == 0) {
      ASSERT_EQ(last_status.decode(ev.data.data(), 0, size), size);
      if (last_status.message.find("not rectified") != std::string::npos) {
        saw_rectified_error = true;
      }
    }
  }
  EXPECT_EQ(counts[fl::channels::kVoPose], 25);
  EXPECT_GE(counts[fl::channels::kVoFactors], 1);  // 1.2 m in 1 m keyframes
  EXPECT_EQ(counts[fl::channels::kVoPoints], counts[fl::channels::kVoFactors] + 1);
  EXPECT_NEAR(last_y, -0.05 * 24, 0.05);
  EXPECT_GE(counts["STATUS_FL_STEREO_VO"], 1);
  // Dropped: the frame before the mounting, the frame after the unrectified calibration, the
  // unrectified calibration and the wrong size; the repeated frame (the same bytes) is a
  // duplicate, dropped by the LCM layer and counted apart.
  EXPECT_EQ(last_status.messages_dropped, 4);
  EXPECT_EQ(StatusValue(last_status, "lcm_duplicates_dropped"), 1);
  EXPECT_TRUE(saw_rectified_error) << "status should report the unrectified calibration";
}

// A log of `frames` stereo pairs of a textured plane 5 m ahead, the rig moving 5 cm to the
// right a frame (10 Hz), after the calibration and mounting; before_frame(log, k, t) may add
// messages before pair k.
void WritePlaneLog(const std::string& path, const StereoCalibration& calib, uint64_t texture_seed,
                   int frames,
                   const std::function<void(fl::LcmLogWriter*, int, Utime)>& before_frame) {
  const cv::Mat tex = fl::test::stereo::Texture(900, 700, texture_seed);
  fl::LcmLogWriter log(path);
  const Utime t0 = 2000000000;
  log.Write(fl::channels::kStereoCalibration, MakeCalibration(calib, true), t0 - 5);
  log.Write(fl::channels::kCameraToBase, MakeCameraToBase(calib), t0 - 4);
  cv::Mat l, r;
  for (int k = 0; k < frames; ++k) {
    const Utime t = t0 + 100000 * k;
    if (before_frame) before_frame(&log, k, t);
    fl::test::stereo::PlanePair(tex, calib, 5.0, 0.05 * k, 0.0, &l, &r);
    log.Write(fl::channels::kStereo, MakeStereo(t, l, r), t);
  }
  log.Close();
}

// fl-stereo-vo with the options `yaml` over dir/in.lcmlog, and what it published.
struct VoProcessRun {
  int exit_status = -1;
  std::string cmd;
  fusionloc::status_t last_status;
  int factors = 0;
};
VoProcessRun RunStereoVoOnLog(const std::string& bin, const fl::test::TempDir& dir,
                              const std::string& yaml) {
  VoProcessRun run;
  {
    std::ofstream out(dir.file("vo.yaml"));
    out << yaml;
  }
  run.cmd = bin + " --config " + dir.file("vo.yaml") + " --lcm-url log:" + dir.file("in.lcmlog") +
            "," + dir.file("out.lcmlog") + " --log-level error > " + dir.file("stdout.txt") +
            " 2>&1";
  run.exit_status = std::system(run.cmd.c_str());
  if (run.exit_status != 0) return run;
  fl::LcmLogReader reader(dir.file("out.lcmlog"));
  fl::LcmLogEvent ev;
  while (reader.Next(&ev)) {
    const int size = static_cast<int>(ev.data.size());
    if (ev.channel == "STATUS_FL_STEREO_VO") {
      if (run.last_status.decode(ev.data.data(), 0, size) != size) run.exit_status = -2;
    } else if (ev.channel == fl::channels::kVoFactors) {
      ++run.factors;
    }
  }
  return run;
}

// use_odometry_prior: ODOMETRY reaches the VO as its motion prior (every tracked frame after
// the first is predicted by it); a non-finite sample is dropped and counted (by the LCM layer,
// lcm_invalid_values).
TEST(StereoVoLcm, ProcessUsesTheOdometryPrior) {
  const std::string bin = fl::test::BinDir() + "/fl-stereo-vo";
  if (!std::filesystem::exists(bin)) GTEST_SKIP() << "build fl-stereo-vo first: " << bin;
  fl::test::TempDir dir;
  WritePlaneLog(dir.file("in.lcmlog"), fl::test::stereo::TestCalibration(), 5, 10,
                [](fl::LcmLogWriter* log, int k, Utime t) {
                  fusionloc::wheel_odometry_t o{};
                  o.utime = t;
                  o.y = -0.05 * k;  // the camera's +x is the base's -y
                  if (k == 5) o.theta = std::nan("");
                  log->Write(fl::channels::kOdometry, o, t);
                });
  const VoProcessRun run = RunStereoVoOnLog(bin, dir, "use_odometry_prior: true\n");
  ASSERT_EQ(run.exit_status, 0) << run.cmd;
  // Frames 1..9 are tracked and predicted, but frame 5: when it arrives the odometry ends at
  // frame 4's time (the odometry is interpolated, never extrapolated).
  EXPECT_EQ(StatusValue(run.last_status, "odometry_prior_frames"), 8);
  EXPECT_EQ(StatusValue(run.last_status, "lcm_invalid_values"), 1);  // the NaN sample
}

// local_ba through the process: a keyframe every 10 cm over a textured plane, each adjusted
// with its window and reported in the status.
TEST(StereoVoLcm, ProcessRunsTheLocalBundleAdjustment) {
  const std::string bin = fl::test::BinDir() + "/fl-stereo-vo";
  if (!std::filesystem::exists(bin)) GTEST_SKIP() << "build fl-stereo-vo first: " << bin;
  fl::test::TempDir dir;
  WritePlaneLog(dir.file("in.lcmlog"), fl::test::stereo::TestCalibration(), 6, 12, nullptr);
  const VoProcessRun run =
      RunStereoVoOnLog(bin, dir, "keyframe_translation_m: 0.1\nlocal_ba: {enabled: true}\n");
  ASSERT_EQ(run.exit_status, 0) << run.cmd;
  EXPECT_GE(run.factors, 4);
  EXPECT_EQ(StatusValue(run.last_status, "local_ba_windows"), run.factors);
  EXPECT_EQ(StatusValue(run.last_status, "local_ba_skipped"), 0);
  EXPECT_GT(StatusValue(run.last_status, "local_ba_points"), 20);
  EXPECT_LT(StatusValue(run.last_status, "local_ba_rms_px"), 1.0);
}

// LASER_3D as the VO's cloud: the extrinsic from both mountings maps a point 5 m ahead on the
// optical axis there; a NaN point is left out and counted.
TEST(StereoVoLcm, LaserCloudFromScanCarriesTheMountings) {
  const StereoCalibration calib = fl::test::stereo::TestCalibration();
  Eigen::Isometry3d T_base_laser = Eigen::Isometry3d::Identity();
  T_base_laser.translation() = Eigen::Vector3d(0.1, 0.0, 0.3);
  // 5 m ahead of the camera along its optical axis, in the laser frame.
  const Eigen::Vector3d p_camera(0, 0, 5);
  const Eigen::Vector3d p_laser = T_base_laser.inverse() * calib.T_base_camera * p_camera;
  fusionloc::laser_scan_3d_t scan{};
  scan.utime = 7;
  scan.num_points = 2;
  scan.x = {static_cast<float>(p_laser.x()), std::numeric_limits<float>::quiet_NaN()};
  scan.y = {static_cast<float>(p_laser.y()), 0.f};
  scan.z = {static_cast<float>(p_laser.z()), 0.f};
  scan.intensity = {0.5f, 0.5f};
  int64_t non_finite = 0;
  const LaserCloud cloud =
      LaserCloudFromScan(scan, calib.T_base_camera.inverse() * T_base_laser, &non_finite);
  EXPECT_EQ(cloud.utime, 7);
  ASSERT_EQ(cloud.points.size(), 1u);
  EXPECT_EQ(non_finite, 1);
  EXPECT_LT((cloud.points[0].cast<double>() - p_laser).norm(), 1e-5);
  EXPECT_LT((cloud.T_camera_laser * cloud.points[0].cast<double>() - p_camera).norm(), 1e-5);
}

// fl-stereo-vo --laser-aided replaying a log: with LASER_3D and its mounting the frames use the
// scans (status laser_frames, laser_depth_features); without the mounting, or without the
// flag, the same frames run on plain stereo and are all tracked.
TEST(StereoVoLcm, ProcessLaserAidedModeUsesTheScansAndFallsBack) {
  const std::string bin = fl::test::BinDir() + "/fl-stereo-vo";
  if (!std::filesystem::exists(bin)) GTEST_SKIP() << "build fl-stereo-vo first: " << bin;
  fl::test::TempDir dir;
  const StereoCalibration calib = fl::test::stereo::TestCalibration();
  const cv::Mat tex = fl::test::stereo::Texture(900, 700, 5);
  Eigen::Isometry3d T_base_laser = Eigen::Isometry3d::Identity();
  T_base_laser.translation() = Eigen::Vector3d(0.1, 0.0, 0.3);
  const Eigen::Isometry3d T_laser_camera = T_base_laser.inverse() * calib.T_base_camera;
  constexpr double kDepth = 5.0;
  auto write_log = [&](const std::string& path, bool with_mounting) {
    fl::LcmLogWriter log(path);
    const Utime t0 = 2000000000;
    log.Write(fl::channels::kStereoCalibration, MakeCalibration(calib, true), t0 - 3);
    log.Write(fl::channels::kCameraToBase, MakeCameraToBase(calib), t0 - 2);
    if (with_mounting) {
      log.Write(fl::channels::kLaser3dToBase, fl::TransformToLcm(T_base_laser, t0 - 1), t0 - 1);
    }
    // The plane at kDepth fills the view; the camera slides along it, so every frame's scan of
    // it is the same in the camera frame: scan lines every 4 px, a point every 2 px.
    fusionloc::laser_scan_3d_t scan{};
    for (double v = 0.5; v < calib.height; v += 4.0) {
      for (double u = 0.5; u < calib.width; u += 2.0) {
        const Eigen::Vector3d p =
            T_laser_camera * Eigen::Vector3d((u - calib.cx) * kDepth / calib.fx,
                                             (v - calib.cy) * kDepth / calib.fy, kDepth);
        scan.x.push_back(static_cast<float>(p.x()));
        scan.y.push_back(static_cast<float>(p.y()));
        scan.z.push_back(static_cast<float>(p.z()));
        scan.intensity.push_back(0.5f);
      }
    }
    scan.num_points = static_cast<int32_t>(scan.x.size());
    scan.frame = "laser";
    cv::Mat l, r;
    for (int k = 0; k < 12; ++k) {
      fl::test::stereo::PlanePair(tex, calib, kDepth, 0.05 * k, 0.0, &l, &r);
      const Utime t = t0 + 100000 * k;
      scan.utime = t - 2000;  // 2 ms before the images
      log.Write(fl::channels::kLaser3d, scan, t - 2000);
      log.Write(fl::channels::kStereo, MakeStereo(t, l, r), t);
    }
    log.Close();
  };
  auto run = [&](const std::string& in, const std::string& out, const std::string& flags) {
    const std::string cmd = bin + " " + flags + " --lcm-url log:" + in + "," + out +
                            " --log-level error > " + dir.file("stdout.txt") + " 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    fl::LcmLogReader reader(out);
    fl::LcmLogEvent ev;
    std::map<std::string, double> values;
    int poses = 0;
    while (reader.Next(&ev)) {
      if (ev.channel == fl::channels::kVoPose) ++poses;
      if (ev.channel != "STATUS_FL_STEREO_VO") continue;
      fusionloc::status_t st;
      const int size = static_cast<int>(ev.data.size());
      EXPECT_EQ(st.decode(ev.data.data(), 0, size), size);
      for (int k = 0; k < st.num_keys; ++k) {
        values[st.keys[static_cast<size_t>(k)]] = st.values[static_cast<size_t>(k)];
      }
    }
    values["poses"] = poses;
    return values;
  };
  write_log(dir.file("with.lcmlog"), true);
  write_log(dir.file("without.lcmlog"), false);

  auto v = run(dir.file("with.lcmlog"), dir.file("o1.lcmlog"), "--laser-aided");
  EXPECT_EQ(v["poses"], 12);
  EXPECT_EQ(v["laser_scans"], 12);
  EXPECT_EQ(v["laser_frames"], 12);
  EXPECT_EQ(v["laser_fallback_frames"], 0);
  EXPECT_GT(v["laser_depth_features"], 20);

  v = run(dir.file("without.lcmlog"), dir.file("o2.lcmlog"), "--laser-aided");
  EXPECT_EQ(v["poses"], 12);  // plain stereo, every frame tracked
  EXPECT_EQ(v["laser_frames"], 0);
  EXPECT_EQ(v["laser_fallback_frames"], 12);

  v = run(dir.file("with.lcmlog"), dir.file("o3.lcmlog"), "");
  EXPECT_EQ(v["poses"], 12);
  EXPECT_EQ(v.count("laser_frames"), 0u);  // mode off: scans not even read
}

}  // namespace
}  // namespace fl::vo
