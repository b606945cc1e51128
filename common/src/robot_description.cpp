#include "fusionloc/common/robot_description.hpp"

#include <cmath>

#include "fusionloc/common/yaml_options.hpp"

namespace fl {
namespace {

// cos and sin of an angle in degrees; exact at multiples of 90°.
void CosSinDeg(double deg, double* c, double* s) {
  const double quarter = deg / 90.0;
  if (quarter == std::round(quarter)) {
    const long k = ((static_cast<long>(std::round(quarter)) % 4) + 4) % 4;
    static const double kCos[4] = {1.0, 0.0, -1.0, 0.0};
    static const double kSin[4] = {0.0, 1.0, 0.0, -1.0};
    *c = kCos[k];
    *s = kSin[k];
    return;
  }
  const double rad = deg * M_PI / 180.0;
  *c = std::cos(rad);
  *s = std::sin(rad);
}

Status CheckTriple(const std::vector<double>& v, const char* name) {
  if (v.size() != 3) {
    return Status::Error(std::string(name) + " must have 3 values, not " +
                         std::to_string(v.size()));
  }
  for (double x : v) {
    if (!std::isfinite(x)) return Status::Error(std::string(name) + " must be finite");
  }
  return Status::Ok();
}

}  // namespace

Eigen::Matrix3d RotationFromRollPitchYawDeg(double roll_deg, double pitch_deg, double yaw_deg) {
  double cr, sr, cp, sp, cy, sy;
  CosSinDeg(roll_deg, &cr, &sr);
  CosSinDeg(pitch_deg, &cp, &sp);
  CosSinDeg(yaw_deg, &cy, &sy);
  Eigen::Matrix3d Rx, Ry, Rz;
  Rx << 1, 0, 0, 0, cr, -sr, 0, sr, cr;
  Ry << cp, 0, sp, 0, 1, 0, -sp, 0, cp;
  Rz << cy, -sy, 0, sy, cy, 0, 0, 0, 1;
  return Rz * Ry * Rx;
}

Eigen::Isometry3d Mount::T_base_sensor() const {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = RotationFromRollPitchYawDeg(rpy_deg.at(0), rpy_deg.at(1), rpy_deg.at(2));
  T.translation() = Eigen::Vector3d(xyz_m.at(0), xyz_m.at(1), xyz_m.at(2));
  return T;
}

Status Mount::Validate() const {
  Status s = CheckTriple(xyz_m, "xyz_m");
  if (!s.ok()) return s;
  return CheckTriple(rpy_deg, "rpy_deg");
}

Status BaseGeometry::Validate() const {
  const bool none = wheel_radius_m == 0.0 && track_m == 0.0 && ticks_per_revolution == 0.0;
  if (none) return Status::Ok();
  if (!(wheel_radius_m > 0.0 && std::isfinite(wheel_radius_m)) ||
      !(track_m > 0.0 && std::isfinite(track_m)) ||
      !(ticks_per_revolution > 0.0 && std::isfinite(ticks_per_revolution))) {
    return Status::Error(
        "base: wheel_radius_m, track_m and ticks_per_revolution must all be > 0 (or all 0 for "
        "a robot without wheel encoders)");
  }
  return Status::Ok();
}

Status RobotDescription::Validate() const {
  if (name.empty()) return Status::Error("name must be set (e.g. name: sim)");
  Status s = laser.Validate();
  if (!s.ok()) return Status::Error("laser." + s.message());
  s = camera.Validate();
  if (!s.ok()) return Status::Error("camera." + s.message());
  s = laser3d.Validate();
  if (!s.ok()) return Status::Error("laser3d." + s.message());
  return base.Validate();
}

RobotDescription LoadRobotDescription(const std::string& path) {
  return LoadYamlFile<RobotDescription>(path);
}

}  // namespace fl
