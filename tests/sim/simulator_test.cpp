// Simulator: messages and timing, determinism of logs, odometry noise statistics, route.
#include "fusionloc/sim/simulator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "sim_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::sim {
namespace {

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

SimOptions Short(double duration_s) {
  SimOptions o;
  o.duration_s = duration_s;
  return o;
}

TEST(SimulatorTest, TheMultiLineLaserAgreesWithTheCameraThroughThePublishedMountings) {
  // LASER_3D points moved into the left camera through LASER_3D_TO_BASE and CAMERA_TO_BASE
  // and projected with STEREO_CALIBRATION land where the camera sees the same depth.
  SimOptions o = DefaultOptionsForWorld("paper");
  o.duration_s = 2.0;
  o.laser3d.enabled = true;
  o.laser3d.range_sigma_m = 0.0;
  Simulator sim(o);
  SimFrame f;
  std::optional<Eigen::Isometry3d> T_base_laser3d, T_base_camera;
  int scans = 0, checked = 0;
  std::vector<double> rel_error;
  while (sim.Step(&f)) {
    if (f.laser_3d_to_base) T_base_laser3d = fl::TransformFromLcm(*f.laser_3d_to_base);
    if (f.camera_to_base) T_base_camera = fl::TransformFromLcm(*f.camera_to_base);
    if (!f.laser_3d) continue;
    ++scans;
    EXPECT_EQ(f.laser_3d->utime, f.utime);
    EXPECT_EQ(f.laser_3d->num_points, static_cast<int32_t>(f.laser_3d->x.size()));
    if (!f.stereo || checked > 0) continue;
    ASSERT_TRUE(T_base_laser3d && T_base_camera);
    const Eigen::Isometry3d T_camera_laser = T_base_camera->inverse() * *T_base_laser3d;
    std::vector<float> depth;
    sim.camera().RenderDepth(sim.world(), f.T_world_base, CameraModel::kLeft, &depth);
    const CameraOptions& c = o.camera;
    for (int i = 0; i < f.laser_3d->num_points; ++i) {
      const Eigen::Vector3d p = T_camera_laser * Eigen::Vector3d(f.laser_3d->x[i], f.laser_3d->y[i],
                                                                 f.laser_3d->z[i]);
      if (p.z() < 0.5) continue;
      const int u = static_cast<int>(std::lround(c.fx * p.x() / p.z() + c.cx));
      const int v = static_cast<int>(std::lround(c.fx * p.y() / p.z() + c.cy));
      if (u < 0 || v < 0 || u >= c.width || v >= c.height) continue;
      const double d = depth[static_cast<size_t>(v) * c.width + u];
      rel_error.push_back(std::abs(d - p.z()) / p.z());
      ++checked;
    }
  }
  EXPECT_EQ(scans, 21);  // 10 Hz over 2 s, both ends
  ASSERT_GT(checked, 500);
  std::sort(rel_error.begin(), rel_error.end());
  EXPECT_LT(rel_error[rel_error.size() / 2], 0.01) << "median relative depth difference";
}

TEST(SimulatorTest, FramesCarryTheMessagesDueWithConsistentTimes) {
  SimOptions o = Short(2.0);
  o.camera.rate_hz = 2.0;  // the MSIF paper's rate: a pair every 5th step
  Simulator sim(o);
  SimFrame f;
  std::map<std::string, int> count;
  int64_t frames = 0;
  while (sim.Step(&f)) {
    EXPECT_EQ(f.step, frames);
    EXPECT_EQ(f.utime, 1000000000000000 + frames * 100000);
    ASSERT_TRUE(f.ground_truth && f.odometry && f.laser);
    EXPECT_EQ(f.ground_truth->utime, f.utime);
    EXPECT_EQ(f.odometry->utime, f.utime);
    EXPECT_EQ(f.laser->utime, f.utime);
    EXPECT_EQ(f.laser->nranges, 682);
    EXPECT_NEAR(f.laser->rad0, -120.0 * M_PI / 180.0, 1e-6);
    EXPECT_NEAR(f.laser->radstep, 0.352 * M_PI / 180.0, 1e-7);
    EXPECT_NEAR(f.ground_truth->pos[0], f.T_world_base.x, 1e-12);
    VisitMessages(f, [&](const char* channel, const auto&) { ++count[channel]; });
    if (f.stereo) {
      EXPECT_EQ(f.step % 5, 0);
      ASSERT_EQ(f.stereo->n_images, 2);
      EXPECT_EQ(f.stereo->image_types[0], 0);  // LEFT
      EXPECT_EQ(f.stereo->image_types[1], 1);  // RIGHT
      const int32_t gray = bot_core::image_t::PIXEL_FORMAT_GRAY;
      for (const auto& im : f.stereo->images) {
        EXPECT_EQ(im.width, 640);
        EXPECT_EQ(im.height, 480);
        EXPECT_EQ(im.row_stride, 640);
        EXPECT_EQ(im.pixelformat, gray);
        EXPECT_EQ(im.size, 640 * 480);
        EXPECT_EQ(im.data.size(), 640u * 480u);
        EXPECT_EQ(im.utime, f.utime);
      }
    }
    if (f.calibration) {
      EXPECT_EQ(f.step % 10, 0);
      EXPECT_TRUE(f.calibration->rectified);
      EXPECT_DOUBLE_EQ(f.calibration->baseline, 0.12);
      // CAMERA_TO_BASE comes with it. Optical z (column 2 of R_base_camera) is base x.
      ASSERT_TRUE(f.camera_to_base.has_value());
      ASSERT_TRUE(f.laser_to_base.has_value());
      const Eigen::Isometry3d T =
          IsometryFromArrays(f.camera_to_base->trans, f.camera_to_base->quat);
      EXPECT_NEAR((T.linear().col(2) - Eigen::Vector3d::UnitX()).norm(), 0.0, 1e-12);
      EXPECT_NEAR((T.linear().col(0) + Eigen::Vector3d::UnitY()).norm(), 0.0, 1e-12);
      EXPECT_NEAR(T.translation().z(), 0.5, 1e-12);
    }
    ++frames;
  }
  EXPECT_EQ(frames, 21);
  EXPECT_EQ(count["LASER"], 21);
  EXPECT_EQ(count["ODOMETRY"], 21);
  EXPECT_EQ(count["GROUND_TRUTH"], 21);
  EXPECT_EQ(count["STEREO"], 5);
  EXPECT_EQ(count["STEREO_CALIBRATION"], 3);
  EXPECT_EQ(count["LASER_TO_BASE"], 3);
  EXPECT_EQ(count["CAMERA_TO_BASE"], 3);
  EXPECT_FALSE(sim.Step(&f));
}

// The published messages, read only through their own fields and the calibration message, must
// describe the simulated geometry: laser end points and back-projected pixels lie on surfaces.
TEST(SimulatorTest, MessagesAgreeWithTheWorldGeometry) {
  SimOptions o = Short(3.0);
  o.laser.range_sigma_m = 0.0;
  o.camera.enabled = false;
  Simulator sim(o);
  SimFrame f;
  // The camera is off (no STEREO, STEREO_CALIBRATION, CAMERA_TO_BASE): its messages are built
  // by the functions that publish them.
  {
    Simulator probe(o);
    ASSERT_TRUE(probe.Step(&f));
    EXPECT_FALSE(f.calibration || f.camera_to_base || f.stereo);
    EXPECT_TRUE(f.laser_to_base.has_value());
  }
  const std::optional<fusionloc::stereo_calibration_t> calib = sim.Calibration(0);
  const bot_core::rigid_transform_t camera_to_base = sim.CameraToBase(0);
  std::optional<bot_core::rigid_transform_t> laser_to_base;
  int checked_beams = 0, checked_pixels = 0;
  while (sim.Step(&f)) {
    if (f.laser_to_base) laser_to_base = f.laser_to_base;
    ASSERT_TRUE(laser_to_base.has_value());
    const auto& gt = *f.ground_truth;
    const Eigen::Isometry3d T_world_base = IsometryFromArrays(gt.pos, gt.orientation);
    const Eigen::Isometry3d T_world_laser =
        T_world_base * IsometryFromArrays(laser_to_base->trans, laser_to_base->quat);
    const auto& scan = *f.laser;
    for (int i = 0; i < scan.nranges; ++i) {
      const double r = scan.ranges[i];
      if (r <= 0) continue;
      const double a = scan.rad0 + i * scan.radstep;
      const Eigen::Vector3d p = T_world_laser * Eigen::Vector3d(r * std::cos(a), r * std::sin(a), 0);
      ASSERT_LT(sim.world().DistanceToObstacles(p.head<2>()), 1e-3) << "beam " << i;
      ++checked_beams;
    }
    if (f.step % 10 != 0) continue;
    // Pixels back-projected with the calibration and the rendered depth land on a surface
    // (an obstacle, or the floor at z = 0).
    const Eigen::Isometry3d T_world_camera =
        T_world_base * IsometryFromArrays(camera_to_base.trans, camera_to_base.quat);
    std::vector<float> depth;
    sim.camera().RenderDepth(sim.world(), f.T_world_base, CameraModel::kLeft, &depth);
    for (int v = 5; v < 480; v += 47) {
      for (int u = 3; u < 640; u += 41) {
        const double d = depth[static_cast<size_t>(v) * 640 + u];
        if (!std::isfinite(d)) continue;
        const Eigen::Vector3d p = T_world_camera * Eigen::Vector3d((u - calib->cx) / calib->fx * d,
                                                                   (v - calib->cy) / calib->fy * d, d);
        const double dist = std::min(std::fabs(p.z()), sim.world().DistanceToObstacles(p.head<2>()));
        ASSERT_LT(dist, 1e-6) << "pixel " << u << "," << v << " depth " << d;
        ++checked_pixels;
      }
    }
  }
  EXPECT_GT(checked_beams, 1000);
  EXPECT_GT(checked_pixels, 200);
}

TEST(SimulatorTest, SameSeedGivesByteIdenticalLogs) {
  test::TempDir dir;
  SimOptions o = Short(2.0);
  o.camera.rate_hz = 2.0;  // 5 pairs a log: the rendering is most of the time
  const LogStats a = WriteLog(o, dir.file("a.lcmlog"));
  WriteLog(o, dir.file("b.lcmlog"));
  SimOptions other = o;
  other.seed = 2;
  WriteLog(other, dir.file("c.lcmlog"));
  const std::string bytes_a = ReadBytes(dir.file("a.lcmlog"));
  EXPECT_GT(bytes_a.size(), 5u * 2 * 640 * 480);
  EXPECT_EQ(bytes_a, ReadBytes(dir.file("b.lcmlog")));
  EXPECT_NE(bytes_a, ReadBytes(dir.file("c.lcmlog")));
  EXPECT_EQ(a.frames, 21);
  EXPECT_EQ(a.events, 21 * 3 + 5 + 3 * 3);
  EXPECT_FALSE(std::filesystem::exists(dir.file("a.lcmlog.partial")));

  // The log reads back: the mountings and the calibration first, every message decodes, times
  // never go back.
  LcmLogReader reader(dir.file("a.lcmlog"));
  LcmLogEvent ev;
  for (const char* first : {"LASER_TO_BASE", "CAMERA_TO_BASE", "STEREO_CALIBRATION"}) {
    ASSERT_TRUE(reader.Next(&ev));
    EXPECT_EQ(ev.channel, first);
  }
  Utime last = 0;
  int64_t n = 3;
  while (reader.Next(&ev)) {
    EXPECT_GE(ev.utime, last);
    last = ev.utime;
    if (ev.channel == "STEREO") {
      bot_core::images_t m;
      EXPECT_EQ(m.decode(ev.data.data(), 0, static_cast<int>(ev.data.size())),
                static_cast<int>(ev.data.size()));
      EXPECT_EQ(m.utime, ev.utime);
    }
    ++n;
  }
  EXPECT_EQ(n, a.events);
  EXPECT_EQ(reader.ProblemSummary(), "");
}

TEST(SimulatorTest, InvalidOptionsCreateNoFile) {
  test::TempDir dir;
  SimOptions o = Short(1.0);
  o.camera.pixel_noise_sigma = -1;
  EXPECT_THROW(WriteLog(o, dir.file("x.lcmlog")), std::invalid_argument);
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.lcmlog")));
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.lcmlog.partial")));
}

TEST(SimulatorTest, FailedLogWriteLeavesNoFile) {
  // fl-sim's Ctrl-C handling throws from the progress callback: the partial log must go.
  test::TempDir dir;
  SimOptions o = Short(5.0);
  o.camera.enabled = false;
  EXPECT_THROW(WriteLog(o, dir.file("x.lcmlog"),
                        [](int64_t done, int64_t) {
                          if (done == 3) throw std::runtime_error("interrupted");
                        }),
               std::runtime_error);
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.lcmlog")));
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.lcmlog.partial")));
}

// Runs the motion and odometry only (no rendering) for `duration_s`.
std::vector<SimFrame> Drive(SimOptions o, double duration_s) {
  o.duration_s = duration_s;
  o.laser.enabled = false;
  o.camera.enabled = false;
  return test::Simulate(o);
}

TEST(SimulatorTest, FixtureHelperGivesTheRequestedSensors) {
  const auto frames = test::Simulate("corridor", 1.0, 4, /*laser=*/true, /*camera=*/false);
  ASSERT_EQ(frames.size(), 11u);
  for (const SimFrame& f : frames) {
    EXPECT_TRUE(f.laser.has_value());
    EXPECT_FALSE(f.stereo.has_value());
  }
}

TEST(SimulatorTest, OdometryNoiseMatchesTheDocumentedModel) {
  const SimOptions o;
  const OdometryOptions& n = o.odometry;
  const std::vector<SimFrame> frames = Drive(o, 1500.0);  // ~15000 increments
  double s_fwd = 0, s2_fwd = 0, s2_lat = 0, s2_yaw = 0;
  int count = 0;
  for (size_t k = 1; k < frames.size(); ++k) {
    const Pose2 truth = frames[k - 1].T_world_base.between(frames[k].T_world_base);
    const Pose2 odom = frames[k - 1].T_odom_base.between(frames[k].T_odom_base);
    const double dist = std::hypot(truth.x, truth.y);
    if (dist < 0.02) continue;  // turning on the spot: forward noise ~ 0
    const double yaw_sigma = std::sqrt(n.yaw_sigma_rad_per_sqrt_rad * n.yaw_sigma_rad_per_sqrt_rad *
                                           std::fabs(truth.theta) +
                                       n.yaw_sigma_rad_per_sqrt_m * n.yaw_sigma_rad_per_sqrt_m * dist);
    const double e_fwd = (odom.x - truth.x) / (n.trans_sigma_m_per_sqrt_m * std::sqrt(dist));
    const double e_lat = (odom.y - truth.y) / (n.lateral_sigma_m_per_sqrt_m * std::sqrt(dist));
    const double e_yaw = WrapAngle(odom.theta - truth.theta) / yaw_sigma;
    s_fwd += e_fwd, s2_fwd += e_fwd * e_fwd, s2_lat += e_lat * e_lat, s2_yaw += e_yaw * e_yaw;
    ++count;
  }
  ASSERT_GT(count, 10000);
  // Normalised errors are N(0, 1): mean within 4 standard errors, std within 5 %.
  EXPECT_NEAR(s_fwd / count, 0.0, 4.0 / std::sqrt(count));
  EXPECT_NEAR(std::sqrt(s2_fwd / count), 1.0, 0.05);
  EXPECT_NEAR(std::sqrt(s2_lat / count), 1.0, 0.05);
  EXPECT_NEAR(std::sqrt(s2_yaw / count), 1.0, 0.05);

  // The published message matches the frame's integrated odometry; velocities are increments / dt.
  EXPECT_NEAR(frames[50].odometry->x, frames[50].T_odom_base.x, 1e-12);
  const Pose2 inc = frames[49].T_odom_base.between(frames[50].T_odom_base);
  EXPECT_NEAR(frames[50].odometry->v, inc.x / 0.1, 1e-9);
}

TEST(SimulatorTest, RobotStaysClearOfObstaclesAndRevisitsPlaces) {
  for (const std::string world : {"paper", "corridor"}) {
    for (int64_t seed : {1, 2, 3}) {
      SimOptions o = DefaultOptionsForWorld(world);
      o.seed = seed;
      const std::vector<SimFrame> frames = Drive(o, o.duration_s);
      Simulator sim(o);  // for the world
      double min_clear = 1e9, path = 0.0;
      // The corridor route passes its start after room A, so there "away" means the far end.
      const double far = world == "paper" ? 5.0 : 40.0;
      bool moved_away = false, returned = false;
      const Eigen::Vector2d start = frames.front().T_world_base.translation();
      for (size_t k = 0; k < frames.size(); ++k) {
        const Eigen::Vector2d p = frames[k].T_world_base.translation();
        min_clear = std::min(min_clear, sim.world().DistanceToObstacles(p));
        if (k > 0) path += (p - frames[k - 1].T_world_base.translation()).norm();
        moved_away |= (p - start).norm() > far;
        returned |= moved_away && (p - start).norm() < 0.5;
        EXPECT_LE(std::fabs(frames[k].v), o.robot.max_speed_mps + 1e-9);
        EXPECT_LE(std::fabs(frames[k].omega), o.robot.max_yaw_rate_rps + 1e-9);
      }
      EXPECT_GE(min_clear, 0.5) << world << " seed " << seed;
      EXPECT_TRUE(returned) << world << " seed " << seed << ": the route never closes the loop";
      EXPECT_GT(path, 0.5 * o.robot.max_speed_mps * o.duration_s) << world;
      std::printf("%s seed %ld: path %.1f m in %.0f s, min clearance %.2f m\n", world.c_str(),
                  static_cast<long>(seed), path, o.duration_s, min_clear);
    }
  }
}

TEST(SimulatorTest, CorridorSizeVariantsStayClear) {
  for (const auto& [length, width] : {std::pair{40.0, 2.0}, std::pair{40.0, 5.0},
                                      std::pair{120.0, 3.0}}) {
    SimOptions o = DefaultOptionsForWorld("corridor");
    o.world.corridor_length_m = length;
    o.world.corridor_width_m = width;
    const std::vector<SimFrame> frames = Drive(o, 400.0);
    Simulator sim(o);
    double min_clear = 1e9;
    for (const SimFrame& f : frames) {
      min_clear = std::min(min_clear, sim.world().DistanceToObstacles(f.T_world_base.translation()));
    }
    EXPECT_GE(min_clear, 0.5) << "corridor " << length << " x " << width;
  }
}

TEST(SimulatorTest, GroundTruthVelocityMatchesMotion) {
  const std::vector<SimFrame> frames = Drive(SimOptions(), 30.0);
  for (size_t k = 1; k < frames.size(); ++k) {
    const Pose2 inc = frames[k - 1].T_world_base.between(frames[k].T_world_base);
    // Arc of constant (v, omega) over 0.1 s: chord length ~ v * dt.
    EXPECT_NEAR(std::hypot(inc.x, inc.y), std::fabs(frames[k].v) * 0.1, 1e-3);
    EXPECT_NEAR(inc.theta, frames[k].omega * 0.1, 1e-9);
    const auto& gt = *frames[k].ground_truth;
    EXPECT_NEAR(std::hypot(gt.vel[0], gt.vel[1]), std::fabs(frames[k].v), 1e-12);
    EXPECT_NEAR(2.0 * std::atan2(gt.orientation[3], gt.orientation[0]),
                frames[k].T_world_base.theta, 1e-9);
  }
}

}  // namespace
}  // namespace fl::sim
