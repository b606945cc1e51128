#include "fusionloc/rbpf_slam/scan_matcher.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>

namespace fl::rbpf {

namespace {
// Whether a scan point (base frame p, world w) lies in observed space: its cell, or the cell
// `margin` back along its beam (approximated from the base origin), was observed.
inline bool Observed(const TiledGrid& grid, const Eigen::Vector2d& p, const Eigen::Vector2d& w,
                     double c, double s, const MatcherOptions& o) {
  if (!o.skip_unexplored || grid.IsKnownAt(w)) return true;
  const double r = p.norm();
  if (o.unexplored_margin <= 0.0 || r <= o.unexplored_margin) return o.unexplored_margin > 0.0;
  const double k = o.unexplored_margin / r;  // step back by margin along the beam
  const Eigen::Vector2d back(c * p.x() - s * p.y(), s * p.x() + c * p.y());
  return grid.IsKnownAt(w - k * back);
}
}  // namespace

double ScanLogLikelihood(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& points_base,
                         const fl::Pose2& T, const MatcherOptions& o, int* inliers) {
  const double c = std::cos(T.theta), s = std::sin(T.theta);
  const double inv2s2 = 1.0 / (2.0 * o.sigma * o.sigma);
  const double dmax = grid.field_radius_cells() * grid.resolution() * 0.999;
  double ll = 0.0;
  int n_in = 0, n_known = 0;
  for (const Eigen::Vector2d& p : points_base) {
    const Eigen::Vector2d w(T.x + c * p.x() - s * p.y(), T.y + s * p.x() + c * p.y());
    if (!Observed(grid, p, w, c, s, o)) continue;
    ++n_known;
    const double d = grid.Distance(w);
    if (d < dmax) ++n_in;
    ll += std::log(o.z_hit * std::exp(-d * d * inv2s2) + o.z_rand);
  }
  if (inliers) *inliers = n_in;
  const double n = static_cast<double>(points_base.size());
  if (n_known == 0) {
    const double d = grid.Distance(Eigen::Vector2d(1e9, 1e9));  // saturated
    return n * std::log(o.z_hit * std::exp(-d * d * inv2s2) + o.z_rand);
  }
  return ll * n / static_cast<double>(n_known);
}

namespace {
// The matcher's cost, the sum of squared (saturated) distances over `pts` (MatchScan passes the
// points in observed cells), and, over the points inside the field (d < dmax), the Gauss-Newton
// Hessian H = Σ JᵀJ and gradient g = Σ Jᵀd in one pass: an accepted step's pass is the next
// iteration's.
double Evaluate(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& pts, const fl::Pose2& T,
                double dmax, Eigen::Matrix3d* H, Eigen::Vector3d* g, int* n) {
  const double c = std::cos(T.theta), s = std::sin(T.theta);
  // Sums in locals: the field is read as bytes, which may alias any memory, so sums kept in
  // *H and *g would be stored and reloaded for every point. H is symmetric: its upper triangle
  // is summed and mirrored (J_i J_j = J_j J_i exactly, so H is the same to the last bit).
  double cost = 0.0;
  double h00 = 0.0, h01 = 0.0, h02 = 0.0, h11 = 0.0, h12 = 0.0, h22 = 0.0;
  double g0 = 0.0, g1 = 0.0, g2 = 0.0;
  int count = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector2d& p = pts[i];
    const Eigen::Vector2d w(T.x + c * p.x() - s * p.y(), T.y + s * p.x() + c * p.y());
    Eigen::Vector2d grad;
    const double d = grid.Distance(w, &grad);
    cost += d * d;
    if (d >= dmax) continue;
    const Eigen::Vector3d J = PoseJacobian(grad, p, c, s);
    const double j0 = J.x(), j1 = J.y(), j2 = J.z();
    h00 += j0 * j0;
    h01 += j0 * j1;
    h02 += j0 * j2;
    h11 += j1 * j1;
    h12 += j1 * j2;
    h22 += j2 * j2;
    g0 += j0 * d;
    g1 += j1 * d;
    g2 += j2 * d;
    ++count;
  }
  *H << h00, h01, h02, h01, h11, h12, h02, h12, h22;
  *g << g0, g1, g2;
  *n = count;
  return cost;
}
}  // namespace

