// The simulator: a differential-drive robot follows the world's route; each Step() advances one
// simulation step and returns the sensor messages due at that time, as the same lcm-gen structs
// the real drivers publish. Pure library: no LCM I/O (WriteLog uses fl::LcmLogWriter).
//
//   fl::sim::Simulator sim(options);
//   fl::sim::SimFrame frame;
//   while (sim.Step(&frame)) { ... frame.laser, frame.stereo, ... }
//
// Timing: frame k has utime start_utime + k * step_s; k = 0 is the start pose (robot at rest).
// Same options (including seed) give the same frames, bit for bit.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "bot_core/images_t.hpp"
#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/channel_map.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/sim/random.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/sim/sensors.hpp"
#include "fusionloc/sim/sim_options.hpp"
#include "fusionloc/sim/world.hpp"
#include "fusionloc/laser_scan_3d_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::sim {

struct SimFrame {
  int64_t step = 0;
  Utime utime = 0;
  Pose2 T_world_base;  // ground truth
  Pose2 T_odom_base;   // noisy integrated odometry
  double v = 0.0;      // [m/s] true forward speed
  double omega = 0.0;  // [rad/s] true yaw rate
  // Messages due at this step (publish in this order).
  std::optional<bot_core::rigid_transform_t> laser_to_base;   // T_base_laser (laser enabled)
  std::optional<bot_core::rigid_transform_t> camera_to_base;  // T_base_camera (camera enabled)
  std::optional<bot_core::rigid_transform_t> laser_3d_to_base;  // T_base_laser3d (laser3d)
  std::optional<fusionloc::stereo_calibration_t> calibration;  // (camera enabled)
  std::optional<bot_core::pose_t> ground_truth;
  std::optional<fusionloc::wheel_odometry_t> odometry;
  std::optional<bot_core::planar_lidar_t> laser;
  std::optional<fusionloc::laser_scan_3d_t> laser_3d;  // before the stereo pair of its step
  std::optional<bot_core::images_t> stereo;
};

// Follows a closed polyline with pure pursuit under speed, yaw-rate and acceleration limits.
class RouteFollower {
 public:
  RouteFollower(std::vector<Eigen::Vector2d> route, const RobotOptions& options);
  // Advances the unicycle state by dt (exact arc integration); returns the commanded (v, omega)
  // used over that interval.
  void Step(double dt, Pose2* pose, double* v, double* omega);
  double progress_m() const { return progress_; }

 private:
  Eigen::Vector2d PointAt(double s) const;
  double Nearest(const Eigen::Vector2d& p, double s_lo, double s_hi) const;

  std::vector<Eigen::Vector2d> route_;
  std::vector<double> cumulative_;  // arc length at each vertex; back() = loop length
  RobotOptions options_;
  double progress_ = 0.0;  // [m] arc length of the nearest route point (unbounded, wraps)
  double v_ = 0.0, omega_ = 0.0;
};

class Simulator {
 public:
  // Throws std::invalid_argument with the Validate() message if the options are invalid.
  explicit Simulator(const SimOptions& options);

  // Fills `out` with the next frame; false when the duration is over (out untouched).
  bool Step(SimFrame* out);

  const World& world() const { return world_; }
  const SimOptions& options() const { return options_; }
  int64_t total_frames() const { return options_.steps() + 1; }
  fusionloc::stereo_calibration_t Calibration(Utime utime) const;
  // The mountings of the robot description, as published on LASER_TO_BASE / CAMERA_TO_BASE.
  bot_core::rigid_transform_t LaserToBase(Utime utime) const;
  bot_core::rigid_transform_t CameraToBase(Utime utime) const;
  bot_core::rigid_transform_t Laser3dToBase(Utime utime) const;  // LASER_3D_TO_BASE
  const LaserModel& laser() const { return laser_; }
  const CameraModel& camera() const { return camera_; }

 private:
  SimOptions options_;
  World world_;
  LaserModel laser_;
  CameraModel camera_;
  Laser3dModel laser3d_;
  RouteFollower follower_;
  Rng odometry_rng_, laser_rng_, camera_rng_, laser3d_rng_;
  int64_t next_step_ = 0;
  int64_t laser_period_, odometry_period_, camera_period_, laser3d_period_, calibration_period_;
  Pose2 pose_;       // ground truth
  Pose2 odom_pose_;  // noisy integrated
  Pose2 odom_last_truth_;  // truth at the last odometry message
  double left_ticks_ = 0.0, right_ticks_ = 0.0;
  double v_ = 0.0, omega_ = 0.0, prev_v_ = 0.0;
};

// Calls fn(channel, message) for each message of a frame, in publishing order, with the
// channel names of fl::channels.
template <class Fn>
void VisitMessages(const SimFrame& f, Fn&& fn) {
  if (f.laser_to_base) fn(channels::kLaserToBase, *f.laser_to_base);
  if (f.camera_to_base) fn(channels::kCameraToBase, *f.camera_to_base);
  if (f.laser_3d_to_base) fn(channels::kLaser3dToBase, *f.laser_3d_to_base);
  if (f.calibration) fn(channels::kStereoCalibration, *f.calibration);
  if (f.ground_truth) fn(channels::kGroundTruth, *f.ground_truth);
  if (f.odometry) fn(channels::kOdometry, *f.odometry);
  if (f.laser) fn(channels::kLaser, *f.laser);
  if (f.laser_3d) fn(channels::kLaser3d, *f.laser_3d);
  if (f.stereo) fn(channels::kStereo, *f.stereo);
}

struct LogStats {
  int64_t frames = 0;
  int64_t events = 0;
  int64_t bytes = 0;
};
// Runs the whole simulation and writes an LCM log (atomically: nothing appears at `path` unless
// it completes). `progress(done, total)` is called after each frame if given. Throws
// std::invalid_argument for invalid options, std::runtime_error for I/O failures. `channels`
// renames the channels as fl-sim --channel does live.
LogStats WriteLog(const SimOptions& options, const std::string& path,
                  const std::function<void(int64_t, int64_t)>& progress = nullptr,
                  const ChannelMap& channels = ChannelMap());

}  // namespace fl::sim
