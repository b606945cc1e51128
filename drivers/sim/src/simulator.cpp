#include "fusionloc/sim/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"

namespace fl::sim {

// ------------------------------------------------------------------------------------------
// RouteFollower

RouteFollower::RouteFollower(std::vector<Eigen::Vector2d> route, const RobotOptions& options)
    : route_(std::move(route)), options_(options) {
  if (route_.size() < 2) throw std::invalid_argument("a route needs at least two points");
  cumulative_.push_back(0.0);
  for (size_t i = 0; i < route_.size(); ++i) {
    cumulative_.push_back(cumulative_.back() +
                          (route_[(i + 1) % route_.size()] - route_[i]).norm());
  }
}

Eigen::Vector2d RouteFollower::PointAt(double s) const {
  const double loop = cumulative_.back();
  s = std::fmod(s, loop);
  if (s < 0) s += loop;
  const size_t i = static_cast<size_t>(std::upper_bound(cumulative_.begin(), cumulative_.end(), s) -
                                       cumulative_.begin() - 1);
  const size_t seg = std::min(i, route_.size() - 1);
  const double len = cumulative_[seg + 1] - cumulative_[seg];
  const double u = len > 0 ? (s - cumulative_[seg]) / len : 0.0;
  return route_[seg] + u * (route_[(seg + 1) % route_.size()] - route_[seg]);
}

double RouteFollower::Nearest(const Eigen::Vector2d& p, double s_lo, double s_hi) const {
  // A windowed search (not global) so that crossings and doubled-back stretches of the route
  // never make the robot jump ahead or back along it.
  constexpr double kStep = 0.01;
  double best_s = s_lo, best_d = std::numeric_limits<double>::infinity();
  for (double s = s_lo; s <= s_hi; s += kStep) {
    const double d = (PointAt(s) - p).squaredNorm();
    if (d < best_d) best_d = d, best_s = s;
  }
  return best_s;
}

void RouteFollower::Step(double dt, Pose2* pose, double* v_out, double* omega_out) {
  const Eigen::Vector2d p = pose->translation();
  progress_ = std::max(progress_, Nearest(p, progress_ - 0.2, progress_ + 1.0));
  const Eigen::Vector2d target = PointAt(progress_ + options_.lookahead_m);
  const Eigen::Vector2d rel = pose->rotation().transpose() * (target - p);
  const double alpha = std::atan2(rel.y(), rel.x());
  const double dist = std::max(rel.norm(), 1e-3);
  const double curvature = 2.0 * std::sin(alpha) / dist;  // pure pursuit

  double v_des, omega_des;
  if (std::fabs(alpha) > M_PI / 3) {
    // Target far off the heading: turn (almost) on the spot.
    v_des = 0.05;
    omega_des = std::copysign(options_.max_yaw_rate_rps, alpha);
  } else {
    v_des = options_.max_speed_mps;
    if (std::fabs(curvature) > 1e-9) {
      v_des = std::min(v_des, options_.max_yaw_rate_rps / std::fabs(curvature));
    }
    omega_des = v_des * curvature;
  }
  const double dv = options_.max_accel_mps2 * dt, dw = options_.max_yaw_accel_rps2 * dt;
  v_ += std::clamp(v_des - v_, -dv, dv);
  omega_ += std::clamp(omega_des - omega_, -dw, dw);
  omega_ = std::clamp(omega_, -options_.max_yaw_rate_rps, options_.max_yaw_rate_rps);

  // Exact integration of the unicycle over dt with constant (v, omega).
  const double th = pose->theta;
  if (std::fabs(omega_) > 1e-9) {
    const double th1 = th + omega_ * dt;
    pose->x += v_ / omega_ * (std::sin(th1) - std::sin(th));
    pose->y -= v_ / omega_ * (std::cos(th1) - std::cos(th));
    pose->theta = WrapAngle(th1);
  } else {
    pose->x += v_ * dt * std::cos(th);
    pose->y += v_ * dt * std::sin(th);
  }
  *v_out = v_;
  *omega_out = omega_;
}

// ------------------------------------------------------------------------------------------
// Simulator

namespace {

SimOptions Validated(const SimOptions& o) {
  const Status s = o.Validate();
  if (!s.ok()) throw std::invalid_argument("invalid simulator options: " + s.message());
  return o;
}

Pose2 StartPose(const World& w) {
  const Eigen::Vector2d d = w.route()[1] - w.route()[0];
  return Pose2(w.route()[0].x(), w.route()[0].y(), std::atan2(d.y(), d.x()));
}

}  // namespace

Simulator::Simulator(const SimOptions& options)
    : options_(Validated(options)),
      world_(World::Build(options_)),
      laser_(options_.laser),
      camera_(options_.camera),
      laser3d_(options_.laser3d),
      follower_(world_.route(), options_.robot),
      odometry_rng_(Hash3(static_cast<uint64_t>(options_.seed), 10, 0)),
      laser_rng_(Hash3(static_cast<uint64_t>(options_.seed), 11, 0)),
      camera_rng_(Hash3(static_cast<uint64_t>(options_.seed), 12, 0)),
      laser3d_rng_(Hash3(static_cast<uint64_t>(options_.seed), 13, 0)),
      laser_period_(options_.PeriodSteps(options_.laser.rate_hz)),
      odometry_period_(options_.PeriodSteps(options_.odometry.rate_hz)),
      camera_period_(options_.PeriodSteps(options_.camera.rate_hz)),
      laser3d_period_(options_.PeriodSteps(options_.laser3d.rate_hz)),
      calibration_period_(options_.PeriodSteps(1.0 / options_.calibration_period_s)),
      pose_(StartPose(world_)),
      odom_last_truth_(pose_) {}

fusionloc::stereo_calibration_t Simulator::Calibration(Utime utime) const {
  const CameraOptions& c = options_.camera;
  fusionloc::stereo_calibration_t m;
  m.utime = utime;
  m.width = c.width;
  m.height = c.height;
  m.fx = c.fx;
  m.fy = c.fx;
  m.cx = c.cx;
  m.cy = c.cy;
  m.baseline = c.baseline_m;
  m.rectified = true;
  return m;
}

bot_core::rigid_transform_t Simulator::LaserToBase(Utime utime) const {
  Mount laser;  // level, 0 rad beam along base x
  laser.xyz_m = {options_.laser.x_m, options_.laser.y_m, options_.laser.z_m};
  return TransformToLcm(laser.T_base_sensor(), utime);
}

bot_core::rigid_transform_t Simulator::Laser3dToBase(Utime utime) const {
  Mount laser3d;  // level: x forward, y left, z up
  laser3d.xyz_m = {options_.laser3d.x_m, options_.laser3d.y_m, options_.laser3d.z_m};
  return TransformToLcm(laser3d.T_base_sensor(), utime);
}

bot_core::rigid_transform_t Simulator::CameraToBase(Utime utime) const {
  // Optical axes in the base frame: x_cam = -y_base, y_cam = -z_base, z_cam = +x_base.
  Mount camera;
  camera.xyz_m = {options_.camera.x_m, options_.camera.y_m, options_.camera.z_m};
  camera.rpy_deg = {-90.0, 0.0, -90.0};
  return TransformToLcm(camera.T_base_sensor(), utime);
}

bool Simulator::Step(SimFrame* out) {
  const int64_t k = next_step_;
  if (k > options_.steps()) return false;
  ++next_step_;
  const double dt = options_.step_s;
  const Utime step_us = static_cast<Utime>(std::llround(dt * 1e6));
  if (k > 0) {
    prev_v_ = v_;
    follower_.Step(dt, &pose_, &v_, &omega_);
  }
  SimFrame f;
  f.step = k;
  f.utime = options_.start_utime + k * step_us;
  f.T_world_base = pose_;
  f.v = v_;
  f.omega = omega_;

  if (k % calibration_period_ == 0) {
    if (options_.laser.enabled) f.laser_to_base = LaserToBase(f.utime);
    if (options_.laser3d.enabled) f.laser_3d_to_base = Laser3dToBase(f.utime);
    if (options_.camera.enabled) {
      f.camera_to_base = CameraToBase(f.utime);
      f.calibration = Calibration(f.utime);
    }
  }

  bot_core::pose_t gt;
  gt.utime = f.utime;
  gt.pos[0] = pose_.x;
  gt.pos[1] = pose_.y;
  gt.pos[2] = 0.0;
  gt.vel[0] = v_ * std::cos(pose_.theta);
  gt.vel[1] = v_ * std::sin(pose_.theta);
  gt.vel[2] = 0.0;
  gt.orientation[0] = std::cos(0.5 * pose_.theta);
  gt.orientation[1] = 0.0;
  gt.orientation[2] = 0.0;
  gt.orientation[3] = std::sin(0.5 * pose_.theta);
  gt.rotation_rate[0] = gt.rotation_rate[1] = 0.0;
  gt.rotation_rate[2] = omega_;
  gt.accel[0] = k > 0 ? (v_ - prev_v_) / dt : 0.0;
  gt.accel[1] = v_ * omega_;
  gt.accel[2] = 0.0;
  f.ground_truth = gt;

  if (k % odometry_period_ == 0) {
    // Noise on the base-frame increment since the last odometry message (docs/SIMULATOR.md).
    const OdometryOptions& n = options_.odometry;
    const Pose2 inc = odom_last_truth_.between(pose_);
    const double dist = std::hypot(inc.x, inc.y);
    const double e_fwd = odometry_rng_.Normal(n.trans_sigma_m_per_sqrt_m * std::sqrt(dist));
    const double e_lat = odometry_rng_.Normal(n.lateral_sigma_m_per_sqrt_m * std::sqrt(dist));
    const double yaw_var =
        n.yaw_sigma_rad_per_sqrt_rad * n.yaw_sigma_rad_per_sqrt_rad * std::fabs(inc.theta) +
        n.yaw_sigma_rad_per_sqrt_m * n.yaw_sigma_rad_per_sqrt_m * dist;
    const double e_yaw = odometry_rng_.Normal(std::sqrt(yaw_var));
    const Pose2 noisy(inc.x + e_fwd, inc.y + e_lat, inc.theta + e_yaw);
    odom_pose_ = odom_pose_ * noisy;
    odom_last_truth_ = pose_;
    const double period_s = static_cast<double>(odometry_period_) * dt;
    const double v_meas = k > 0 ? noisy.x / period_s : 0.0;
    const double w_meas = k > 0 ? noisy.theta / period_s : 0.0;
    const RobotOptions& r = options_.robot;
    const double ticks_per_m = r.ticks_per_rev / (2.0 * M_PI * r.wheel_radius_m);
    left_ticks_ += (noisy.x - 0.5 * r.wheel_base_m * noisy.theta) * ticks_per_m;
    right_ticks_ += (noisy.x + 0.5 * r.wheel_base_m * noisy.theta) * ticks_per_m;
    fusionloc::wheel_odometry_t odo;
    odo.utime = f.utime;
    odo.x = odom_pose_.x;
    odo.y = odom_pose_.y;
    odo.theta = odom_pose_.theta;
    odo.v = v_meas;
    odo.omega = w_meas;
    odo.left_ticks = std::round(left_ticks_);
    odo.right_ticks = std::round(right_ticks_);
    f.odometry = odo;
  }
  f.T_odom_base = odom_pose_;

  if (options_.laser.enabled && k % laser_period_ == 0) {
    bot_core::planar_lidar_t scan;
    scan.utime = f.utime;
    laser_.Scan(world_, pose_, &laser_rng_, &scan.ranges);
    scan.nranges = static_cast<int32_t>(scan.ranges.size());
    scan.nintensities = 0;
    scan.rad0 = static_cast<float>(options_.laser.first_angle_deg * M_PI / 180.0);
    scan.radstep = static_cast<float>(options_.laser.step_deg * M_PI / 180.0);
    f.laser = std::move(scan);
  }

  if (options_.laser3d.enabled && k % laser3d_period_ == 0) {
    std::vector<Eigen::Vector3f> points;
    laser3d_.Scan(world_, pose_, &laser3d_rng_, &points);
    fusionloc::laser_scan_3d_t scan;
    scan.utime = f.utime;
    scan.frame = "laser3d";
    scan.num_points = static_cast<int32_t>(points.size());
    scan.x.reserve(points.size());
    scan.y.reserve(points.size());
    scan.z.reserve(points.size());
    for (const Eigen::Vector3f& p : points) {
      scan.x.push_back(p.x());
      scan.y.push_back(p.y());
      scan.z.push_back(p.z());
    }
    scan.intensity.assign(points.size(), 0.5f);  // the simulator has no reflectance
    f.laser_3d = std::move(scan);
  }

  if (options_.camera.enabled && k % camera_period_ == 0) {
    bot_core::images_t pair;
    pair.utime = f.utime;
    pair.n_images = 2;
    const int16_t left = bot_core::images_t::LEFT, right = bot_core::images_t::RIGHT;
    pair.image_types = {left, right};
    const int32_t gray = bot_core::image_t::PIXEL_FORMAT_GRAY;
    for (CameraModel::Eye eye : {CameraModel::kLeft, CameraModel::kRight}) {
      bot_core::image_t im;
      im.utime = f.utime;
      im.width = options_.camera.width;
      im.height = options_.camera.height;
      im.row_stride = options_.camera.width;
      im.pixelformat = gray;
      camera_.Render(world_, pose_, eye, &camera_rng_, &im.data);
      im.size = static_cast<int32_t>(im.data.size());
      im.nmetadata = 0;
      pair.images.push_back(std::move(im));
    }
    f.stereo = std::move(pair);
  }
  *out = std::move(f);
  return true;
}

// ------------------------------------------------------------------------------------------
// Log writing

LogStats WriteLog(const SimOptions& options, const std::string& path,
                  const std::function<void(int64_t, int64_t)>& progress,
                  const ChannelMap& channels) {
  Simulator sim(options);  // validates before any file is created
  LcmLogWriter writer(path);
  LogStats stats;
  try {
    SimFrame frame;
    while (sim.Step(&frame)) {
      VisitMessages(frame, [&](const char* channel, const auto& msg) {
        writer.Write(channels(channel), msg, frame.utime);
        ++stats.events;
        stats.bytes += msg.getEncodedSize();
      });
      ++stats.frames;
      if (progress) progress(stats.frames, sim.total_frames());
    }
    writer.Close();
  } catch (...) {
    writer.Abandon();
    throw;
  }
  return stats;
}

}  // namespace fl::sim
