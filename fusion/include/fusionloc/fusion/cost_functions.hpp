// Ceres cost functors of the fusion back-end: SE(2) prior, SE(3) between. The SE(2) between
// factor (laser eqs. 13-15, vision eqs. 17-19 reduced to the plane, wheel odometry) is
// fl::Se2BetweenCost (fusionloc/common/se2_between_cost.hpp), shared with the RBPF.
//
// Every factor's cost is d(e) = e^T Omega e (MSIF eqs. 11-12) written as a least-squares
// residual r = S e with S^T S = Omega, so that Ceres' 1/2 |r|^2 = 1/2 d(e); S comes from
// fl::SqrtInformation (fusionloc/common/sqrt_information.hpp, which also explains the
// SqrtConvention the g2o benchmark uses to reproduce Ceres' example costs).
#pragma once

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

#include "fusionloc/common/se2_between_cost.hpp"
#include "fusionloc/common/sqrt_information.hpp"

namespace fl::fusion {

// Wraps an angle to [-pi, pi), also for Jets (same formula as Ceres' NormalizeAngle).
template <typename T>
T NormalizeAngle(const T& angle) {
  using std::floor;
  const T two_pi(2.0 * M_PI);
  return angle - two_pi * floor((angle + T(M_PI)) / two_pi);
}

// Manifold of an SE(2) parameter block [x, y, theta]: Euclidean in x, y, the angle wrapped
// to [-pi, pi) after every step (Ceres' AngleManifold for the third coordinate).
class Pose2Manifold final : public ceres::Manifold {
 public:
  int AmbientSize() const override { return 3; }
  int TangentSize() const override { return 3; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    x_plus_delta[0] = x[0] + delta[0];
    x_plus_delta[1] = x[1] + delta[1];
    x_plus_delta[2] = NormalizeAngle(x[2] + delta[2]);
    return true;
  }
  bool PlusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> jac(jacobian);
    jac.setIdentity();
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    y_minus_x[0] = y[0] - x[0];
    y_minus_x[1] = y[1] - x[1];
    y_minus_x[2] = NormalizeAngle(y[2] - x[2]);
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> jac(jacobian);
    jac.setIdentity();
    return true;
  }
};

// SE(2) prior factor on one pose (the first pose of the graph, fixing the gauge).
//   e = [ p - p_prior ; Normalize(theta - theta_prior) ],  r = S e,  dr/dpose = S.
class Se2PriorCost final : public ceres::SizedCostFunction<3, 3> {
 public:
  Se2PriorCost(const Eigen::Vector3d& T_map_prior, const Eigen::Matrix3d& sqrt_information)
      : T_map_prior_(T_map_prior), sqrt_information_(sqrt_information) {}

  static ceres::CostFunction* Create(const Eigen::Vector3d& T_map_prior,
                                     const Eigen::Matrix3d& sqrt_information) {
    return new Se2PriorCost(T_map_prior, sqrt_information);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double* p = parameters[0];
    const Eigen::Vector3d e(p[0] - T_map_prior_[0], p[1] - T_map_prior_[1],
                            NormalizeAngle(p[2] - T_map_prior_[2]));
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r = sqrt_information_ * e;
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> jac(jacobians[0]);
      jac = sqrt_information_;
    }
    return true;
  }

 private:
  Eigen::Vector3d T_map_prior_;
  Eigen::Matrix3d sqrt_information_;
};

// SE(3) between factor (for 3D pose graphs, VERTEX_SE3:QUAT / EDGE_SE3:QUAT).
// Parameter blocks: p_i (3), q_i (4, Eigen order x y z w, unit, EigenQuaternionManifold),
// p_j (3), q_j (4). Measurement T_i_j = (p_ij, q_ij).
//
//   q_ij_est = q_i^-1 q_j,   p_ij_est = q_i^-1 (p_j - p_i)
//   dq = q_ij * q_ij_est^-1
//   e = [ p_ij_est - p_ij ; 2 vec(dq) ]   (metres in frame i; ~radians for small errors)
//   r = S e,  S^T S = Omega (6x6, order x y z rx ry rz)
//
// Jacobians by automatic differentiation.
class Se3BetweenCost {
 public:
  Se3BetweenCost(const Eigen::Vector3d& p_ij, const Eigen::Quaterniond& q_ij,
                 const Eigen::Matrix<double, 6, 6>& sqrt_information)
      : p_ij_(p_ij), q_ij_(q_ij.normalized()), sqrt_information_(sqrt_information) {}

  template <typename T>
  bool operator()(const T* const p_i_ptr, const T* const q_i_ptr, const T* const p_j_ptr,
                  const T* const q_j_ptr, T* residuals_ptr) const {
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_i(p_i_ptr);
    Eigen::Map<const Eigen::Quaternion<T>> q_i(q_i_ptr);
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_j(p_j_ptr);
    Eigen::Map<const Eigen::Quaternion<T>> q_j(q_j_ptr);
    const Eigen::Quaternion<T> q_i_inv = q_i.conjugate();
    const Eigen::Quaternion<T> q_ij_est = q_i_inv * q_j;
    const Eigen::Matrix<T, 3, 1> p_ij_est = q_i_inv * (p_j - p_i);
    const Eigen::Quaternion<T> dq = q_ij_.template cast<T>() * q_ij_est.conjugate();
    Eigen::Matrix<T, 6, 1> e;
    e.template head<3>() = p_ij_est - p_ij_.template cast<T>();
    e.template tail<3>() = T(2.0) * dq.vec();
    Eigen::Map<Eigen::Matrix<T, 6, 1>> r(residuals_ptr);
    r = sqrt_information_.template cast<T>() * e;
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& p_ij, const Eigen::Quaterniond& q_ij,
                                     const Eigen::Matrix<double, 6, 6>& sqrt_information) {
    return new ceres::AutoDiffCostFunction<Se3BetweenCost, 6, 3, 4, 3, 4>(
        new Se3BetweenCost(p_ij, q_ij, sqrt_information));
  }

  EIGEN_MAKE_ALIGNED_OPERATOR_NEW

 private:
  Eigen::Vector3d p_ij_;
  Eigen::Quaterniond q_ij_;
  Eigen::Matrix<double, 6, 6> sqrt_information_;
};

}  // namespace fl::fusion
