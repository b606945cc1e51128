// Differential-drive odometry from the Kobuki's wrapping 16-bit encoder counters, and the
// velocity-command watchdog. No I/O, no LCM.
#pragma once

#include <cstdint>

#include "fusionloc/base/kobuki_protocol.hpp"
#include "fusionloc/common/robot_description.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::base {

// The base geometry odometry needs (fl::BaseGeometry from the robot description): all three
// positive, else the error naming the robot file's keys and the Kobuki's values.
fl::Status CheckOdometryGeometry(const fl::BaseGeometry& g);
// [m] wheel travel per encoder tick.
double MetresPerTick(const fl::BaseGeometry& g);
// The `base:` of a robot description (config/robot/<robot>.yaml), which must be described.
// Throws fl::ConfigError naming the file and the fix.
fl::BaseGeometry LoadBaseGeometry(const std::string& robot_path);

// One odometry sample (the fields of fusionloc.wheel_odometry_t). Odometry frame: the base
// frame at the first reading (x forward, y left), heading counter-clockwise in (-pi, pi].
struct OdometrySample {
  Utime utime = 0;           // [us] host time of the reading
  double x = 0.0;            // [m]
  double y = 0.0;            // [m]
  double theta = 0.0;        // [rad]
  double v = 0.0;            // [m/s] forward speed over the last reading interval
  double omega = 0.0;        // [rad/s] yaw rate over the last reading interval
  double left_ticks = 0.0;   // [ticks] cumulative (unwrapped) left count since the start
  double right_ticks = 0.0;  // [ticks] cumulative (unwrapped) right count since the start
};

// Integrates encoder readings: tick steps are taken modulo 65536 (WrapDelta16), so both
// forward and backward wrap-around are followed; each step is integrated as the exact arc
// (constant curvature between readings): with ds = (dl + dr) / 2, dth = (dr - dl) / track,
//   x += ds * sinc(dth / 2) * cos(theta + dth / 2),  y += ... sin(...),  theta += dth.
// Velocities use the robot's own millisecond clock (also wrapping) for the interval.
class WheelOdometry {
 public:
  struct Options {
    // [s] host-time gap between readings beyond which the tick step cannot be trusted (at
    // 0.7 m/s the Kobuki's counter wraps by half in about 2.8 s): the reference is reset,
    // the motion in the gap is lost, and it is counted in gaps().
    double max_gap_s = 1.0;
  };
  // `geometry` must pass CheckOdometryGeometry (std::invalid_argument otherwise).
  WheelOdometry(const BaseGeometry& geometry, const Options& options);

  // Adds a reading taken at host time `utime`. Returns false for the first reading (and the
  // first after a gap or Restart()), which only sets the reference; true with `out` filled
  // otherwise.
  bool Update(Utime utime, const kobuki::BasicSensorData& reading, OdometrySample* out);
  // The next reading sets a new reference (after a reconnect); the pose is kept.
  void Restart() { have_reference_ = false; }

  const OdometrySample& last() const { return last_; }
  int64_t gaps() const { return gaps_; }

 private:
  BaseGeometry geometry_;
  Options options_;
  bool have_reference_ = false;
  kobuki::BasicSensorData previous_;
  Utime previous_utime_ = 0;
  OdometrySample last_;
  int64_t gaps_ = 0;
};

// Stops the wheels when velocity commands stop: Current() is the last command while it is
// younger than timeout_s, and zero after.
class CommandWatchdog {
 public:
  explicit CommandWatchdog(double timeout_s) : timeout_us_(SecondsToUtime(timeout_s)) {}
  void Command(Utime now, double v, double omega);
  struct Velocity {
    double v = 0.0;      // [m/s]
    double omega = 0.0;  // [rad/s]
  };
  // `now` on the same clock as Command(). Counts each expiry once in timeouts().
  Velocity Current(Utime now);
  bool active(Utime now) const { return has_command_ && now - last_us_ <= timeout_us_; }
  int64_t timeouts() const { return timeouts_; }

 private:
  Utime timeout_us_;
  bool has_command_ = false;
  bool expired_reported_ = true;
  Utime last_us_ = 0;
  Velocity last_;
  int64_t timeouts_ = 0;
};

}  // namespace fl::base
