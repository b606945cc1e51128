// Batch optimisation of a whole g2o pose graph (2D or 3D) with the fusion's cost functors:
// the back-end of `fl-bench-posegraph`, formulated as Ceres' pose_graph_2d/3d examples so
// that the final costs are comparable with theirs.
//
//   2D: one [x, y, theta] block per vertex (Pose2Manifold: angle wrapped), Se2BetweenCost.
//   3D: p (3) and q (4, EigenQuaternionManifold) blocks per vertex, Se3BetweenCost.
//   Gauge: the vertex with the smallest id is held constant.
//   Solver: Levenberg-Marquardt, SPARSE_NORMAL_CHOLESKY, at most max_iterations.
#pragma once

#include <string>

#include "fusionloc/common/status.hpp"
#include "fusionloc/fusion/cost_functions.hpp"
#include "fusionloc/fusion/g2o_reader.hpp"

namespace fl::fusion {

struct PoseGraphSolveOptions {
  int max_iterations = 100;  // LM iterations (Ceres' examples use 100)
  int num_threads = 1;       // 1 for a fair single-core time
  SqrtConvention sqrt_convention = SqrtConvention::kCeresExample;
  bool progress_to_stdout = false;
  // Sparse Cholesky back-end: "suite_sparse" (CHOLMOD, as Ceres' examples) or "eigen_sparse".
  std::string sparse_library = "suite_sparse";
};

struct PoseGraphResult {
  double initial_cost = 0.0;  // 1/2 sum |r|^2 at the file's initial values
  double final_cost = 0.0;
  int iterations = 0;        // LM iterations (successful + unsuccessful steps)
  double solve_s = 0.0;      // wall time of ceres::Solve
  double solve_cpu_s = 0.0;  // CPU time of this process during ceres::Solve (robust to a
                             // loaded machine; equals wall time when single-threaded & idle)
  double total_s = 0.0;      // building the problem + solving
  bool converged = false;    // Ceres termination CONVERGENCE
  std::string termination;   // e.g. "CONVERGENCE", "NO_CONVERGENCE"
  std::string brief_report;  // ceres::Solver::Summary::BriefReport()
  std::string full_report;   // ceres::Solver::Summary::FullReport()
};

// Optimises graph's poses in place. Errors (not-positive-definite information on an edge,
// a solver failure) name the edge.
Status OptimizePoseGraph(G2oGraph* graph, const PoseGraphSolveOptions& options,
                         PoseGraphResult* result);

}  // namespace fl::fusion
