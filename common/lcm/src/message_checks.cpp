#include "fusionloc/common/message_checks.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace fl {
namespace {

bool Bad(double v) { return !(std::abs(v) <= kMaxFieldMagnitude); }  // NaN fails the test

std::string Text(const std::string& name, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), " = %g", v);
  return name + buf;
}

std::string Indexed(const std::string& name, size_t i) {
  return name + "[" + std::to_string(i) + "]";
}

// Collects the first bad field in order of the calls.
class FirstBad {
 public:
  FirstBad& Scalar(const char* name, double v) {
    if (found_.empty() && Bad(v)) found_ = Text(name, v);
    return *this;
  }
  template <class T>
  FirstBad& Array(const char* name, const T* values, size_t n) {
    for (size_t i = 0; i < n && found_.empty(); ++i) {
      if (Bad(static_cast<double>(values[i]))) found_ = Text(Indexed(name, i), values[i]);
    }
    return *this;
  }
  template <class T>
  FirstBad& Vector(const char* name, const std::vector<T>& values) {
    return Array(name, values.data(), values.size());
  }
  // A time stamp [us]: negative (before 1970) or beyond 2^61 us cannot come from a clock.
  FirstBad& Stamp(const char* name, int64_t t) {
    if (found_.empty() && (t < 0 || t >= kMaxStampUs))
      found_ = std::string(name) + " = " + std::to_string(t);
    return *this;
  }
  std::string result() const { return found_; }

 private:
  std::string found_;
};

}  // namespace

std::string BadField(const bot_core::planar_lidar_t& m) {
  return FirstBad().Scalar("rad0", m.rad0).Scalar("radstep", m.radstep).result();
}

std::string BadField(const bot_core::pose_t& m) {
  return FirstBad()
      .Array("pos", m.pos, 3)
      .Array("vel", m.vel, 3)
      .Array("orientation", m.orientation, 4)
      .Array("rotation_rate", m.rotation_rate, 3)
      .Array("accel", m.accel, 3)
      .result();
}

std::string BadField(const bot_core::rigid_transform_t& m) {
  return FirstBad()
      .Stamp("utime", m.utime)
      .Array("trans", m.trans, 3)
      .Array("quat", m.quat, 4)
      .result();
}

std::string BadField(const fusionloc::wheel_odometry_t& m) {
  return FirstBad()
      .Scalar("x", m.x)
      .Scalar("y", m.y)
      .Scalar("theta", m.theta)
      .Scalar("v", m.v)
      .Scalar("omega", m.omega)
      .Scalar("left_ticks", m.left_ticks)
      .Scalar("right_ticks", m.right_ticks)
      .result();
}

std::string BadField(const fusionloc::stereo_calibration_t& m) {
  return FirstBad()
      .Scalar("fx", m.fx)
      .Scalar("fy", m.fy)
      .Scalar("cx", m.cx)
      .Scalar("cy", m.cy)
      .Scalar("baseline", m.baseline)
      .result();
}

std::string BadField(const fusionloc::relative_pose_factor_t& m) {
  return FirstBad()
      .Array("trans", m.trans, 3)
      .Array("quat", m.quat, 4)
      .Array("information", m.information, 36)
      .result();
}

std::string BadField(const fusionloc::point_cloud_t& m) {
  for (size_t i = 0; i < m.points.size(); ++i) {
    for (size_t k = 0; k < m.points[i].size(); ++k) {
      if (Bad(m.points[i][k])) return Text(Indexed(Indexed("points", i), k), m.points[i][k]);
    }
  }
  return FirstBad().Vector("intensities", m.intensities).result();
}

std::string BadField(const fusionloc::fused_pose_t& m) {
  return FirstBad()
      .Scalar("x", m.x)
      .Scalar("y", m.y)
      .Scalar("theta", m.theta)
      .Array("covariance", m.covariance, 9)
      .result();
}

std::string BadField(const fusionloc::trajectory_t& m) {
  return FirstBad()
      .Vector("x", m.x)
      .Vector("y", m.y)
      .Vector("z", m.z)
      .Vector("theta", m.theta)
      .result();
}

}  // namespace fl
