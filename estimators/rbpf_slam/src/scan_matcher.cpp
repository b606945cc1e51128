#include "fusionloc/rbpf_slam/scan_matcher.hpp"

#include <Eigen/Cholesky>
#include <cmath>

namespace fl::rbpf {

double ScanLogLikelihood(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& points_base,
                         const fl::Pose2& T, const MatcherOptions& o, int* inliers) {
  const double c = std::cos(T.theta), s = std::sin(T.theta);
  const double inv2s2 = 1.0 / (2.0 * o.sigma * o.sigma);
  const double dmax = grid.field_radius_cells() * grid.resolution() * 0.999;
  double ll = 0.0;
  int n_in = 0;
  for (const Eigen::Vector2d& p : points_base) {
    const Eigen::Vector2d w(T.x + c * p.x() - s * p.y(), T.y + s * p.x() + c * p.y());
    const double d = grid.Distance(w);
    if (d < dmax) ++n_in;
    ll += std::log(o.z_hit * std::exp(-d * d * inv2s2) + o.z_rand);
  }
  if (inliers) *inliers = n_in;
  return ll;
}

namespace {
// Sum of squared (saturated) distances, the matcher's cost.
double Cost(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& pts, const fl::Pose2& T) {
  const double c = std::cos(T.theta), s = std::sin(T.theta);
  double cost = 0.0;
  for (const Eigen::Vector2d& p : pts) {
    const double d = grid.Distance({T.x + c * p.x() - s * p.y(), T.y + s * p.x() + c * p.y()});
    cost += d * d;
  }
  return cost;
}
}  // namespace

MatchResult MatchScan(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& pts,
                      const fl::Pose2& initial, const MatcherOptions& o) {
  MatchResult r;
  r.T_world_base = initial;
  if (pts.empty()) return r;
  const double dmax = grid.field_radius_cells() * grid.resolution() * 0.999;
  fl::Pose2 T = initial;
  double cost = Cost(grid, pts, T);
  double lambda = 1e-3;
  for (int it = 0; it < o.max_iterations; ++it) {
    const double c = std::cos(T.theta), s = std::sin(T.theta);
    Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    int n = 0;
    for (const Eigen::Vector2d& p : pts) {
      const Eigen::Vector2d w(T.x + c * p.x() - s * p.y(), T.y + s * p.x() + c * p.y());
      Eigen::Vector2d grad;
      const double d = grid.Distance(w, &grad);
      if (d >= dmax) continue;
      const Eigen::Vector3d J(grad.x(), grad.y(),
                              grad.x() * (-s * p.x() - c * p.y()) + grad.y() * (c * p.x() - s * p.y()));
      H.noalias() += J * J.transpose();
      g.noalias() += J * d;
      ++n;
    }
    if (n < 3) break;
    bool improved = false;
    for (int tries = 0; tries < 6 && !improved; ++tries) {
      Eigen::Matrix3d A = H;
      A.diagonal() += lambda * (H.diagonal().array() + 1e-6).matrix();
      const Eigen::Vector3d delta = -A.ldlt().solve(g);
      if (!delta.allFinite()) break;
      const fl::Pose2 T_new(T.x + delta.x(), T.y + delta.y(), fl::WrapAngle(T.theta + delta.z()));
      const double cost_new = Cost(grid, pts, T_new);
      if (cost_new < cost) {
        const bool small = delta.head<2>().norm() < 1e-4 && std::abs(delta.z()) < 1e-4;
        T = T_new;
        cost = cost_new;
        lambda = std::max(1e-6, lambda * 0.3);
        improved = true;
        if (small) it = o.max_iterations;  // converged
      } else {
        lambda *= 10.0;
      }
    }
    if (!improved) break;
  }
  r.log_likelihood = ScanLogLikelihood(grid, pts, T, o, &r.inliers);
  const fl::Pose2 corr = initial.between(T);
  const bool within = std::hypot(corr.x, corr.y) <= o.max_correction_m &&
                      std::abs(corr.theta) <= o.max_correction_rad;
  r.ok = within && r.inliers >= o.min_inlier_fraction * static_cast<double>(pts.size());
  if (r.ok) {
    r.T_world_base = T;
  } else {
    r.log_likelihood = ScanLogLikelihood(grid, pts, initial, o, &r.inliers);
  }
  (void)dmax;
  return r;
}

}  // namespace fl::rbpf
