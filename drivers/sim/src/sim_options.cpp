#include "fusionloc/sim/sim_options.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace fl::sim {
namespace {

// Small helper so every message names the key, the value and the allowed range.
class Checker {
 public:
  explicit Checker(std::string prefix) : prefix_(std::move(prefix)) {}
  void Range(const char* key, double v, double lo, double hi, const char* unit = "") {
    if (!error_.empty()) return;
    if (!std::isfinite(v) || v < lo || v > hi) {
      std::ostringstream s;
      s << prefix_ << key << " = " << v << " is out of range; use a value in [" << lo << ", "
        << hi << "]" << unit;
      error_ = s.str();
    }
  }
  void Positive(const char* key, double v, const char* unit = "") {
    if (!error_.empty()) return;
    if (!std::isfinite(v) || v <= 0.0) {
      std::ostringstream s;
      s << prefix_ << key << " = " << v << " must be positive" << unit;
      error_ = s.str();
    }
  }
  void NonNegative(const char* key, double v) {
    if (!error_.empty()) return;
    if (!std::isfinite(v) || v < 0.0) {
      std::ostringstream s;
      s << prefix_ << key << " = " << v << " must be >= 0 (0 disables this noise)";
      error_ = s.str();
    }
  }
  void Fail(const std::string& message) {
    if (error_.empty()) error_ = prefix_ + message;
  }
  Status status() const { return error_.empty() ? Status::Ok() : Status::Error(error_); }

 private:
  std::string prefix_;
  std::string error_;
};

}  // namespace

Status WorldOptions::Validate() const {
  Checker c("world.");
  if (name != "paper" && name != "corridor") {
    c.Fail("name = '" + name + "' is not a known world; use 'paper' or 'corridor'");
  }
  c.Range("landmarks", landmarks, 0, 1000);
  c.Range("route_clearance_m", route_clearance_m, 0.8, 5.0, " m (the robot must keep 0.5 m)");
  c.Range("wall_height_m", wall_height_m, 1.0, 10.0, " m");
  c.Range("corridor_length_m", corridor_length_m, 40.0, 200.0, " m");
  c.Range("corridor_width_m", corridor_width_m, 2.0, 5.0, " m");
  return c.status();
}

Status RobotOptions::Validate() const {
  Checker c("robot.");
  c.Range("max_speed_mps", max_speed_mps, 0.05, 3.0, " m/s");
  c.Range("max_yaw_rate_rps", max_yaw_rate_rps, 0.1, 5.0, " rad/s");
  c.Range("max_accel_mps2", max_accel_mps2, 0.05, 10.0, " m/s^2");
  c.Range("max_yaw_accel_rps2", max_yaw_accel_rps2, 0.1, 20.0, " rad/s^2");
  c.Range("lookahead_m", lookahead_m, 0.2, 3.0, " m");
  c.Positive("wheel_base_m", wheel_base_m, " m");
  c.Positive("wheel_radius_m", wheel_radius_m, " m");
  c.Positive("ticks_per_rev", ticks_per_rev);
  return c.status();
}

Status OdometryOptions::Validate() const {
  Checker c("odometry.");
  c.Positive("rate_hz", rate_hz, " Hz");
  c.NonNegative("trans_sigma_m_per_sqrt_m", trans_sigma_m_per_sqrt_m);
  c.NonNegative("lateral_sigma_m_per_sqrt_m", lateral_sigma_m_per_sqrt_m);
  c.NonNegative("yaw_sigma_rad_per_sqrt_rad", yaw_sigma_rad_per_sqrt_rad);
  c.NonNegative("yaw_sigma_rad_per_sqrt_m", yaw_sigma_rad_per_sqrt_m);
  return c.status();
}

Status LaserOptions::Validate() const {
  Checker c("laser.");
  c.Positive("rate_hz", rate_hz, " Hz");
  c.NonNegative("range_sigma_m", range_sigma_m);
  c.Range("min_range_m", min_range_m, 0.0, 1.0, " m");
  c.Range("max_range_m", max_range_m, 0.5, 100.0, " m");
  if (max_range_m <= min_range_m) c.Fail("max_range_m must be greater than min_range_m");
  c.Range("beams", beams, 1, 10000);
  c.Range("step_deg", step_deg, 0.01, 10.0, " deg");
  c.Range("first_angle_deg", first_angle_deg, -180.0, 180.0, " deg");
  if (beams >= 1 && (beams - 1) * step_deg > 360.0) {
    c.Fail("beams * step_deg covers more than 360 deg; reduce beams or step_deg");
  }
  c.Range("x_m", x_m, -2.0, 2.0, " m");
  c.Range("y_m", y_m, -2.0, 2.0, " m");
  c.Range("z_m", z_m, 0.05, 0.5,
          " m (scan plane must lie below the lowest obstacle top, 0.5 m)");
  return c.status();
}

Status Laser3dOptions::Validate() const {
  Checker c("laser3d.");
  c.Positive("rate_hz", rate_hz, " Hz");
  c.Range("lines", lines, 1, 128);
  c.Range("vertical_fov_deg", vertical_fov_deg, 0.0, 90.0, " deg");
  c.Range("azimuth_step_deg", azimuth_step_deg, 0.05, 10.0, " deg");
  c.Range("range_sigma_m", range_sigma_m, 0.0, 1.0, " m");
  c.Range("min_range_m", min_range_m, 0.0, 5.0, " m");
  c.Range("max_range_m", max_range_m, min_range_m + 0.1, 200.0, " m");
  if (enabled) {
    c.Range("x_m", x_m, -2.0, 2.0, " m");
    c.Range("y_m", y_m, -2.0, 2.0, " m");
    c.Range("z_m", z_m, 0.1, 2.4,
            " m (the robot description's laser3d.xyz_m: above the floor, below the walls' top)");
  }
  return c.status();
}

