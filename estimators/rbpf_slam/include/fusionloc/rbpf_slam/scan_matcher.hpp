// Scan-to-map matching on the likelihood field: the improved proposal of the particle filter
// and its observation model (the paper's eq. 3).
//
// Observation model: a beam end point p (in the world) at distance d(p) from the nearest
// obstacle has likelihood  p(z | x, m) = z_hit * exp(-d² / 2σ²) + z_rand.
// Matching: Gauss-Newton / Levenberg-Marquardt on Σ_i d(T_world_base * p_base,i)² over the
// points inside the field (d < field_max_distance), with the interpolated field gradient:
//   ∂d/∂(x, y, θ) = ∇dᵀ [ I₂ | R'(θ) p_base ],  R'(θ) = dR/dθ.
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
  bool ok = false;              // converged, enough inliers, correction within bounds
};

// Log-likelihood of the scan points (base frame) at a pose; `inliers` counts points inside the
// field (optional).
double ScanLogLikelihood(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& points_base,
                         const fl::Pose2& T_world_base, const MatcherOptions& options,
                         int* inliers = nullptr);

// Refines `initial` so the points fall on obstacles of `grid`.
MatchResult MatchScan(const TiledGrid& grid, const std::vector<Eigen::Vector2d>& points_base,
                      const fl::Pose2& initial, const MatcherOptions& options);

}  // namespace fl::rbpf
