// Point-to-line ICP between 2D scans (keyframe factors and loop-closure verification).
//
// Finds T_ref_query minimising Σ_i ( n_jᵀ (R q_i + t − r_j) )² over pairs (q_i query point,
// r_j nearest reference point with unit normal n_j) closer than a correspondence distance that
// shrinks from max_correspondence_m to final_correspondence_m. At convergence the information
// of (x, y, θ) is the Gauss-Newton Hessian  Ω = Σ J_iᵀ J_i / σ²,
//   J_i = [ n_jᵀ , n_jᵀ R'(θ) q_i ],
// with σ = IcpOptions::sigma (the point-to-line noise), i.e. the inverse of the covariance
// the fit supports; directions the scene does not constrain (a corridor) get little information.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/rbpf_slam/options.hpp"
#include "fusionloc/rbpf_slam/types.hpp"

namespace fl::rbpf {

// Estimates normals of points ordered along a scan (from neighbours within `max_gap` metres);
// points whose normal cannot be estimated are dropped.
std::vector<PointNormal> ComputeNormals(const std::vector<Eigen::Vector2d>& ordered_points,
                                        double max_gap = 0.3);

struct IcpResult {
  bool ok = false;               // converged and passed the quality checks
  fl::Pose2 T_ref_query;
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();  // (x, y, θ) of T_ref_query
  double rms = 0.0;              // [m] point-to-line RMS over the final pairs
  double inlier_fraction = 0.0;  // [-] paired query points / query points
  int pairs = 0;
  int iterations = 0;
  bool converged = false;        // the last step was below 1e-5 m / rad
  std::string failure;           // why !ok
};

IcpResult AlignPointToLine(const std::vector<PointNormal>& reference,
                           const std::vector<Eigen::Vector2d>& query, const fl::Pose2& initial,
                           const IcpOptions& options);

}  // namespace fl::rbpf
