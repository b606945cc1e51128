// Options of the simulator (fl::sim::Simulator, fl-sim). Every default is the MSIF paper's
// simulation setting unless noted; docs/SIMULATOR.md explains the models behind each field.
// YAML: config/sim_paper.yaml, config/sim_corridor.yaml.
#pragma once

#include <cstdint>
#include <string>

#include "fusionloc/common/robot_description.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::sim {

// Which world to build and how to populate it.
struct WorldOptions {
  std::string name = "paper";     // "paper" (30 m x 30 m, random landmarks) or "corridor"
  int landmarks = 30;             // [count] paper: random pillars and boxes (0..1000)
  double route_clearance_m = 1.5; // [m] paper: min distance from a landmark to the route line
  double wall_height_m = 2.5;     // [m] height of walls (corridor: also the ceiling height)
  double corridor_length_m = 60.0;  // [m] corridor: length of the main corridor (>= 40)
  double corridor_width_m = 2.5;    // [m] corridor: width of the main corridor (2..5)

  template <class A>
  void Serialize(A* a) {
    a->Visit("name", &name);
    a->Visit("landmarks", &landmarks);
    a->Visit("route_clearance_m", &route_clearance_m);
    a->Visit("wall_height_m", &wall_height_m);
    a->Visit("corridor_length_m", &corridor_length_m);
    a->Visit("corridor_width_m", &corridor_width_m);
  }
  Status Validate() const;
};

// The two-wheel differential-drive robot and its route follower (pure pursuit).
struct RobotOptions {
  double max_speed_mps = 0.7;        // [m/s] cruise speed on straight stretches
  double max_yaw_rate_rps = 0.8;     // [rad/s] yaw-rate limit
  double max_accel_mps2 = 0.5;       // [m/s^2] linear acceleration limit (smooth v)
  double max_yaw_accel_rps2 = 1.5;   // [rad/s^2] yaw acceleration limit (smooth omega)
  double lookahead_m = 0.8;          // [m] pure-pursuit look-ahead distance on the route
  double wheel_base_m = 0.4;         // [m] distance between the wheels (for encoder ticks)
  double wheel_radius_m = 0.1;       // [m] wheel radius (for encoder ticks)
  double ticks_per_rev = 2048.0;     // [ticks] encoder resolution

  template <class A>
  void Serialize(A* a) {
    a->Visit("max_speed_mps", &max_speed_mps);
    a->Visit("max_yaw_rate_rps", &max_yaw_rate_rps);
    a->Visit("max_accel_mps2", &max_accel_mps2);
    a->Visit("max_yaw_accel_rps2", &max_yaw_accel_rps2);
    a->Visit("lookahead_m", &lookahead_m);
    a->Visit("wheel_base_m", &wheel_base_m);
    a->Visit("wheel_radius_m", &wheel_radius_m);
    a->Visit("ticks_per_rev", &ticks_per_rev);
  }
  Status Validate() const;
};

// Wheel-odometry noise, a random walk in distance travelled (docs/SIMULATOR.md):
// per step with true base-frame increment (dd forward, dth yaw),
//   forward += N(0, trans_sigma^2 * |dd|), lateral += N(0, lateral_sigma^2 * |dd|),
//   yaw     += N(0, yaw_sigma_per_rad^2 * |dth| + yaw_sigma_per_m^2 * |dd|).
// So after 1 m straight the forward error has sigma 0.05 m ("odometry error 0.05 m").
struct OdometryOptions {
  double rate_hz = 10.0;                      // [Hz] must divide the step rate
  double trans_sigma_m_per_sqrt_m = 0.05;     // [m/sqrt(m)] forward error per sqrt(metre)
  double lateral_sigma_m_per_sqrt_m = 0.01;   // [m/sqrt(m)] sideways slip per sqrt(metre)
  double yaw_sigma_rad_per_sqrt_rad = 0.02;   // [rad/sqrt(rad)] heading error per sqrt(rad turned)
  double yaw_sigma_rad_per_sqrt_m = 0.005;    // [rad/sqrt(m)] heading drift per sqrt(metre)

