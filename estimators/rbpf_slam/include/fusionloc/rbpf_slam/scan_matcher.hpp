// Scan-to-map matching on the likelihood field: the improved proposal of the particle filter
// and its observation model (the paper's eq. 3).
//
// Observation model: a beam end point p (in the world) at distance d(p) from the nearest
// obstacle has likelihood  p(z | x, m) = z_hit * exp(-d² / 2σ²) + z_rand.
// Matching: Gauss-Newton / Levenberg-Marquardt on Σ_i d(T_world_base * p_base,i)² over the
// points inside the field (d < field_max_distance), with the interpolated field gradient:
//   ∂d/∂(x, y, θ) = ∇dᵀ [ I₂ | R'(θ) p_base ],  R'(θ) = dR/dθ.
// Unexplored space: an end point in a cell the map never observed (beyond the map's frontier,
// e.g. past the end of a wall seen at the limit of the range) says nothing about the pose; the
// nearest mapped obstacle would pull it (and the whole scan) back towards the explored part, a
// systematic shortening of the motion along a corridor. Such points are left out of the matching
// and are scored at the mean log-likelihood of the scan's observed points, so a particle gains
// nothing by pushing points into, or out of, unexplored space.
// Degeneracy (Zhang, Kaess & Singh, ICRA 2016, "solution remapping"): at the initial pose the
// Hessian H = Σ JᵀJ is eigen-decomposed in the scaled coordinates (x, y, L·θ), L = RMS range of
// the points; directions whose eigenvalue is below matcher.degeneracy_ratio × the largest are
// not constrained by the scan (the axis of a corridor whose ends are out of range) and every LM
// step is projected onto the other directions, so the pose keeps the motion model's sample
// along them instead of sliding on noise and map artefacts.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/rbpf_slam/options.hpp"
#include "fusionloc/rbpf_slam/tiled_grid.hpp"

namespace fl::rbpf {

struct MatchResult {
  fl::Pose2 T_world_base;       // refined pose (the initial pose if !ok)
  double log_likelihood = 0.0;  // Σ log p(z_i) at T_world_base over the points used
  int inliers = 0;              // points inside the field at T_world_base
  int degenerate_dims = 0;      // directions left at the initial pose (see above)
  bool ok = false;              // converged, enough inliers, correction within bounds
  int evaluations = 0;          // cost evaluations (passes over the points) of the search
};

// Jacobian over the pose (x, y, θ) of vᵀ (R(θ) p + t) with v held fixed, c = cos θ, s = sin θ:
// [ vᵀ , vᵀ R'(θ) p ]. With v = ∇d at the world point it is ∂d/∂(x, y, θ) of one scan point (see
// above); with v the reference normal, the point-to-line Jacobian of one ICP pair (icp.hpp).
inline Eigen::Vector3d PoseJacobian(const Eigen::Vector2d& v, const Eigen::Vector2d& p, double c,
                                    double s) {
  return Eigen::Vector3d(v.x(), v.y(),
                         v.x() * (-s * p.x() - c * p.y()) + v.y() * (c * p.x() - s * p.y()));
}

// Projector P (in (x, y, θ)) removing the degenerate components of a step, δ' = P δ, for a
// Gauss-Newton Hessian H over (x, y, θ): with S = diag(1, 1, 1/L), H_s = S H S = V Λ Vᵀ, the
// columns v_k with λ_k < ratio · λ_max are degenerate and P = S V_c V_cᵀ S⁻¹ over the others.
// Identity if none is (or ratio ≤ 0); `degenerate_dims` (optional) counts them.
Eigen::Matrix3d WellConstrainedProjector(const Eigen::Matrix3d& H, double length_m, double ratio,
                                         int* degenerate_dims = nullptr);

// Log-likelihood of the scan points (base frame) at a pose (points in unexplored cells scored at
// the mean of the others, see above); `inliers` counts observed points inside the field
// (optional).
double ScanLogLikelihood(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& points_base,
                         const fl::Pose2& T_world_base, const MatcherOptions& options,
                         int* inliers = nullptr);

// Refines `initial` so the points fall on obstacles of `grid`.
MatchResult MatchScan(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& points_base,
                      const fl::Pose2& initial, const MatcherOptions& options);

}  // namespace fl::rbpf
