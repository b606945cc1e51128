// The robot description: where the sensors are mounted on the base, and the base's geometry.
// One file per robot (config/robot/<robot>.yaml, docs/ROBOT.md), read by the programs that
// describe the robot (the simulator, the importers, fl-robot-description on a real robot),
// which publish the mounting as bot_core.rigid_transform_t on LASER_TO_BASE and
// CAMERA_TO_BASE (channels.hpp). Estimators and the fusion read those channels, so a log
// carries the mounting it was recorded with.
//
// Frames: base x forward, y left, z up (on the ground, between the wheels); laser x along the
// scan's 0 rad beam, z up; camera = the left camera's optical frame, x right, y down,
// z forward. A mounting is T_base_sensor: p_base = R * p_sensor + t, with R = Rz(yaw) Ry(pitch)
// Rx(roll) (fixed axes, as ROS's static_transform_publisher and URDF's rpy). Quarter turns
// are exact (cos 90° = 0, not 6e-17).
//
//   name: sim
//   laser:  {xyz_m: [0.15, 0, 0.3], rpy_deg: [0, 0, 0]}
//   camera: {xyz_m: [0.2, 0.06, 0.5], rpy_deg: [-90, 0, -90]}   # optical z = base x
//   laser3d: {xyz_m: [0.1, 0, 0.9], rpy_deg: [0, 0, 0]}          # optional multi-line laser
//   base:   {wheel_radius_m: 0.035, track_m: 0.23, ticks_per_revolution: 2578.33}
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"

namespace fl {

// A sensor's mounting on the base: T_base_sensor.
struct Mount {
  std::vector<double> xyz_m{0.0, 0.0, 0.0};    // [m] sensor origin in the base frame
  std::vector<double> rpy_deg{0.0, 0.0, 0.0};  // [deg] roll, pitch, yaw (R = Rz Ry Rx)

  Eigen::Isometry3d T_base_sensor() const;
  template <class A>
  void Serialize(A* a) {
    a->Visit("xyz_m", &xyz_m);
    a->Visit("rpy_deg", &rpy_deg);
  }
  Status Validate() const;
};

// A differential-drive base (wheel odometry from encoder ticks). 0 = not described.
struct BaseGeometry {
  double wheel_radius_m = 0.0;        // [m] drive wheel radius
  double track_m = 0.0;               // [m] distance between the two wheels' contact points
  double ticks_per_revolution = 0.0;  // [ticks] encoder ticks per wheel revolution

  bool described() const { return wheel_radius_m > 0.0; }
  template <class A>
  void Serialize(A* a) {
    a->Visit("wheel_radius_m", &wheel_radius_m);
    a->Visit("track_m", &track_m);
    a->Visit("ticks_per_revolution", &ticks_per_revolution);
  }
  // All zero (not described) or all positive and finite.
  Status Validate() const;
};

struct RobotDescription {
  std::string name;   // e.g. "sim", "kitti", "turtlebot2"
  Mount laser;        // T_base_laser
  Mount camera;       // T_base_camera (left camera, optical frame)
  // T_base_laser3d: a multi-line (3D) laser, x forward, y left, z up (optional; the simulator's
  // laser3d, published on LASER_3D_TO_BASE). All zero: not described.
  Mount laser3d;
  BaseGeometry base;  // wheel geometry (optional)

  template <class A>
  void Serialize(A* a) {
    a->Visit("name", &name);
    a->Visit("laser", &laser);
    a->Visit("camera", &camera);
    a->Visit("laser3d", &laser3d);
    a->Visit("base", &base);
  }
  Status Validate() const;
};

// Loads config/robot/<robot>.yaml; throws fl::ConfigError naming the file, the key and the fix.
RobotDescription LoadRobotDescription(const std::string& path);

// R = Rz(yaw) Ry(pitch) Rx(roll) from degrees, with exact values at multiples of 90°.
Eigen::Matrix3d RotationFromRollPitchYawDeg(double roll_deg, double pitch_deg, double yaw_deg);

}  // namespace fl
