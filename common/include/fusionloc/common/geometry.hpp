// SE(2) and SE(3) helpers on Eigen.
//
// Naming: T_a_b is the pose of frame b expressed in frame a, so p_a = T_a_b * p_b and
// T_a_c = T_a_b * T_b_c. Angles in radians, counter-clockwise; quaternions (w, x, y, z).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>

namespace fl {

// Wraps an angle to [-pi, pi).
inline double WrapAngle(double a) {
  a = std::fmod(a + M_PI, 2.0 * M_PI);
  if (a < 0) a += 2.0 * M_PI;
  return a - M_PI;
}

// A planar rigid transform (x, y, theta).
struct Pose2 {
  double x = 0.0;
  double y = 0.0;
  double theta = 0.0;

  Pose2() = default;
  Pose2(double x_in, double y_in, double theta_in) : x(x_in), y(y_in), theta(theta_in) {}

  Eigen::Vector2d translation() const { return {x, y}; }
  Eigen::Matrix2d rotation() const {
    const double c = std::cos(theta), s = std::sin(theta);
    Eigen::Matrix2d r;
    r << c, -s, s, c;
    return r;
  }
  Eigen::Vector3d vector() const { return {x, y, theta}; }

  // this * other
  Pose2 operator*(const Pose2& o) const {
    const double c = std::cos(theta), s = std::sin(theta);
    return Pose2(x + c * o.x - s * o.y, y + s * o.x + c * o.y, WrapAngle(theta + o.theta));
  }
  Eigen::Vector2d operator*(const Eigen::Vector2d& p) const {
    const double c = std::cos(theta), s = std::sin(theta);
    return {x + c * p.x() - s * p.y(), y + s * p.x() + c * p.y()};
  }
  Pose2 inverse() const {
    const double c = std::cos(theta), s = std::sin(theta);
    return Pose2(-c * x - s * y, s * x - c * y, WrapAngle(-theta));
  }
  // The relative transform this^-1 * other (other expressed in this frame).
  Pose2 between(const Pose2& other) const { return inverse() * other; }

  Eigen::Isometry2d isometry() const {
    Eigen::Isometry2d t = Eigen::Isometry2d::Identity();
    t.linear() = rotation();
    t.translation() = translation();
    return t;
  }
  static Pose2 FromIsometry(const Eigen::Isometry2d& t) {
    return Pose2(t.translation().x(), t.translation().y(),
                 std::atan2(t.linear()(1, 0), t.linear()(0, 0)));
  }

  // Embeds in SE(3) as a motion in the x-y plane about z.
  Eigen::Isometry3d ToIsometry3() const {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    t.translation() = Eigen::Vector3d(x, y, 0.0);
    return t;
  }
  // Projects an SE(3) transform onto the plane: x, y and the yaw of the rotated x axis.
  static Pose2 FromIsometry3(const Eigen::Isometry3d& t) {
    const Eigen::Vector3d xaxis = t.linear().col(0);
    return Pose2(t.translation().x(), t.translation().y(), std::atan2(xaxis.y(), xaxis.x()));
  }
};

// SE(2) exponential of a twist (vx, vy, omega) over unit time, and its logarithm.
inline Pose2 ExpSe2(double vx, double vy, double w) {
  if (std::fabs(w) < 1e-9) return Pose2(vx, vy, w);
  const double a = std::sin(w) / w, b = (1.0 - std::cos(w)) / w;
  return Pose2(a * vx - b * vy, b * vx + a * vy, w);
}
inline Eigen::Vector3d LogSe2(const Pose2& p) {
  const double w = p.theta;
  if (std::fabs(w) < 1e-9) return Eigen::Vector3d(p.x, p.y, w);
  const double a = std::sin(w) / w, b = (1.0 - std::cos(w)) / w;
  const double det = a * a + b * b;
  return Eigen::Vector3d((a * p.x + b * p.y) / det, (-b * p.x + a * p.y) / det, w);
}
// Pose at fraction alpha of the way from a to b along the constant-velocity (constant
// curvature) path: a * Exp(alpha * Log(a^-1 b)). Exact for arcs, unlike interpolating x, y.
inline Pose2 Interpolate(const Pose2& a, const Pose2& b, double alpha) {
  const Eigen::Vector3d twist = LogSe2(a.between(b));
  return a * ExpSe2(alpha * twist[0], alpha * twist[1], alpha * twist[2]);
}

// Builds an SE(3) transform from a translation and a (w, x, y, z) quaternion array.
inline Eigen::Isometry3d IsometryFromArrays(const double trans[3], const double quat_wxyz[4]) {
  Eigen::Quaterniond q(quat_wxyz[0], quat_wxyz[1], quat_wxyz[2], quat_wxyz[3]);
  q.normalize();
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = q.toRotationMatrix();
  t.translation() = Eigen::Vector3d(trans[0], trans[1], trans[2]);
  return t;
}

inline void IsometryToArrays(const Eigen::Isometry3d& t, double trans[3], double quat_wxyz[4]) {
  const Eigen::Quaterniond q(t.linear());
  trans[0] = t.translation().x();
  trans[1] = t.translation().y();
  trans[2] = t.translation().z();
  quat_wxyz[0] = q.w();
  quat_wxyz[1] = q.x();
  quat_wxyz[2] = q.y();
  quat_wxyz[3] = q.z();
}

// Roll, pitch, yaw (x, y, z fixed axes: R = Rz(yaw) Ry(pitch) Rx(roll)) of a rotation.
inline Eigen::Vector3d RollPitchYaw(const Eigen::Matrix3d& r) {
  const double pitch = std::asin(std::max(-1.0, std::min(1.0, -r(2, 0))));
  const double roll = std::atan2(r(2, 1), r(2, 2));
  const double yaw = std::atan2(r(1, 0), r(0, 0));
  return {roll, pitch, yaw};
}

inline Eigen::Matrix3d RotationFromRollPitchYaw(double roll, double pitch, double yaw) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

// The rotation nearest to a 3x3 matrix in the Frobenius norm (the rotation factor of its polar
// decomposition, det +1): U diag(1, 1, det(U Vᵀ)) Vᵀ from m = U S Vᵀ. It re-orthonormalises a
// rotation printed with few digits and gives the chordal mean of rotations from their sum.
inline Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& m) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

// Angle of a rotation matrix (geodesic distance to identity), in radians.
inline double RotationAngle(const Eigen::Matrix3d& r) {
  const double c = std::max(-1.0, std::min(1.0, 0.5 * (r.trace() - 1.0)));
  return std::acos(c);
}

}  // namespace fl
