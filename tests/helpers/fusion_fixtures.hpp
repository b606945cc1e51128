// Synthetic data for the fusion tests: a robot driving a rounded square at constant speed,
// with laser-rate RBPF poses (drifting: integrated noisy, heading-biased motion), laser
// between-factors of consecutive nodes, asynchronous vision keyframe factors (6-DoF, full
// correlated information, times offset from the laser) and a loop closure.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/fusion/factor_graph_fusion.hpp"

namespace fl::test {

struct FusionSimOptions {
  double side_m = 6.0;               // [m] square side
  double corner_radius_m = 0.8;      // [m] rounded corners
  double speed_mps = 1.0;            // [m/s]
  int laps = 1;                      // laps of the square
  double laser_hz = 10.0;            // node rate
  int vision_every = 5;              // a vision keyframe every N laser periods (2 Hz)
  double vision_offset_s = 0.013;    // [s] vision times = laser times + offset
  double laser_sigma_xy = 0.0;       // [m] noise of laser between-factors
  double laser_sigma_theta = 0.0;    // [rad]
  double vision_sigma_xy = 0.0;      // [m] noise of vision factors
  double vision_sigma_theta = 0.0;   // [rad]
  double rbpf_heading_bias = 0.004;  // [rad/step] drift of the RBPF poses
  bool loop_closure = true;          // laser loop closure newest -> first node
  Utime start_utime = 1000000;       // [us]
  unsigned seed = 1;
};

struct FusionSimData {
  std::vector<fusion::TrajectoryPoint> truth;  // at laser times
  std::vector<fusion::TrajectoryPoint> rbpf;   // drifting laser-rate poses
  std::vector<fusion::RelativePoseFactor> laser_factors;
  std::vector<fusion::RelativePoseFactor> vision_factors;
  std::vector<fusion::RelativePoseFactor> loop_factors;
};

// Truth pose after driving distance s along the rounded square (starts at the origin,
// heading +x, counter-clockwise).
inline Pose2 RoundedSquarePose(const FusionSimOptions& o, double s) {
  const double r = o.corner_radius_m;
  const double straight = o.side_m - 2.0 * r;
  const double arc = 0.5 * M_PI * r;
  const double per_side = straight + arc;
  const double lap = 4.0 * per_side;
  s = std::fmod(std::max(s, 0.0), lap);
  const int side = static_cast<int>(s / per_side);
  const double u = s - side * per_side;
  // Local frame of this side: starts at (0,0) heading +x.
  Pose2 local;
  if (u <= straight) {
    local = Pose2(u, 0.0, 0.0);
  } else {
    const double a = (u - straight) / r;  // angle turned on the arc
    local = Pose2(straight + r * std::sin(a), r * (1.0 - std::cos(a)), a);
  }
  Pose2 start(0.0, 0.0, 0.0);
  for (int k = 0; k < side; ++k) start = start * Pose2(straight + r, r, 0.5 * M_PI);
  // Correct the corner offset so that every side starts where the previous arc ended.
  return start * local;
}

inline Eigen::Isometry3d Planar3(const Pose2& p) { return p.ToIsometry3(); }

inline FusionSimData MakeRoundedSquareSim(const FusionSimOptions& o) {
  FusionSimData d;
  std::mt19937 rng(o.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double r = o.corner_radius_m;
  const double lap = 4.0 * (o.side_m - 2.0 * r + 0.5 * M_PI * r);
  const double duration = o.laps * lap / o.speed_mps;
  const int steps = static_cast<int>(duration * o.laser_hz);
  const Utime dt = SecondsToUtime(1.0 / o.laser_hz);
  auto truth_at = [&](Utime t) {
    return RoundedSquarePose(o, o.speed_mps * UtimeToSeconds(t - o.start_utime));
  };
  Pose2 rbpf;
  for (int k = 0; k < steps; ++k) {
    const Utime t = o.start_utime + k * dt;
    const Pose2 truth = truth_at(t);
    d.truth.push_back({t, truth});
    if (k == 0) {
      rbpf = truth;
    } else {
      const Pose2 motion = d.truth[k - 1].T_map_base.between(truth);
      const Pose2 noisy(motion.x + o.laser_sigma_xy * n01(rng),
                        motion.y + o.laser_sigma_xy * n01(rng),
                        motion.theta + o.laser_sigma_theta * n01(rng));
      // The RBPF pose drifts: noisy motion plus a heading bias.
      rbpf = rbpf * Pose2(noisy.x, noisy.y, noisy.theta + o.rbpf_heading_bias);
      fusion::RelativePoseFactor f;
      f.utime_i = d.truth[k - 1].utime;
      f.utime_j = t;
      f.T_i_j = Planar3(noisy);
      const double sxy = std::max(o.laser_sigma_xy, 0.01);
      const double sth = std::max(o.laser_sigma_theta, 0.005);
      f.information(0, 0) = f.information(1, 1) = 1.0 / (sxy * sxy);
      f.information(5, 5) = 1.0 / (sth * sth);
      f.source = fusion::FactorSource::kLaser;
      d.laser_factors.push_back(f);
    }
    d.rbpf.push_back({t, rbpf});
  }
  // Vision keyframes: every vision_every laser periods, offset in time, 6-DoF with a full
  // correlated covariance.
  const Utime off = SecondsToUtime(o.vision_offset_s);
  Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Identity();
  a(0, 5) = 0.3;
  a(1, 3) = -0.2;
  a(2, 4) = 0.25;
  const double vsxy = std::max(o.vision_sigma_xy, 0.02);
  const double vsth = std::max(o.vision_sigma_theta, 0.005);
  const Eigen::Matrix<double, 6, 1> sig =
      (Eigen::Matrix<double, 6, 1>() << vsxy, vsxy, vsxy, vsth, vsth, vsth).finished();
  const Eigen::Matrix<double, 6, 6> cov = sig.asDiagonal() * a * a.transpose() * sig.asDiagonal();
  const Eigen::Matrix<double, 6, 6> info = cov.inverse();
  Utime prev = -1;
  for (int k = 0; k + 1 < steps; k += o.vision_every) {
    const Utime t = o.start_utime + k * dt + off;
    if (prev >= 0) {
      const Pose2 motion = truth_at(prev).between(truth_at(t));
      fusion::RelativePoseFactor f;
      f.utime_i = prev;
      f.utime_j = t;
      f.T_i_j = Planar3(Pose2(motion.x + o.vision_sigma_xy * n01(rng),
                              motion.y + o.vision_sigma_xy * n01(rng),
                              motion.theta + o.vision_sigma_theta * n01(rng)));
      f.information = 0.5 * (info + info.transpose());
      f.source = fusion::FactorSource::kVision;
      d.vision_factors.push_back(f);
    }
    prev = t;
  }
  if (o.loop_closure && steps > 2) {
    fusion::RelativePoseFactor f;
    f.utime_i = d.truth.back().utime;
    f.utime_j = d.truth.front().utime;
    f.T_i_j = Planar3(d.truth.back().T_map_base.between(d.truth.front().T_map_base));
    f.information(0, 0) = f.information(1, 1) = 1.0 / (0.02 * 0.02);
    f.information(5, 5) = 1.0 / (0.005 * 0.005);
    f.source = fusion::FactorSource::kLaser;
    f.is_loop_closure = true;
    d.loop_factors.push_back(f);
  }
  return d;
}

}  // namespace fl::test
