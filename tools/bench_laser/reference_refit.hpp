// Reference refit: how far do a log's own scans and odometry pull its reference trajectory?
//
// The benchmark's corrected CARMEN logs come with "corrected" poses that are themselves the
// output of a SLAM system. RefitReference builds the maximum-a-posteriori problem of the data
// under this estimator's measurement models and solves it starting AT the reference:
//   nodes  T_world_base(k), one per scan, started at the reference pose;
//   odometry edges k-1 → k: the odometry's relative pose, Ω = diag(1/σ_xy², 1/σ_xy², 1/σ_θ²)
//          with σ_xy = max(min_sigma_xy, trans_per_m·d + trans_per_rad·|Δθ|),
//               σ_θ  = max(min_sigma_rad, rot_per_rad·|Δθ| + rot_per_m·d) of the odometry's
//          motion (d, Δθ) (for synthetic noise: the model that generated it);
//   ICP edges i → k: point-to-line ICP (icp.hpp) of scan k against scan i, started at the
//          reference's relative pose, with ICP's calibrated information and a Huber loss, for
//          i = k-1 and the max_pairs nearest earlier scans within pair_radius_m (by the
//          reference); results that fail ICP's checks or move farther than max_icp_move_* from
//          the start are left out (a different basin, not a correction).
// Levenberg-Marquardt (node 0 fixed) then moves the nodes to where odometry and scans agree
// best. The distance of that optimum from the reference (e.g. its ATE) is how much the data,
// read through these models, disagrees with the reference: an estimator that trusts its ICP as
// much as ICP's information says cannot be expected to end closer to the reference than that.
// It is not a bound for estimators with other scan models or weights.
#pragma once

#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/rbpf_slam/options.hpp"
#include "fusionloc/rbpf_slam/types.hpp"

namespace fl::rbpf {

// Odometry noise per step (see above); RefitOdometrySigma::FromMotion gives the filter's model.
struct RefitOdometrySigma {
  double trans_per_m = 0.05;      // [m/m]
  double trans_per_rad = 0.01;    // [m/rad]
  double rot_per_rad = 0.05;      // [rad/rad]
  double rot_per_m = 0.01;        // [rad/m]
  double min_sigma_xy = 0.001;    // [m]
  double min_sigma_rad = 0.0005;  // [rad]

  static RefitOdometrySigma FromMotion(const MotionOptions& m);
};

struct RefitOptions {
  double pair_radius_m = 4.0;     // [m] ICP edges to earlier scans this close (by the reference)
  int max_pairs = 10;             // [-] ... at most this many, nearest first (plus scan k-1)
  double max_icp_move_m = 0.3;    // [m] ICP results moved farther from the start are left out
  double max_icp_move_rad = 0.1;  // [rad]
  double icp_huber = 3.0;         // [-] Huber scale on the whitened ICP residual (0 = none)
  int max_iterations = 200;       // [-] Levenberg-Marquardt iterations

  Status Validate() const;
};

// One scan of the log with the odometry and the reference pose at its time.
struct RefitScan {
  LaserScan scan;
  fl::Pose2 T_odom_base;
  fl::Pose2 T_world_base_reference;
};

struct RefitResult {
  std::vector<fl::Pose2> T_world_base;  // the optimum, one per input scan
  int odometry_edges = 0;
  int icp_edges = 0;          // ICP edges used
  int icp_left_out = 0;       // candidate pairs whose ICP failed or moved too far
  double initial_cost = 0.0;  // ½ Σ whitened squared residuals at the reference
  double final_cost = 0.0;    // ... at the optimum
};

// T_base_laser is the laser's mounting (the robot description's; identity for the CARMEN
// importer's logs, whose LASER is in the laser frame). Scans must be in time order with the same
// beam geometry (beams over icp's grid max range, NaN, inf and <= 0 are ignored). Throws
// std::invalid_argument for bad options or fewer than 2 scans.
RefitResult RefitReference(const std::vector<RefitScan>& scans, const fl::Pose2& T_base_laser,
                           const RbpfSlamOptions& options, const RefitOdometrySigma& sigma,
                           const RefitOptions& refit);

}  // namespace fl::rbpf
