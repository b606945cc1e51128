#include "fusionloc/base/odometry.hpp"

#include <cmath>
#include <stdexcept>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/robot_description.hpp"
#include "fusionloc/common/yaml_options.hpp"

namespace fl::base {

fl::Status CheckOdometryGeometry(const fl::BaseGeometry& g) {
  if (auto s = g.Validate(); !s.ok()) return s;
  const double wheel_radius_m = g.wheel_radius_m, track_m = g.track_m,
               ticks_per_revolution = g.ticks_per_revolution;
  if (!(wheel_radius_m > 0) || !(track_m > 0) || !(ticks_per_revolution > 0)) {
    return fl::Status::Error(
        "base geometry needs wheel_radius_m, track_m and ticks_per_revolution > 0 (got " +
        FormatDouble(wheel_radius_m) + ", " + FormatDouble(track_m) + ", " +
        FormatDouble(ticks_per_revolution) +
        "); the Kobuki's are 0.035 m, 0.230 m and 2578.33 ticks (config/robot/turtlebot2.yaml)");
  }
  return fl::Status::Ok();
}

double MetresPerTick(const fl::BaseGeometry& g) {
  return 2.0 * M_PI * g.wheel_radius_m / g.ticks_per_revolution;
}

fl::BaseGeometry LoadBaseGeometry(const std::string& robot_path) {
  const fl::BaseGeometry g = LoadRobotDescription(robot_path).base;
  if (auto s = CheckOdometryGeometry(g); !s.ok()) {
    throw ConfigError(robot_path + ": base: " + s.message());
  }
  return g;
}

WheelOdometry::WheelOdometry(const BaseGeometry& geometry, const Options& options)
    : geometry_(geometry), options_(options) {
  if (auto s = CheckOdometryGeometry(geometry_); !s.ok()) throw std::invalid_argument(s.message());
}

bool WheelOdometry::Update(Utime utime, const kobuki::BasicSensorData& r, OdometrySample* out) {
  if (have_reference_ && utime - previous_utime_ > SecondsToUtime(options_.max_gap_s)) {
    ++gaps_;
    have_reference_ = false;
  }
  if (!have_reference_) {
    have_reference_ = true;
    previous_ = r;
    previous_utime_ = utime;
    last_.utime = utime;
    last_.v = last_.omega = 0.0;
    return false;
  }
  const int32_t dl_ticks = kobuki::WrapDelta16(previous_.left_encoder, r.left_encoder);
  const int32_t dr_ticks = kobuki::WrapDelta16(previous_.right_encoder, r.right_encoder);
  const int32_t dt_ms = kobuki::WrapDelta16(previous_.timestamp_ms, r.timestamp_ms);
  const double m_per_tick = MetresPerTick(geometry_);
  const double dl = dl_ticks * m_per_tick, dr = dr_ticks * m_per_tick;
  const double ds = 0.5 * (dl + dr);
  const double dth = (dr - dl) / geometry_.track_m;
  const double half = 0.5 * dth;
  const double sinc = std::abs(half) < 1e-9 ? 1.0 - half * half / 6.0 : std::sin(half) / half;
  last_.x += ds * sinc * std::cos(last_.theta + half);
  last_.y += ds * sinc * std::sin(last_.theta + half);
  last_.theta = WrapAngle(last_.theta + dth);
  last_.left_ticks += dl_ticks;
  last_.right_ticks += dr_ticks;
  if (dt_ms > 0) {  // a repeated robot time stamp keeps the previous velocities
    last_.v = ds / (dt_ms * 1e-3);
    last_.omega = dth / (dt_ms * 1e-3);
  }
  last_.utime = utime;
  previous_ = r;
  previous_utime_ = utime;
  *out = last_;
  return true;
}

void CommandWatchdog::Command(Utime now, double v, double omega) {
  has_command_ = true;
  expired_reported_ = false;
  last_us_ = now;
  last_ = {v, omega};
}

CommandWatchdog::Velocity CommandWatchdog::Current(Utime now) {
  if (active(now)) return last_;
  if (has_command_ && !expired_reported_) {
    expired_reported_ = true;
    ++timeouts_;
  }
  return {};
}

}  // namespace fl::base
