// Ceres cost functor of the VO refinement: stereo reprojection error of one point under a
// right-perturbed relative pose.
//
// Parameters: delta = [rho(3); phi(3)], the perturbation of a fixed linearisation point T0_a_b:
//     T_a_b(delta) = T0_a_b * [R(phi) | rho]            (R(phi): angle-axis rotation)
//     R_a_b = R0 R(phi),  t_a_b = R0 rho + t0.
// Direction kForward (point triangulated at a, observed at b):
//     p_b = T_a_b^-1 p_a = R(phi)^T (R0^T (p_a - t0) - rho) = R(-phi) (q - rho),
//     q = R0^T (p_a - t0) is precomputed.
// Direction kBackward (point triangulated at b, observed at a):
//     p_a = T_a_b p_b = R0 (R(phi) p_b + rho) + t0.
// Projection into the rectified pair (left camera frame, right camera at +baseline along x):
//     u_l = fx x/z + cx,  v = fy y/z + cy,  u_r = fx (x - baseline)/z + cx.
// Residual (3, [px]): (u_l, v, u_r) predicted - observed.
#pragma once

#include <ceres/autodiff_cost_function.h>
#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "fusionloc/stereo_vo/motion.hpp"

namespace fl::vo {

// The point p_a of frame a in frame b, T_a_b = T0_a_b [R(phi) | rho] (R0, t0: T0_a_b):
//     p_b = R(-phi) (R0^T (p_a - t0) - rho).
template <typename T>
void PointInFrameB(const Eigen::Matrix3d& R0, const Eigen::Vector3d& t0, const T* rho,
                   const T* phi, const T* p_a, T* p_b) {
  const T d[3] = {p_a[0] - T(t0(0)), p_a[1] - T(t0(1)), p_a[2] - T(t0(2))};
  T q_minus_rho[3];
  for (int i = 0; i < 3; ++i) {
    q_minus_rho[i] = T(R0(0, i)) * d[0] + T(R0(1, i)) * d[1] + T(R0(2, i)) * d[2] - rho[i];
  }
  const T minus_phi[3] = {-phi[0], -phi[1], -phi[2]};
  ceres::AngleAxisRotatePoint(minus_phi, q_minus_rho, p_b);
}

class StereoReprojectionCost {
 public:
  enum Direction { kForward, kBackward };

  StereoReprojectionCost(const StereoCamera& cam, const Eigen::Isometry3d& T0_a_b,
                         const Eigen::Vector3d& point, const Eigen::Vector3d& observed_uvu,
                         Direction direction)
      : cam_(cam),
        R0_(T0_a_b.linear()),
        t0_(T0_a_b.translation()),
        obs_(observed_uvu),
        direction_(direction) {
    // Forward: keep q = R0^T (p_a - t0); backward: keep p_b.
    point_ = direction == kForward ? Eigen::Vector3d(R0_.transpose() * (point - t0_)) : point;
  }

  template <typename T>
  bool operator()(const T* const delta, T* residual) const {
    const T* rho = delta;
    const T* phi = delta + 3;
    T p_cam[3];
    if (direction_ == kForward) {
      const T q_minus_rho[3] = {T(point_.x()) - rho[0], T(point_.y()) - rho[1],
                                T(point_.z()) - rho[2]};
      const T minus_phi[3] = {-phi[0], -phi[1], -phi[2]};
      ceres::AngleAxisRotatePoint(minus_phi, q_minus_rho, p_cam);
    } else {
      const T p_b[3] = {T(point_.x()), T(point_.y()), T(point_.z())};
      T r_p[3];
      ceres::AngleAxisRotatePoint(phi, p_b, r_p);
      const T s[3] = {r_p[0] + rho[0], r_p[1] + rho[1], r_p[2] + rho[2]};
      for (int i = 0; i < 3; ++i) {
        p_cam[i] = T(R0_(i, 0)) * s[0] + T(R0_(i, 1)) * s[1] + T(R0_(i, 2)) * s[2] + T(t0_(i));
      }
    }
    // Points behind the camera cannot be observed; keep the residual finite (Ceres rejects
    // steps that produce non-finite costs only if we report failure).
    if (!(p_cam[2] > T(1e-6))) return false;
    const T inv_z = T(1.0) / p_cam[2];
    residual[0] = T(cam_.fx) * p_cam[0] * inv_z + T(cam_.cx) - T(obs_(0));
    residual[1] = T(cam_.fy) * p_cam[1] * inv_z + T(cam_.cy) - T(obs_(1));
    residual[2] = T(cam_.fx) * (p_cam[0] - T(cam_.baseline)) * inv_z + T(cam_.cx) - T(obs_(2));
    return true;
  }

