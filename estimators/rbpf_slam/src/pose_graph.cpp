#include "fusionloc/rbpf_slam/pose_graph.hpp"

#include <stdexcept>
#include <string>

#include "fusionloc/common/se2_between_cost.hpp"
#include "fusionloc/common/sqrt_information.hpp"

namespace fl::rbpf {

int PoseGraph2D::AddNode(const fl::Pose2& T) {
  nodes_.push_back({T.x, T.y, T.theta});
  merged_.push_back(false);
  return static_cast<int>(nodes_.size()) - 1;
}

void PoseGraph2D::AddEdge(const PoseGraphEdge& e) {
  if (e.i < 0 || e.j < 0 || e.i >= num_nodes() || e.j >= num_nodes() || e.i == e.j ||
      merged(e.i) || merged(e.j)) {
    throw std::invalid_argument("PoseGraph2D::AddEdge: bad node ids " + std::to_string(e.i) +
                                ", " + std::to_string(e.j));
  }
  edges_.push_back(e);
}

int PoseGraph2D::MergeNode(int j, int i, const fl::Pose2& T_i_j) {
  if (j <= 0 || i < 0 || j >= num_nodes() || i >= num_nodes() || i == j || merged(i) ||
      merged(j)) {
    throw std::invalid_argument("PoseGraph2D::MergeNode: bad node ids " + std::to_string(j) +
                                " into " + std::to_string(i));
  }
  // The residual (se2_between_cost.hpp) is e = [t(T_est) − t(T_meas) in the first node's
  // frame; θ_est − θ_meas]. With J = I · T_i_j:
  // - an edge j → y, measured T_j_y, becomes i → y measured T_i_j · T_j_y: its estimate is
  //   T_i_j · T_est, so e' = B e with B = diag(R(θ_i_j), 1) (exact) and Ω' = B Ω Bᵀ;
  // - an edge x → j, measured T_x_j, becomes x → i measured T_x_j · T_j_i: its estimate is
  //   T_est · T_j_i, so t' differs by (R(θ_est) − R(θ_meas)) t_j_i ≈ δθ R(θ_meas) J t_j_i
  //   (J the 90° rotation): e' ≈ A e with A = [I c; 0 1], c = R(θ_meas) J t_j_i, and
  //   Ω' = A⁻ᵀ Ω A⁻¹.
  const fl::Pose2 T_j_i = T_i_j.inverse();
  int moved = 0;
  std::vector<PoseGraphEdge> kept;
  kept.reserve(edges_.size());
  for (PoseGraphEdge e : edges_) {
    const bool from_j = e.i == j, to_j = e.j == j;
    if ((from_j && e.j == i) || (to_j && e.i == i)) continue;  // between i and j: dropped
    if (from_j) {
      Eigen::Matrix3d B = Eigen::Matrix3d::Identity();
      B.topLeftCorner<2, 2>() = T_i_j.rotation();
      e.information = B * e.information * B.transpose();
      e.T_i_j = T_i_j * e.T_i_j;
      e.i = i;
      ++moved;
    } else if (to_j) {
      const Eigen::Vector2d t_j_i = T_j_i.translation();
      Eigen::Matrix3d A_inv = Eigen::Matrix3d::Identity();
      A_inv.topRightCorner<2, 1>() = -(e.T_i_j.rotation() * Eigen::Vector2d(-t_j_i.y(), t_j_i.x()));
      e.information = A_inv.transpose() * e.information * A_inv;
      e.T_i_j = e.T_i_j * T_j_i;
      e.j = i;
      ++moved;
    }
    kept.push_back(e);
  }
  edges_ = std::move(kept);
  merged_[static_cast<size_t>(j)] = true;
  ++num_merged_;
  problem_.reset();  // rebuilt without node j at the next Optimize / Cost
  return moved;
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
