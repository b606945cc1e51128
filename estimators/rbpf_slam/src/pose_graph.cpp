#include "fusionloc/rbpf_slam/pose_graph.hpp"

#include <Eigen/Cholesky>
#include <stdexcept>

#include "fusionloc/common/solver_threads.hpp"

namespace fl::rbpf {

ceres::CostFunction* RelativePose2Cost::Create(const fl::Pose2& T_i_j,
                                               const Eigen::Matrix3d& information) {
  // S with SᵀS = Ω: the transpose of the lower Cholesky factor (Ω = L Lᵀ → S = Lᵀ).
  const Eigen::Matrix3d sym = 0.5 * (information + information.transpose());
  Eigen::LLT<Eigen::Matrix3d> llt(sym);
  if (llt.info() != Eigen::Success) {
    throw std::invalid_argument("RelativePose2Cost: information matrix is not positive definite");
  }
  const Eigen::Matrix3d S = llt.matrixL().transpose();
  return new ceres::AutoDiffCostFunction<RelativePose2Cost, 3, 3, 3>(
      new RelativePose2Cost(T_i_j, S));
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

void PoseGraph2D::BuildProblem(ceres::Problem* problem) {
  for (const PoseGraphEdge& e : edges_) {
    if (!e.enabled) continue;
    ceres::LossFunction* loss = e.huber_scale > 0 ? new ceres::HuberLoss(e.huber_scale) : nullptr;
    problem->AddResidualBlock(RelativePose2Cost::Create(e.T_i_j, e.information), loss,
                              nodes_[e.i].data(), nodes_[e.j].data());
  }
}

double PoseGraph2D::Cost() {
  if (nodes_.empty()) return 0.0;
  ceres::Problem problem;
  BuildProblem(&problem);
  double cost = 0.0;
  problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
  return cost;
}

double PoseGraph2D::Optimize(int max_iterations, bool* converged) {
  if (nodes_.empty()) return 0.0;
  ceres::Problem problem;
  BuildProblem(&problem);
  if (problem.HasParameterBlock(nodes_[0].data())) problem.SetParameterBlockConstant(nodes_[0].data());
  ceres::Solver::Options opts;
  opts.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  opts.max_num_iterations = max_iterations;
  opts.num_threads = 1;
  fl::ConfigureSparseSolverThreads(opts.num_threads);  // CHOLMOD's OpenMP teams: see header
  ceres::Solver::Summary summary;
  ceres::Solve(opts, &problem, &summary);
  for (auto& n : nodes_) n[2] = fl::WrapAngle(n[2]);
  if (converged) *converged = summary.termination_type == ceres::CONVERGENCE;
  return summary.final_cost;
}

}  // namespace fl::rbpf
