// The SE(2) between factor of every planar pose graph in the project: the RBPF's keyframe
// graph (fl::rbpf::PoseGraph2D), the fusion back-end (laser, vision and wheel-odometry
// factors) and the g2o pose-graph benchmark (EDGE_SE2).
//
// Parameter blocks: T_world_i = (x_i, y_i, θ_i) and T_world_j likewise, the poses of nodes i
// and j in the graph's world frame. Measurement: T_i_j = (x_ij, y_ij, θ_ij), the pose of node
// j in the frame of node i. With t = (x, y) and R(θ) the 2D rotation:
//
//   (u, v) = R(θ_i)ᵀ (t_j − t_i)                    translation of j in frame i [m]
//   e      = [ u − x_ij ; v − y_ij ; wrap(θ_j − θ_i − θ_ij) ]
//                                                   (wrap to [−π, π): a constant 2πk shift)
//   r      = S e,   SᵀS = Ω_ij (3x3, order x, y, θ; see fl::SqrtInformation)
//
// so that Ceres' ½|r|² is ½ eᵀΩe. Analytic Jacobians (c = cos θ_i, s = sin θ_i):
//
//   ∂e/∂T_world_i = [ −c  −s   v ]      ∂e/∂T_world_j = [  c   s   0 ]
//                   [  s  −c  −u ]                      [ −s   c   0 ]
//                   [  0   0  −1 ]                      [  0   0   1 ]
//   ∂r/∂T = S ∂e/∂T.
//
// (They replaced AutoDiff: the pose-graph solves were a third of the RBPF's run on intel. The
// GradientChecker test in tests/common/se2_between_cost_test.cpp holds them to the numeric
// derivatives.) The angle may leave [−π, π) during a solve unless the block has a manifold
// that wraps it; the residual is the same either way.
//
// Ceres-dependent: link fl_common_ceres.
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>

#include "fusionloc/common/geometry.hpp"

namespace fl {

class Se2BetweenCost final : public ceres::SizedCostFunction<3, 3, 3> {
 public:
  // sqrt_information: S with SᵀS = Ω (fl::SqrtInformation), not Ω itself.
  Se2BetweenCost(const Pose2& T_i_j, const Eigen::Matrix3d& sqrt_information)
      : T_i_j_(T_i_j), sqrt_information_(sqrt_information) {}

  static ceres::CostFunction* Create(const Pose2& T_i_j, const Eigen::Matrix3d& sqrt_information) {
    return new Se2BetweenCost(T_i_j, sqrt_information);
  }

  // parameters[0] = T_world_i, parameters[1] = T_world_j, each (x, y, θ).
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

  const Pose2& T_i_j() const { return T_i_j_; }
  const Eigen::Matrix3d& sqrt_information() const { return sqrt_information_; }

 private:
  Pose2 T_i_j_;
  Eigen::Matrix3d sqrt_information_;
};

}  // namespace fl
