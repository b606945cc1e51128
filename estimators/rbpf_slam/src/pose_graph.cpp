#include "fusionloc/rbpf_slam/pose_graph.hpp"

#include <stdexcept>
#include <string>

#include "fusionloc/common/se2_between_cost.hpp"
#include "fusionloc/common/sqrt_information.hpp"

namespace fl::rbpf {

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
    // The information of an ICP fit may be asymmetric by rounding: use its symmetric part.
    Eigen::Matrix3d S;
    if (!fl::SqrtInformation<3>(Eigen::Matrix3d(0.5 * (e.information + e.information.transpose())),
                                &S)) {
      throw std::invalid_argument("PoseGraph2D: information matrix of edge " +
                                  std::to_string(e.i) + " -> " + std::to_string(e.j) +
                                  " is not positive definite");
    }
    ceres::LossFunction* loss = e.huber_scale > 0 ? new ceres::HuberLoss(e.huber_scale) : nullptr;
    problem_->AddResidualBlock(fl::Se2BetweenCost::Create(e.T_i_j, S), loss,
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
