// A 2D pose graph (keyframes + relative-pose edges) optimised with Ceres; each edge is an
// fl::Se2BetweenCost (fusionloc/common/se2_between_cost.hpp).
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <array>
#include <deque>
#include <memory>
#include <vector>

#include "fusionloc/common/geometry.hpp"

namespace fl::rbpf {

struct PoseGraphEdge {
  int i = 0;
  int j = 0;
  fl::Pose2 T_i_j;
  Eigen::Matrix3d information = Eigen::Matrix3d::Identity();
  double huber_scale = 0.0;  // > 0: robust (Huber) loss with this scale on the whitened residual
  bool enabled = true;       // disabled edges are kept but not optimised (rejected loop closures)
  bool loop_closure = false; // a loop closure (may be rejected after optimisation)
};

// The Ceres problem is kept between optimisations: new edges are appended to it, and it is
// rebuilt (in edge order, so the same problem a fresh build gives) only after an edge was
// disabled. Copies start with no problem and build their own.
class PoseGraph2D {
 public:
  PoseGraph2D() = default;
  PoseGraph2D(const PoseGraph2D& other) : nodes_(other.nodes_), edges_(other.edges_) {}
  PoseGraph2D& operator=(const PoseGraph2D& other) {
    if (this != &other) {
      nodes_ = other.nodes_;
      edges_ = other.edges_;
      problem_.reset();
      edges_in_problem_ = 0;
    }
    return *this;
  }

  int AddNode(const fl::Pose2& T_world_node);
  void AddEdge(const PoseGraphEdge& edge);
  // Levenberg-Marquardt with sparse Cholesky; node 0 is held fixed. Returns the final cost
  // (½ Σ squared whitened residuals); `converged` tells whether Ceres reported convergence.
  // It also stops when a step lowers the cost by less than `function_tolerance` of it.
  double Optimize(int max_iterations, bool* converged = nullptr,
                  double function_tolerance = 1e-6);
  // ½ Σ squared whitened (robustified) residuals of the enabled edges at the current poses.
  double Cost();

  int num_nodes() const { return static_cast<int>(nodes_.size()); }
  int num_edges() const { return static_cast<int>(edges_.size()); }
  fl::Pose2 pose(int i) const { return {nodes_[i][0], nodes_[i][1], nodes_[i][2]}; }
  void set_pose(int i, const fl::Pose2& p) { nodes_[i] = {p.x, p.y, p.theta}; }
  const std::vector<PoseGraphEdge>& edges() const { return edges_; }
  void DisableEdge(int k) {
    edges_.at(k).enabled = false;
    problem_.reset();  // rebuilt without it at the next Optimize / Cost
  }
  // Error of edge k at the current poses: T_i_j^-1 * (pose(i)^-1 * pose(j)).
  fl::Pose2 EdgeError(int k) const {
    const PoseGraphEdge& e = edges_.at(k);
    return e.T_i_j.inverse() * pose(e.i).between(pose(e.j));
  }

 private:
  // Brings problem_ up to date: one residual block per enabled edge, in edge order; node 0
  // held constant.
  void SyncProblem();

  // A deque: the problem points into the nodes, and push_back keeps them where they are.
  std::deque<std::array<double, 3>> nodes_;
  std::vector<PoseGraphEdge> edges_;
  std::unique_ptr<ceres::Problem> problem_;
  int edges_in_problem_ = 0;  // edges_[0, edges_in_problem_) have been added (if enabled)
};

}  // namespace fl::rbpf
