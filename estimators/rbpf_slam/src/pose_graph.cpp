#include "fusionloc/rbpf_slam/pose_graph.hpp"

#include <cmath>
#include <stdexcept>

#include "fusionloc/common/sqrt_information.hpp"

namespace fl::rbpf {

ceres::CostFunction* RelativePose2Cost::Create(const fl::Pose2& T_i_j,
                                               const Eigen::Matrix3d& information) {
  // The information of an ICP fit may be asymmetric by rounding: use its symmetric part.
  const Eigen::Matrix3d sym = 0.5 * (information + information.transpose());
  Eigen::Matrix3d S;
  if (!fl::SqrtInformation<3>(sym, &S)) {
    throw std::invalid_argument("RelativePose2Cost: information matrix is not positive definite");
  }
  return new RelativePose2Cost(T_i_j, S);
}

bool RelativePose2Cost::Evaluate(double const* const* parameters, double* residuals,
                                 double** jacobians) const {
  const double* x_i = parameters[0];
  const double* x_j = parameters[1];
  const double c = std::cos(x_i[2]), s = std::sin(x_i[2]);
  const double dx = x_j[0] - x_i[0], dy = x_j[1] - x_i[1];
  const double u = c * dx + s * dy, v = -s * dx + c * dy;
  const double a = x_j[2] - x_i[2] - T_i_j_.theta;
  const double two_pi = 2.0 * M_PI;
  const Eigen::Vector3d e(u - T_i_j_.x, v - T_i_j_.y, a - two_pi * std::floor((a + M_PI) / two_pi));
  Eigen::Map<Eigen::Vector3d> r(residuals);
  r = sqrt_info_ * e;
  if (!jacobians) return true;
  using RowMajor3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  if (jacobians[0]) {
    RowMajor3 de;
    de << -c, -s, v, s, -c, -u, 0.0, 0.0, -1.0;
    Eigen::Map<RowMajor3> J_i(jacobians[0]);
    J_i = sqrt_info_ * de;
  }
  if (jacobians[1]) {
    RowMajor3 de;
    de << c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0;
    Eigen::Map<RowMajor3> J_j(jacobians[1]);
    J_j = sqrt_info_ * de;
  }
  return true;
}

int PoseGraph2D::AddNode(const fl::Pose2& T) {
  nodes_.push_back({T.x, T.y, T.theta});
  return static_cast<int>(nodes_.size()) - 1;
}

void PoseGraph2D::AddEdge(const PoseGraphEdge& e) {
  if (e.i < 0 || e.j < 0 || e.i >= num_nodes() || e.j >= num_nodes() || e.i == e.j) {
    throw std::invalid_argument("PoseGraph2D::AddEdge: bad node ids " + std::to_string(e.i) +
                                ", " + std::to_string(e.j));
  }
  edges_.push_back(e);
}

void PoseGraph2D::SyncProblem() {
  if (!problem_) {
    problem_ = std::make_unique<ceres::Problem>();
    edges_in_problem_ = 0;
  }
  for (; edges_in_problem_ < num_edges(); ++edges_in_problem_) {
    const PoseGraphEdge& e = edges_[edges_in_problem_];
    if (!e.enabled) continue;
    ceres::LossFunction* loss = e.huber_scale > 0 ? new ceres::HuberLoss(e.huber_scale) : nullptr;
    problem_->AddResidualBlock(RelativePose2Cost::Create(e.T_i_j, e.information), loss,
                               nodes_[e.i].data(), nodes_[e.j].data());
  }
  double* first = nodes_[0].data();
  if (problem_->HasParameterBlock(first) && !problem_->IsParameterBlockConstant(first)) {
    problem_->SetParameterBlockConstant(first);
  }
}

double PoseGraph2D::Cost() {
  if (nodes_.empty()) return 0.0;
  SyncProblem();
  double cost = 0.0;
  problem_->Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
  return cost;
}

double PoseGraph2D::Optimize(int max_iterations, bool* converged, double function_tolerance) {
  if (nodes_.empty()) return 0.0;
  SyncProblem();
  ceres::Solver::Options opts;
  opts.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  // Eigen's simplicial LDLT: on these graphs (3x3 blocks, up to a few thousand nodes) it
  // factors faster than CHOLMOD's supernodal code, whose per-supernode set-up dominates
  // (intel: the solves' share of the run fell from 33 % to 26 %, same results; BENCHMARKS.md).
  opts.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
  opts.max_num_iterations = max_iterations;
  opts.function_tolerance = function_tolerance;
  opts.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(opts, problem_.get(), &summary);
  for (auto& n : nodes_) n[2] = fl::WrapAngle(n[2]);
  if (converged) *converged = summary.termination_type == ceres::CONVERGENCE;
  return summary.final_cost;
}

}  // namespace fl::rbpf
