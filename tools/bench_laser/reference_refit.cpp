#include "reference_refit.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include "fusionloc/rbpf_slam/icp.hpp"
#include "fusionloc/rbpf_slam/pose_graph.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam.hpp"

namespace fl::rbpf {

RefitOdometrySigma RefitOdometrySigma::FromMotion(const MotionOptions& m) {
  RefitOdometrySigma s;
  s.trans_per_m = m.srr;
  s.trans_per_rad = m.srt;
  s.rot_per_rad = m.stt;
  s.rot_per_m = m.str;
  return s;
}

Status RefitOptions::Validate() const {
  const std::pair<const char*, double> positive[] = {{"pair_radius_m", pair_radius_m},
                                                     {"max_icp_move_m", max_icp_move_m},
                                                     {"max_icp_move_rad", max_icp_move_rad}};
  for (const auto& [name, v] : positive) {
    if (!(std::isfinite(v) && v > 0.0)) {
      return Status::Error(std::string("refit.") + name + " = " + std::to_string(v) +
                           " must be a finite number > 0");
    }
  }
  if (!(std::isfinite(icp_huber) && icp_huber >= 0.0)) {
    return Status::Error("refit.icp_huber = " + std::to_string(icp_huber) +
                         " must be >= 0 (0 = no robust loss)");
  }
  if (max_pairs < 0) {
    return Status::Error("refit.max_pairs = " + std::to_string(max_pairs) + " must be >= 0");
  }
  if (max_iterations < 1) {
    return Status::Error("refit.max_iterations = " + std::to_string(max_iterations) +
                         " must be >= 1");
  }
  return Status::Ok();
}

RefitResult RefitReference(const std::vector<RefitScan>& scans, const fl::Pose2& T_base_laser,
                           const RbpfSlamOptions& options, const RefitOdometrySigma& sigma,
                           const RefitOptions& refit) {
  if (const Status s = refit.Validate(); !s.ok()) throw std::invalid_argument(s.message());
  if (const Status s = options.Validate(); !s.ok()) throw std::invalid_argument(s.message());
  if (scans.size() < 2) {
    throw std::invalid_argument("RefitReference: needs at least 2 scans, got " +
                                std::to_string(scans.size()));
  }
  const int n = static_cast<int>(scans.size());
  std::vector<std::vector<Eigen::Vector2d>> points(n);
  std::vector<std::vector<PointNormal>> normals(n);
  for (int k = 0; k < n; ++k) {
    const LaserScan& s = scans[k].scan;
    if (k > 0 && s.utime <= scans[k - 1].scan.utime) {
      throw std::invalid_argument("RefitReference: scan " + std::to_string(k) + " (utime " +
                                  std::to_string(s.utime) + ") is not after the previous one");
    }
    ScanToBasePoints(s, T_base_laser, options.grid.max_range, &points[k]);
    normals[k] =
        ComputeNormals(points[k], options.icp);
  }

  PoseGraph2D graph;
  for (const RefitScan& s : scans) graph.AddNode(s.T_world_base_reference);
  RefitResult out;
  for (int k = 1; k < n; ++k) {
    const fl::Pose2 u = scans[k - 1].T_odom_base.between(scans[k].T_odom_base);
    const double d = std::hypot(u.x, u.y), turn = std::abs(u.theta);
    const double s_xy =
        std::max({sigma.min_sigma_xy, sigma.trans_per_m * d + sigma.trans_per_rad * turn, 1e-6});
    const double s_th =
        std::max({sigma.min_sigma_rad, sigma.rot_per_rad * turn + sigma.rot_per_m * d, 1e-7});
    PoseGraphEdge odo;
    odo.i = k - 1;
    odo.j = k;
    odo.T_i_j = u;
    odo.information =
        Eigen::Vector3d(1.0 / (s_xy * s_xy), 1.0 / (s_xy * s_xy), 1.0 / (s_th * s_th)).asDiagonal();
    graph.AddEdge(odo);
    ++out.odometry_edges;

    const fl::Pose2& ref_k = scans[k].T_world_base_reference;
    std::vector<std::pair<double, int>> near;
    for (int i = 0; i + 1 < k; ++i) {
      const fl::Pose2& ref_i = scans[i].T_world_base_reference;
      const double dist = std::hypot(ref_i.x - ref_k.x, ref_i.y - ref_k.y);
      if (dist < refit.pair_radius_m) near.emplace_back(dist, i);
    }
    std::sort(near.begin(), near.end());
    if (static_cast<int>(near.size()) > refit.max_pairs) near.resize(refit.max_pairs);
    near.emplace_back(0.0, k - 1);
    for (const auto& [dist, i] : near) {
      (void)dist;
      const fl::Pose2 start = scans[i].T_world_base_reference.between(ref_k);
      const IcpResult icp = AlignPointToLine(normals[i], points[k], start, options.icp);
      const fl::Pose2 moved = start.between(icp.T_ref_query);
      if (!icp.ok || std::hypot(moved.x, moved.y) > refit.max_icp_move_m ||
          std::abs(moved.theta) > refit.max_icp_move_rad) {
        ++out.icp_left_out;
        continue;
      }
      PoseGraphEdge e;
      e.i = i;
      e.j = k;
      e.T_i_j = icp.T_ref_query;
      e.information = icp.information;
      e.huber_scale = refit.icp_huber;
      graph.AddEdge(e);
      ++out.icp_edges;
    }
  }
  out.initial_cost = graph.Cost();
  out.final_cost = graph.Optimize(refit.max_iterations);
  out.T_world_base.reserve(n);
  for (int k = 0; k < n; ++k) out.T_world_base.push_back(graph.pose(k));
  return out;
}

}  // namespace fl::rbpf
