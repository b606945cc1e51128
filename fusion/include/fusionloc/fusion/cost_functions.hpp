// Ceres cost functors of the fusion back-end: SE(2) prior. The SE(2) and SE(3) between
// factor (laser eqs. 13-15, vision eqs. 17-19 reduced to the plane, wheel odometry) is
// fl::Se2BetweenCost and fl::Se3BetweenCost (fusionloc/common/), shared with the RBPF and the
// stereo VO.
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
#include "fusionloc/common/se3_between_cost.hpp"
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

// The SE(3) between factor is fl::Se3BetweenCost (fusionloc/common/se3_between_cost.hpp),
// shared with the stereo VO's local bundle adjustment.
using fl::Se3BetweenCost;

}  // namespace fl::fusion