Eigen::Matrix3d WellConstrainedProjector(const Eigen::Matrix3d& H, double length_m, double ratio,
                                         int* degenerate_dims) {
  if (degenerate_dims) *degenerate_dims = 0;
  if (!(ratio > 0.0) || !(length_m > 0.0) || !H.allFinite()) return Eigen::Matrix3d::Identity();
  const Eigen::Vector3d s(1.0, 1.0, 1.0 / length_m);
  const Eigen::Matrix3d Hs = s.asDiagonal() * H * s.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(0.5 * (Hs + Hs.transpose()));
  const double lmax = es.eigenvalues()(2);
  if (!(lmax > 0.0)) return Eigen::Matrix3d::Identity();
  Eigen::Matrix3d Pc = Eigen::Matrix3d::Zero();
  int degenerate = 0;
  for (int k = 0; k < 3; ++k) {
    if (es.eigenvalues()(k) < ratio * lmax) {
      ++degenerate;
    } else {
      Pc += es.eigenvectors().col(k) * es.eigenvectors().col(k).transpose();
    }
  }
  if (degenerate_dims) *degenerate_dims = degenerate;
  if (degenerate == 0) return Eigen::Matrix3d::Identity();
  return s.asDiagonal() * Pc * s.cwiseInverse().asDiagonal();
}

MatchResult MatchScan(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& pts,
                      const fl::Pose2& initial, const MatcherOptions& o) {
  MatchResult r;
  r.T_world_base = initial;
  if (pts.empty()) return r;
  const double dmax = grid.field_radius_cells() * grid.resolution() * 0.999;
  fl::Pose2 T = initial;
  // Points in cells the map never observed are left out (fixed at the initial pose so that the
  // cost compares like with like).
  thread_local std::vector<Eigen::Vector2d> used;
  used.clear();
  {
    const double c = std::cos(T.theta), s = std::sin(T.theta);
    for (const Eigen::Vector2d& p : pts) {
      const Eigen::Vector2d w(T.x + c * p.x() - s * p.y(), T.y + s * p.x() + c * p.y());
      if (Observed(grid, p, w, c, s, o)) used.push_back(p);
    }
  }
  Eigen::Matrix3d H;
  Eigen::Vector3d g;
  int n = 0;
  double cost = Evaluate(grid, used, T, dmax, &H, &g, &n);
  r.evaluations = 1;
  double lambda = 1e-3;
  double length_sq = 0.0;
  for (const Eigen::Vector2d& p : pts) length_sq += p.squaredNorm();
  const double length_m = std::sqrt(length_sq / static_cast<double>(pts.size()));
  Eigen::Matrix3d P = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d H_new;
  Eigen::Vector3d g_new;
  int n_new = 0;
  for (int it = 0; it < o.max_iterations; ++it) {
    if (n < 3) break;
    if (it == 0) P = WellConstrainedProjector(H, length_m, o.degeneracy_ratio, &r.degenerate_dims);
    bool improved = false;
    for (int tries = 0; tries < 6 && !improved; ++tries) {
      Eigen::Matrix3d A = H;
      A.diagonal() += lambda * (H.diagonal().array() + 1e-6).matrix();
      const Eigen::Vector3d delta = P * (-A.ldlt().solve(g));
      if (!delta.allFinite()) break;
      const fl::Pose2 T_new(T.x + delta.x(), T.y + delta.y(), fl::WrapAngle(T.theta + delta.z()));
      const double cost_new = Evaluate(grid, used, T_new, dmax, &H_new, &g_new, &n_new);
      ++r.evaluations;
      if (cost_new < cost) {
        const bool small =
            (delta.head<2>().norm() < o.converged_step && std::abs(delta.z()) < o.converged_step) ||
            cost - cost_new < o.function_tolerance * cost;
        T = T_new;
        cost = cost_new;
        H = H_new;
        g = g_new;
        n = n_new;
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
