#include "fusionloc/fusion/pose_graph.hpp"

#include <chrono>
#include <ctime>
#include <memory>

#include "fusionloc/common/solver_threads.hpp"

namespace fl::fusion {
namespace {

std::string EdgeName(const char* kind, size_t index, int i, int j) {
  return std::string(kind) + " #" + std::to_string(index) + " (" + std::to_string(i) + " -> " +
         std::to_string(j) + ")";
}

}  // namespace

Status OptimizePoseGraph(G2oGraph* graph, const PoseGraphSolveOptions& options,
                         PoseGraphResult* result) {
  if (graph->num_poses() == 0) return Status::Error("pose graph has no vertices");
  const auto t0 = std::chrono::steady_clock::now();
  // Declared before the problem, which borrows them (no leak on an early error return).
  Pose2Manifold pose2_manifold;
  ceres::EigenQuaternionManifold quaternion_manifold;
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  if (!graph->is_3d()) {
    ceres::Manifold* manifold = &pose2_manifold;
    for (size_t k = 0; k < graph->edges2.size(); ++k) {
      const G2oEdge2& e = graph->edges2[k];
      Eigen::Matrix3d sqrt_info;
      if (!SqrtInformation<3>(e.information, &sqrt_info, options.sqrt_convention)) {
        return Status::Error(EdgeName("EDGE_SE2", k, e.id_i, e.id_j) +
                             ": information matrix is not symmetric positive definite");
      }
      const Pose2 T_i_j(e.T_i_j[0], e.T_i_j[1], e.T_i_j[2]);
      problem.AddResidualBlock(Se2BetweenCost::Create(T_i_j, sqrt_info), nullptr,
                               graph->poses2.at(e.id_i).data(), graph->poses2.at(e.id_j).data());
    }
    for (auto& [id, pose] : graph->poses2) {
      if (problem.HasParameterBlock(pose.data())) problem.SetManifold(pose.data(), manifold);
    }
    double* first = graph->poses2.begin()->second.data();
    if (problem.HasParameterBlock(first)) problem.SetParameterBlockConstant(first);
  } else {
    ceres::Manifold* manifold = &quaternion_manifold;
    for (size_t k = 0; k < graph->edges3.size(); ++k) {
      const G2oEdge3& e = graph->edges3[k];
      Eigen::Matrix<double, 6, 6> sqrt_info;
      if (!SqrtInformation<6>(e.information, &sqrt_info, options.sqrt_convention)) {
        return Status::Error(EdgeName("EDGE_SE3:QUAT", k, e.id_i, e.id_j) +
                             ": information matrix is not symmetric positive definite");
      }
      G2oPose3& a = graph->poses3.at(e.id_i);
      G2oPose3& b = graph->poses3.at(e.id_j);
      problem.AddResidualBlock(Se3BetweenCost::Create(e.T_i_j.p, e.T_i_j.q, sqrt_info), nullptr,
                               a.p.data(), a.q.coeffs().data(), b.p.data(), b.q.coeffs().data());
    }
    for (auto& [id, pose] : graph->poses3) {
      if (problem.HasParameterBlock(pose.q.coeffs().data())) {
        problem.SetManifold(pose.q.coeffs().data(), manifold);
      }
    }
    G2oPose3& first = graph->poses3.begin()->second;
    if (problem.HasParameterBlock(first.p.data())) {
      problem.SetParameterBlockConstant(first.p.data());
      problem.SetParameterBlockConstant(first.q.coeffs().data());
    }
  }

  ceres::Solver::Options solver_options;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  solver_options.num_threads = options.num_threads;
  solver_options.minimizer_progress_to_stdout = options.progress_to_stdout;
  if (options.sparse_library == "eigen_sparse") {
    solver_options.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
  } else if (options.sparse_library != "suite_sparse") {
    return Status::Error("sparse_library '" + options.sparse_library +
                         "' unknown; use suite_sparse or eigen_sparse");
  }
  std::string error;
  if (!solver_options.IsValid(&error)) return Status::Error("Ceres options: " + error);
  ConfigureSparseSolverThreads(options.num_threads);
  ceres::Solver::Summary summary;
  timespec cpu0{}, cpu1{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &cpu0);
  ceres::Solve(solver_options, &problem, &summary);
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &cpu1);
  result->solve_cpu_s = (cpu1.tv_sec - cpu0.tv_sec) + 1e-9 * (cpu1.tv_nsec - cpu0.tv_nsec);
  const auto t1 = std::chrono::steady_clock::now();
  result->initial_cost = summary.initial_cost;
  result->final_cost = summary.final_cost;
  result->iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
  result->solve_s = summary.total_time_in_seconds;
  result->total_s = std::chrono::duration<double>(t1 - t0).count();
  result->converged = summary.termination_type == ceres::CONVERGENCE;
  result->termination = ceres::TerminationTypeToString(summary.termination_type);
  result->brief_report = summary.BriefReport();
  result->full_report = summary.FullReport();
  if (summary.termination_type == ceres::FAILURE) {
    return Status::Error("Ceres failed: " + summary.message);
  }
  return Status::Ok();
}

}  // namespace fl::fusion
