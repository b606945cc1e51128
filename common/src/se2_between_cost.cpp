#include "fusionloc/common/se2_between_cost.hpp"

#include <cmath>

namespace fl {

bool Se2BetweenCost::Evaluate(double const* const* parameters, double* residuals,
                              double** jacobians) const {
  const double* T_world_i = parameters[0];
  const double* T_world_j = parameters[1];
  const double c = std::cos(T_world_i[2]), s = std::sin(T_world_i[2]);
  const double dx = T_world_j[0] - T_world_i[0], dy = T_world_j[1] - T_world_i[1];
  const double u = c * dx + s * dy, v = -s * dx + c * dy;
  const double a = T_world_j[2] - T_world_i[2] - T_i_j_.theta;
  const double two_pi = 2.0 * M_PI;
  const Eigen::Vector3d e(u - T_i_j_.x, v - T_i_j_.y, a - two_pi * std::floor((a + M_PI) / two_pi));
  Eigen::Map<Eigen::Vector3d> r(residuals);
  r = sqrt_information_ * e;
  if (jacobians == nullptr) return true;
  using RowMajor3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  if (jacobians[0] != nullptr) {
    RowMajor3 de;
    de << -c, -s, v, s, -c, -u, 0.0, 0.0, -1.0;
    Eigen::Map<RowMajor3> J_i(jacobians[0]);
    J_i = sqrt_information_ * de;
  }
  if (jacobians[1] != nullptr) {
    RowMajor3 de;
    de << c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0;
    Eigen::Map<RowMajor3> J_j(jacobians[1]);
    J_j = sqrt_information_ * de;
  }
  return true;
}

}  // namespace fl