Status CameraOptions::Validate() const {
  Checker c("camera.");
  c.Positive("rate_hz", rate_hz, " Hz");
  c.Range("width", width, 16, 4096, " px");
  c.Range("height", height, 16, 4096, " px");
  c.Range("fx", fx, 10.0, 10000.0, " px");
  c.Range("cx", cx, 0.0, width - 1.0, " px (inside the image)");
  c.Range("cy", cy, 0.0, height - 1.0, " px (inside the image)");
  c.Range("baseline_m", baseline_m, 0.01, 2.0, " m");
  c.Range("x_m", x_m, -2.0, 2.0, " m");
  c.Range("y_m", y_m, -2.0, 2.0, " m");
  c.Range("z_m", z_m, 0.1, 2.0, " m (must be above the floor and below the walls' top)");
  c.Range("pixel_noise_sigma", pixel_noise_sigma, 0.0, 64.0, " gray levels");
  c.Range("supersampling", supersampling, 1, 4);
  return c.status();
}

Status SimOptions::SetMounting(const RobotDescription& robot) {
  const std::vector<double> level{0.0, 0.0, 0.0}, optical{-90.0, 0.0, -90.0};
  if (robot.laser.rpy_deg != level) {
    return Status::Error("robot '" + robot.name +
                         "': laser.rpy_deg must be [0, 0, 0] for the simulator (it models a "
                         "level laser whose 0 rad beam points along base x)");
  }
  if (robot.camera.rpy_deg != optical) {
    return Status::Error("robot '" + robot.name +
                         "': camera.rpy_deg must be [-90, 0, -90] for the simulator (it renders "
                         "a level camera looking along base x)");
  }
  if (robot.laser3d.rpy_deg != level) {
    return Status::Error("robot '" + robot.name +
                         "': laser3d.rpy_deg must be [0, 0, 0] for the simulator (it models a "
                         "level multi-line laser)");
  }
  const auto position = [](const Mount& m, double* x, double* y, double* z) {
    *x = m.xyz_m.at(0);
    *y = m.xyz_m.at(1);
    *z = m.xyz_m.at(2);
  };
  position(robot.laser, &laser.x_m, &laser.y_m, &laser.z_m);
  position(robot.camera, &camera.x_m, &camera.y_m, &camera.z_m);
  position(robot.laser3d, &laser3d.x_m, &laser3d.y_m, &laser3d.z_m);
  return Validate();
}

Status SimOptions::Validate() const {
  for (const Status& s : {world.Validate(), robot.Validate(), odometry.Validate(),
                          laser.Validate(), camera.Validate(), laser3d.Validate()}) {
    if (!s.ok()) return s;
  }
  Checker c("");
  c.Range("seed", static_cast<double>(seed), 0.0, 9.0e18);
  c.Range("step_s", step_s, 0.001, 1.0, " s");
  c.Range("duration_s", duration_s, step_s, 1.0e6, " s");
  c.Range("start_utime", static_cast<double>(start_utime), 0.0, 4.0e18, " us");
  c.Range("calibration_period_s", calibration_period_s, step_s, 3600.0, " s");
  if (camera.z_m >= world.wall_height_m) c.Fail("camera.z_m must be below world.wall_height_m");
  if (!c.status().ok()) return c.status();
  struct Rate {
    const char* key;
    double hz;
  };
  for (const Rate& r : {Rate{"odometry.rate_hz", odometry.rate_hz},
                        Rate{"laser.rate_hz", laser.rate_hz},
                        Rate{"camera.rate_hz", camera.rate_hz},
                        Rate{"laser3d.rate_hz", laser3d.rate_hz},
                        Rate{"calibration_period_s (as a rate)", 1.0 / calibration_period_s}}) {
    const double period = 1.0 / (r.hz * step_s);
    if (period < 0.999999 || std::fabs(period - std::round(period)) > 1e-6) {
      std::ostringstream s;
      s << r.key << " = " << r.hz << " Hz does not divide the step rate " << 1.0 / step_s
        << " Hz; use step_rate / n (e.g. " << 1.0 / step_s << ", " << 0.5 / step_s << ", "
        << 0.2 / step_s << " Hz)";
      return Status::Error(s.str());
    }
  }
  return Status::Ok();
}

int64_t SimOptions::steps() const {
  return static_cast<int64_t>(std::llround(duration_s / step_s));
}

int64_t SimOptions::PeriodSteps(double rate_hz) const {
  return std::max<int64_t>(1, std::llround(1.0 / (rate_hz * step_s)));
}

SimOptions DefaultOptionsForWorld(const std::string& world) {
  SimOptions o;
  if (world == "paper") return o;
  if (world == "corridor") {
    o.world.name = "corridor";
    o.duration_s = 240.0;
    return o;
  }
  throw std::invalid_argument("unknown world '" + world + "'; use 'paper' or 'corridor'");
}

}  // namespace fl::sim