  template <class A>
  void Serialize(A* a) {
    a->Visit("rate_hz", &rate_hz);
    a->Visit("trans_sigma_m_per_sqrt_m", &trans_sigma_m_per_sqrt_m);
    a->Visit("lateral_sigma_m_per_sqrt_m", &lateral_sigma_m_per_sqrt_m);
    a->Visit("yaw_sigma_rad_per_sqrt_rad", &yaw_sigma_rad_per_sqrt_rad);
    a->Visit("yaw_sigma_rad_per_sqrt_m", &yaw_sigma_rad_per_sqrt_m);
  }
  Status Validate() const;
};

// Single-line laser, geometry of a Hokuyo URG-04LX (240 deg, 0.352 deg step, 682 beams).
struct LaserOptions {
  bool enabled = true;           // publish LASER and LASER_TO_BASE
  double rate_hz = 10.0;         // [Hz] must divide the step rate
  double range_sigma_m = 0.1;    // [m] Gaussian range noise
  double max_range_m = 10.0;     // [m] no return beyond (published as range 0)
  double min_range_m = 0.02;     // [m] no return closer than this
  double first_angle_deg = -120.0;  // [deg] angle of beam 0, CCW from laser x
  double step_deg = 0.352;          // [deg] angle between beams
  int beams = 682;                  // [count]
  // Mounting: not in the world file but in the robot description (config/robot/sim.yaml),
  // set by SimOptions::SetMounting; these defaults are that file's values.
  double x_m = 0.15;  // [m] laser position in the base frame (x forward)
  double y_m = 0.0;   // [m] (y left)
  double z_m = 0.3;   // [m] (z up) scan-plane height; obstacles are all taller than 0.5 m

  template <class A>
  void Serialize(A* a) {
    a->Visit("enabled", &enabled);
    a->Visit("rate_hz", &rate_hz);
    a->Visit("range_sigma_m", &range_sigma_m);
    a->Visit("max_range_m", &max_range_m);
    a->Visit("min_range_m", &min_range_m);
    a->Visit("first_angle_deg", &first_angle_deg);
    a->Visit("step_deg", &step_deg);
    a->Visit("beams", &beams);
  }
  Status Validate() const;
};

// Multi-line (3D) laser, VLP-16-like, for the stereo VO's laser-aided mode: `lines` scan
// lines evenly over [-vertical_fov/2, +vertical_fov/2] (elevation), a full turn in azimuth at
// azimuth_step_deg, the whole scan at one instant (no motion skew). Points in the scanner's
// frame (x forward, y left, z up) on LASER_3D, its mounting on LASER_3D_TO_BASE. Off by
// default (bench sim's laser-aided runs turn it on).
struct Laser3dOptions {
  bool enabled = false;            // publish LASER_3D and LASER_3D_TO_BASE
  double rate_hz = 10.0;           // [Hz] must divide the step rate
  int lines = 16;                  // [count] scan lines
  double vertical_fov_deg = 30.0;  // [deg] from the lowest to the highest line
  double azimuth_step_deg = 0.4;   // [deg] between the points of a line (900 per turn)
  double range_sigma_m = 0.03;     // [m] Gaussian range noise (along the beam)
  double min_range_m = 0.5;        // [m] no return closer (the robot itself)
  double max_range_m = 40.0;       // [m] no return beyond
  // Mounting, from the robot description's laser3d (SimOptions::SetMounting; level only).
  double x_m = 0.1;  // [m] in the base frame
  double y_m = 0.0;  // [m]
  double z_m = 0.9;  // [m]

  template <class A>
  void Serialize(A* a) {
    a->Visit("enabled", &enabled);
    a->Visit("rate_hz", &rate_hz);
    a->Visit("lines", &lines);
    a->Visit("vertical_fov_deg", &vertical_fov_deg);
    a->Visit("azimuth_step_deg", &azimuth_step_deg);
    a->Visit("range_sigma_m", &range_sigma_m);
    a->Visit("min_range_m", &min_range_m);
    a->Visit("max_range_m", &max_range_m);
  }
  Status Validate() const;
};

