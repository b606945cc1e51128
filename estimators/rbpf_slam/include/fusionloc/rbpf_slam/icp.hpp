// Point-to-line ICP between 2D scans (keyframe factors and loop-closure verification).
//
// Finds T_ref_query minimising Σ_i e_i², e_i = n_jᵀ (R q_i + t − r_j), over pairs (q_i query
// point, r_j nearest reference point with unit normal n_j) closer than a correspondence distance
// that shrinks from max_correspondence_m to final_correspondence_m (Huber-weighted steps).
//
// COVARIANCE of (x, y, θ) at the solution, calibrated from the fit itself:
//   H  = Σ J_iᵀ J_i,  J_i = [ n_jᵀ , n_jᵀ R'(θ) q_i ]          (Gauss-Newton Hessian; J_i is
//        PoseJacobian(n_j, q_i, cos θ, sin θ) of scan_matcher.hpp)
//   M  = n/(n−3) Σ e_i² J_iᵀ J_i + min_sigma² H                  (residual-weighted: range noise
//        of both scans, normal and discretisation errors at this sensor; each pair with its own
//        residual, since noise depends on range and incidence: a beam grazing a wall has a
//        small point-to-line error, one hitting it square the full range noise)
//   ρ  = Σ e_i e_{i+1} / Σ e_i² over pairs of consecutive beams  (lag-1 correlation: neighbouring
//        residuals share a reference line, a normal error, a wall's bias)
//   κ  = (1 + ρ) / (1 − ρ), ρ clamped to [0, 0.95]              (AR(1) variance inflation: the
//        n residuals carry the information of n/κ independent ones)
//   Σ  = κ H⁺ M H⁺ + diag(floor_xy², floor_xy², floor_θ²)       (the heteroscedasticity-robust
//        "sandwich" covariance of least squares, plus a floor for errors no fit shows)
// H⁺ is the inverse over the eigen-directions of H (in the scaled coordinates (x, y, L·θ), L =
// RMS point range) whose eigenvalue is at least icp.degeneracy_ratio of the largest; the weaker
// ones (a corridor's axis, where the only "information" comes from normal noise on featureless
// walls) get the std max_sigma_xy (max_sigma_xy / L in heading). Every eigenvalue of Σ is finally
// capped at that value, so Ω = Σ⁻¹ is positive definite and says "unknown" along directions the
// scene does not constrain instead of trusting the initial guess there.
//
// NOISY SENSORS: a reference normal fitted within normal_radius of a scan whose range noise is
// comparable (the simulator's 10 cm in 0.3 m) follows the noise, often tens of degrees off the
// wall, and H then claims centimetres along a featureless corridor's axis. Each reference point
// also carries n_wide, fitted over a neighbourhood scaled to the scan's own noise
// (ComputeNormals with IcpOptions); the pairs and the fit stay those of n, but H and M are
// built with n_wide. The directions unconstrained with n_wide and constrained with n are
// counted in noise_made_dims. For scans whose noise needs no wider fit (n_wide = n), nothing
// changes.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/rbpf_slam/options.hpp"
#include "fusionloc/rbpf_slam/types.hpp"

namespace fl::rbpf {

// The scan's range noise [m], robustly: the median over consecutive triples of points (steps
// at most max_step) of the range's second difference |p[k−1]| − 2|p[k]| + |p[k+1]| (about zero
// on a smooth surface; 6σ² its variance from noise), divided by 0.6745·√6. Ranges are taken
// from the points' frame origin (the laser, or a base close to it). 0 if fewer than 10 triples.
double ScanRangeNoise(const std::vector<Eigen::Vector2d>& ordered_points, double max_step = 1.0);

// Estimates normals of points ordered along a scan by a line fit (PCA) over the neighbours in
// scan order within `radius` metres of the point, not crossing a gap between consecutive points
// larger than `max_gap`; points with fewer than 3 points in the fit or whose scatter is not a
// line (small / large eigenvalue > max_eigen_ratio) are dropped.
std::vector<PointNormal> ComputeNormals(const std::vector<Eigen::Vector2d>& ordered_points,
                                        double radius = 0.3, double max_eigen_ratio = 0.3,
                                        double max_gap = 0.3);

// The same with the fit adapted to the scan's own noise σ = ScanRangeNoise: radius
// max(normal_radius, normal_radius_per_noise·σ), gap max(normal_max_gap,
// normal_gap_per_noise·σ). A fit much narrower than the noise (10 cm noise in 0.3 m) returns
// normals that follow the noise, up to 90° off the surface, and they add "information" along a
// corridor's axis that the scene does not have.
std::vector<PointNormal> ComputeNormals(const std::vector<Eigen::Vector2d>& ordered_points,
                                        const IcpOptions& options);
// ... with the scan's noise already estimated (range_noise = ScanRangeNoise(ordered_points)).
std::vector<PointNormal> ComputeNormals(const std::vector<Eigen::Vector2d>& ordered_points,
                                        const IcpOptions& options, double range_noise);

// Σ and Ω = Σ⁻¹ as documented above from H = Σ JᵀJ, M = Σ e² JᵀJ over n pairs and the
// residual correlation ρ; `length_m` is the scale L of the heading (RMS point range). Returns
// the number of unconstrained directions of H.
int IcpCovariance(const Eigen::Matrix3d& H, const Eigen::Matrix3d& M, int n, double correlation,
                  double length_m, const IcpOptions& options, Eigen::Matrix3d* covariance,
                  Eigen::Matrix3d* information);

struct IcpResult {
  bool ok = false;               // converged and passed the quality checks
  fl::Pose2 T_ref_query;
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();  // (x, y, θ) of T_ref_query = Σ⁻¹
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();   // Σ (see above)
  Eigen::Matrix3d hessian = Eigen::Matrix3d::Zero();      // H = Σ JᵀJ at the solution
  double sigma = 0.0;            // [m] σ̂, the per-pair residual std used in Σ
  double correlation = 0.0;      // [-] ρ, lag-1 correlation of the residuals
  int degenerate_dims = 0;       // directions of H with (almost) no information
  int noise_made_dims = 0;       // of those, directions only the normals' noise constrained
                                 // (the point's own normals do, the wide ones do not)
  double length_m = 1.0;         // [m] L, the RMS query range: H's directions are in (x, y, L·θ)
  double rms = 0.0;              // [m] point-to-line RMS over the final pairs
  double inlier_fraction = 0.0;  // [-] paired query points / query points
  int pairs = 0;
  int iterations = 0;
  bool converged = false;        // the last step was below 1e-5 m / rad
  bool failed_only_rms = false;  // every check passed but the RMS gate (options.max_rms)
  std::string failure;           // why !ok
};

IcpResult AlignPointToLine(const std::vector<PointNormal>& reference,
                           const std::vector<Eigen::Vector2d>& query, const fl::Pose2& initial,
                           const IcpOptions& options);

}  // namespace fl::rbpf
