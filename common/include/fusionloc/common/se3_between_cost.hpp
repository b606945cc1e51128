// The SE(3) between factor: the 3D pose graphs (fl::fusion::PoseGraph, VERTEX_SE3:QUAT /
// EDGE_SE3:QUAT of the g2o benchmark) and the keyframe motion prior of the stereo VO's local
// bundle adjustment (fl::vo::LocalBundleAdjustment).
//
// Parameter blocks: p_i (3), q_i (4, Eigen order x y z w, unit, EigenQuaternionManifold),
// p_j (3), q_j (4): T_world_i and T_world_j. Measurement T_i_j = (p_ij, q_ij).
//
//   q_ij_est = q_i^-1 q_j,   p_ij_est = q_i^-1 (p_j - p_i)
//   dq = q_ij * q_ij_est^-1
//   e = [ p_ij_est - p_ij ; 2 vec(dq) ]   (metres in frame i; ~radians for small errors)
//   r = S e,  S^T S = Omega (6x6, order x y z rx ry rz; fl::SqrtInformation)
//
// For a measurement whose covariance Sigma is of a right perturbation delta = [rho; phi]
// (T_est = T_ij Exp(delta)): to first order e = [R_ij rho; -R_ij phi], so the covariance of e is
// M Sigma M^T with M = diag(R_ij, -R_ij) (Se3BetweenErrorCovariance below).
//
// Jacobians by automatic differentiation.
#pragma once

#include <ceres/autodiff_cost_function.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace fl {

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

// Covariance of the error e above for a measurement T_ij with right-perturbation covariance
// cov_delta ([rho; phi]).
inline Eigen::Matrix<double, 6, 6> Se3BetweenErrorCovariance(
    const Eigen::Matrix3d& R_ij, const Eigen::Matrix<double, 6, 6>& cov_delta) {
  Eigen::Matrix<double, 6, 6> M = Eigen::Matrix<double, 6, 6>::Zero();
  M.topLeftCorner<3, 3>() = R_ij;
  M.bottomRightCorner<3, 3>() = -R_ij;
  return M * cov_delta * M.transpose();
}

}  // namespace fl
