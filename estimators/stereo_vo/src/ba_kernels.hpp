// The pieces both analytic bundle adjustments share (the two-view refinement in motion.cpp,
// the keyframe window in local_ba.cpp): the rectified stereo projection residual and its
// Jacobian, the skew matrix of the pose Jacobian, and the Huber loss as Ceres applies it to a
// residual block (IRLS weight rho'(s), no second-order correction: rho'' <= 0).
//
//   pi(p) = (fx x/z + cx, fy y/z + cy, fx (x - b)/z + cx)
//   d pi / d p = [fx/z 0 -fx x/z^2; 0 fy/z -fy y/z^2; fx/z 0 -fx (x - b)/z^2]
//   Huber(h): rho(s) = s (s <= h^2), 2 h sqrt(s) - h^2 otherwise; rho'(s) = 1 or h / sqrt(s).
// Private to the stereo VO library (not installed).
#pragma once

#include <Eigen/Core>
#include <cmath>

#include "fusionloc/stereo_vo/motion.hpp"

namespace fl::vo::ba {

inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

// pi(p) - obs [px]; false if the point is not in front of the camera (z <= 1e-6).
inline bool StereoResidual(const StereoCamera& cam, const Eigen::Vector3d& p,
                           const Eigen::Vector3d& obs, Eigen::Vector3d* r) {
  if (!(p.z() > 1e-6)) return false;
  const double iz = 1.0 / p.z();
  (*r)(0) = cam.fx * p.x() * iz + cam.cx - obs(0);
  (*r)(1) = cam.fy * p.y() * iz + cam.cy - obs(1);
  (*r)(2) = cam.fx * (p.x() - cam.baseline) * iz + cam.cx - obs(2);
  return true;
}

inline Eigen::Matrix3d StereoProjectionJacobian(const StereoCamera& cam, const Eigen::Vector3d& p) {
  const double iz = 1.0 / p.z(), iz2 = iz * iz;
  Eigen::Matrix3d J;
  J << cam.fx * iz, 0, -cam.fx * p.x() * iz2,  //
      0, cam.fy * iz, -cam.fy * p.y() * iz2,    //
      cam.fx * iz, 0, -cam.fx * (p.x() - cam.baseline) * iz2;
  return J;
}

struct Huber {
  double width = 1.0;  // h [same unit as the residual]
  double Rho(double s) const {
    const double h2 = width * width;
    return s <= h2 ? s : 2.0 * width * std::sqrt(s) - h2;
  }
  double Weight(double s) const {
    const double h2 = width * width;
    return s <= h2 ? 1.0 : width / std::sqrt(s);
  }
};

}  // namespace fl::vo::ba
