// Hand-made trajectories for evaluation tests, with closed-form properties.
#pragma once

#include <cmath>
#include <functional>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/eval/trajectory.hpp"

namespace fl::test {

// Planar poses (x, y, theta) at `period_us` from t0; `f(i)` gives pose i.
inline eval::Trajectory MakePlanarTrajectory(size_t n, const std::function<Pose2(size_t)>& f,
                                             Utime t0 = 1000000, Utime period_us = 100000) {
  eval::Trajectory traj;
  for (size_t i = 0; i < n; ++i) {
    traj.push_back({t0 + static_cast<Utime>(i) * period_us, f(i).ToIsometry3()});
  }
  return traj;
}

// Straight line along x, `step_m` apart, heading 0.
inline eval::Trajectory MakeStraightTrajectory(size_t n, double step_m, Utime t0 = 1000000,
                                               Utime period_us = 100000) {
  return MakePlanarTrajectory(
      n, [step_m](size_t i) { return Pose2(step_m * static_cast<double>(i), 0.0, 0.0); }, t0,
      period_us);
}

// A 3D helix-like path with changing roll, pitch and yaw (well-conditioned for SE3 alignment).
inline eval::Trajectory MakeHelixTrajectory(size_t n, Utime t0 = 1000000,
                                            Utime period_us = 100000) {
  eval::Trajectory traj;
  for (size_t i = 0; i < n; ++i) {
    const double s = 0.1 * static_cast<double>(i);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = Eigen::Vector3d(5.0 * std::cos(s), 3.0 * std::sin(s), 0.4 * s);
    T.linear() = RotationFromRollPitchYaw(0.1 * std::sin(2 * s), 0.05 * std::cos(s), s + M_PI_2);
    traj.push_back({t0 + static_cast<Utime>(i) * period_us, T});
  }
  return traj;
}

// Applies T_left * pose (and optionally scales positions first) to every pose.
inline eval::Trajectory TransformTrajectory(const eval::Trajectory& traj,
                                            const Eigen::Isometry3d& T_left, double scale = 1.0) {
  eval::Trajectory out = traj;
  for (auto& p : out) {
    p.T_world_base.translation() *= scale;
    p.T_world_base = T_left * p.T_world_base;
  }
  return out;
}

}  // namespace fl::test