  static ceres::CostFunction* Create(const StereoCamera& cam, const Eigen::Isometry3d& T0_a_b,
                                     const Eigen::Vector3d& point,
                                     const Eigen::Vector3d& observed_uvu, Direction direction) {
    return new ceres::AutoDiffCostFunction<StereoReprojectionCost, 3, 6>(
        new StereoReprojectionCost(cam, T0_a_b, point, observed_uvu, direction));
  }

 private:
  StereoCamera cam_;
  Eigen::Matrix3d R0_;
  Eigen::Vector3d t0_;
  Eigen::Vector3d point_;
  Eigen::Vector3d obs_;
  Direction direction_;
};

// Joint (two-view bundle adjustment) form: the point is a parameter, p_a in frame a.
// View kViewA:  residual = project(p_a) - obs_a                       (parameters: p_a)
// View kViewB:  residual = project(R(-phi) (R0^T (p_a - t0) - rho)) - obs_b  (delta, p_a)
// Optimising the points removes the bias of fixed triangulated points (E[fb/d] > fb/E[d]
// makes fixed points too far and the estimated motion too long).
class StereoPointCostA {
 public:
  StereoPointCostA(const StereoCamera& cam, const Eigen::Vector3d& observed_uvu)
      : cam_(cam), obs_(observed_uvu) {}
  template <typename T>
  bool operator()(const T* const p_a, T* residual) const {
    if (!(p_a[2] > T(1e-6))) return false;
    const T inv_z = T(1.0) / p_a[2];
    residual[0] = T(cam_.fx) * p_a[0] * inv_z + T(cam_.cx) - T(obs_(0));
    residual[1] = T(cam_.fy) * p_a[1] * inv_z + T(cam_.cy) - T(obs_(1));
    residual[2] = T(cam_.fx) * (p_a[0] - T(cam_.baseline)) * inv_z + T(cam_.cx) - T(obs_(2));
    return true;
  }
  static ceres::CostFunction* Create(const StereoCamera& cam, const Eigen::Vector3d& obs) {
    return new ceres::AutoDiffCostFunction<StereoPointCostA, 3, 3>(new StereoPointCostA(cam, obs));
  }

 private:
  StereoCamera cam_;
  Eigen::Vector3d obs_;
};

class StereoPointCostB {
 public:
  StereoPointCostB(const StereoCamera& cam, const Eigen::Isometry3d& T0_a_b,
                   const Eigen::Vector3d& observed_uvu)
      : cam_(cam), R0_(T0_a_b.linear()), t0_(T0_a_b.translation()), obs_(observed_uvu) {}
  template <typename T>
  bool operator()(const T* const delta, const T* const p_a, T* residual) const {
    T p_b[3];
    PointInFrameB(R0_, t0_, delta, delta + 3, p_a, p_b);
    if (!(p_b[2] > T(1e-6))) return false;
    const T inv_z = T(1.0) / p_b[2];
    residual[0] = T(cam_.fx) * p_b[0] * inv_z + T(cam_.cx) - T(obs_(0));
    residual[1] = T(cam_.fy) * p_b[1] * inv_z + T(cam_.cy) - T(obs_(1));
    residual[2] = T(cam_.fx) * (p_b[0] - T(cam_.baseline)) * inv_z + T(cam_.cx) - T(obs_(2));
    return true;
  }
  static ceres::CostFunction* Create(const StereoCamera& cam, const Eigen::Isometry3d& T0_a_b,
                                     const Eigen::Vector3d& obs) {
    return new ceres::AutoDiffCostFunction<StereoPointCostB, 3, 6, 3>(
        new StereoPointCostB(cam, T0_a_b, obs));
  }

 private:
  StereoCamera cam_;
  Eigen::Matrix3d R0_;
  Eigen::Vector3d t0_;
  Eigen::Vector3d obs_;
};

// Applies a perturbation: T0 * [R(phi) | rho].
inline Eigen::Isometry3d ApplyDelta(const Eigen::Isometry3d& T0, const double delta[6]) {
  const Eigen::Vector3d phi(delta[3], delta[4], delta[5]);
  Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
  const double angle = phi.norm();
  if (angle > 1e-12) D.linear() = Eigen::AngleAxisd(angle, phi / angle).toRotationMatrix();
  D.translation() = Eigen::Vector3d(delta[0], delta[1], delta[2]);
  Eigen::Isometry3d T = T0 * D;
  // Re-orthonormalise to keep rounding from accumulating.
  const Eigen::Quaterniond q(T.linear());
  T.linear() = q.normalized().toRotationMatrix();
  return T;
}

}  // namespace fl::vo