// Rectified stereo pair (Bumblebee2-like), rendered by ray casting; the optical axis is level
// and points along base x. Left camera pose in the base frame: (x_m, y_m, z_m) from the robot
// description; the right camera is `baseline_m` to its right.
struct CameraOptions {
  bool enabled = true;         // publish STEREO, STEREO_CALIBRATION and CAMERA_TO_BASE
  // [Hz] must divide the step rate. 10: the rate real stereo cameras run at (the MSIF paper's
  // 2 Hz is an option: fl-sim --camera-rate-hz 2, with fl-stereo-vo on config/stereo_vo_2hz.yaml).
  double rate_hz = 10.0;
  int width = 640;             // [px]
  int height = 480;            // [px]
  double fx = 400.0;           // [px] focal length (fx = fy)
  double cx = 319.5;           // [px] principal point
  double cy = 239.5;           // [px]
  double baseline_m = 0.12;    // [m]
  // Mounting, from the robot description (SimOptions::SetMounting; defaults = config/robot/sim.yaml)
  double x_m = 0.2;            // [m] left camera position in the base frame
  double y_m = 0.06;           // [m]
  double z_m = 0.5;            // [m]
  double pixel_noise_sigma = 8.0;  // [gray levels] Gaussian intensity noise (calibrated: SIMULATOR.md)
  int supersampling = 2;       // [-] n x n rays per pixel (anti-aliasing; 1 = one ray)

  template <class A>
  void Serialize(A* a) {
    a->Visit("enabled", &enabled);
    a->Visit("rate_hz", &rate_hz);
    a->Visit("width", &width);
    a->Visit("height", &height);
    a->Visit("fx", &fx);
    a->Visit("cx", &cx);
    a->Visit("cy", &cy);
    a->Visit("baseline_m", &baseline_m);
    a->Visit("pixel_noise_sigma", &pixel_noise_sigma);
    a->Visit("supersampling", &supersampling);
  }
  Status Validate() const;
};

struct SimOptions {
  int64_t seed = 1;                       // [-] random seed (world layout and all noise), >= 0
  double duration_s = 100.0;              // [s] simulated time (paper: 1000 steps of 0.1 s)
  double step_s = 0.1;                    // [s] simulation step (ground truth and odometry)
  int64_t start_utime = 1000000000000000; // [us] time stamp of step 0
  double calibration_period_s = 1.0;      // [s] STEREO_CALIBRATION, LASER_TO_BASE, CAMERA_TO_BASE repeat period
  WorldOptions world;
  RobotOptions robot;
  OdometryOptions odometry;
  LaserOptions laser;
  CameraOptions camera;
  Laser3dOptions laser3d;

  template <class A>
  void Serialize(A* a) {
    a->Visit("seed", &seed);
    a->Visit("duration_s", &duration_s);
    a->Visit("step_s", &step_s);
    a->Visit("start_utime", &start_utime);
    a->Visit("calibration_period_s", &calibration_period_s);
    a->Visit("world", &world);
    a->Visit("robot", &robot);
    a->Visit("odometry", &odometry);
    a->Visit("laser", &laser);
    a->Visit("camera", &camera);
    a->Visit("laser3d", &laser3d);
  }
  // Takes the laser's and the camera's mounting from a robot description
  // (config/robot/sim.yaml). The simulator models a level laser and a level camera looking
  // along base x: other rotations are an error naming the key.
  Status SetMounting(const RobotDescription& robot);
  Status Validate() const;

  // Number of motion steps (duration / step, rounded); the simulator emits steps + 1 frames.
  int64_t steps() const;
  // Steps between two messages of a stream at `rate_hz` (rate must divide the step rate).
  int64_t PeriodSteps(double rate_hz) const;
};

// Defaults for a named world ("paper" or "corridor"): the corridor world drives a longer
// route and so defaults to a longer duration. Throws std::invalid_argument for other names.
SimOptions DefaultOptionsForWorld(const std::string& world);

}  // namespace fl::sim
