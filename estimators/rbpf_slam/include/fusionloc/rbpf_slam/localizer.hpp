// Monte Carlo localization on a saved map (what AMCL and slam_toolbox's localization mode give):
// the SLAM's particle filter with its map frozen. Same likelihood field (TiledGrid), same
// scan-matching proposal and weights (scan_matcher.hpp: MatchScan, ScanLogLikelihood), same
// odometry motion model; no mapping, no keyframe graph.
//
// Per processed scan (after linear_update / angular_update of odometry motion, like the SLAM):
//   1. Predict: every particle samples the odometry step (motion.srr/srt/str/stt);
//   2. Correct: the sample is refined by scan-to-map matching and weighted by the likelihood
//      field, log w += log p(z | x, m) / matcher.likelihood_gain (the SLAM's improved proposal);
//   3. Check: the fit of the scan (mean log-likelihood per beam at the best-fitting particle) is
//      compared with lost_log_likelihood; after lost_updates bad updates in a row the whole map
//      is searched (a global initialisation on this scan), and if the scan fits the best place
//      found by relocalize_min_gain more than where the filter is, the filter moves there: it
//      was lost (a kidnapped robot) or, if it never fitted since an initial pose, the initial
//      pose was wrong; either is reported (LocalizationResult), never followed silently. If no
//      place fits better (people around the robot, a stretch where the map is wrong) the
//      filter stays and says so (relocalization_refused). relocalize: false reports at once;
//   4. Resample (N_eff < neff_threshold · N) with KLD sampling (Fox 2003): particles are drawn
//      until their count reaches the KLD bound for the number of (x, y, θ) bins they occupy,
//      within [min_particles, max_particles]; a tight cloud needs few particles, a spread one
//      many.
// Initialisation: around an initial pose (SetInitialPose: a Gaussian with initial_sigma_xy /
// initial_sigma_theta, since bot_core.pose_t carries no covariance), or, without one or when
// lost, globally over the free space: every global_step_m on the known-free cells and every
// global_step_rad of heading is scored with ScanLogLikelihood on global_beams beams; the best
// global_hypotheses are refined by MatchScan and become the particles.
// Output: the weighted mean of the particles within cluster_radius_m / cluster_radius_rad of the
// most likely one (so that a multi-modal cloud is not averaged across its modes), at every scan
// (between filter updates: that pose plus the odometry since), and, while localized, a
// relative-pose factor between consecutive keyframes (every keyframe_distance /
// keyframe_angle), whose covariance is the two poses' cluster covariances (plus a floor)
// carried into the relative pose, for the fusion as the SLAM's ICP factors.
//
// Frames: poses in and out are in the map's frame (the frame of the occupancy grid's origin).
// Not thread-safe; one instance per laser. No LCM (lcm/localizer_lcm.hpp adapts).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/rbpf_slam/options.hpp"
#include "fusionloc/rbpf_slam/scan_input.hpp"
#include "fusionloc/rbpf_slam/tiled_grid.hpp"
#include "fusionloc/rbpf_slam/types.hpp"

namespace fl::rbpf {

// A static occupancy map, as map_server holds it (fusionloc.occupancy_grid_t without LCM).
struct OccupancyMap {
  double resolution = 0.05;   // [m] side of a cell
  double origin_x = 0.0;      // [m] map-frame position of the lower-left corner of cell (0, 0)
  double origin_y = 0.0;      // [m]
  int width = 0;              // [cells] along x
  int height = 0;             // [cells] along y
  std::vector<int8_t> cells;  // row-major from the lowest y: -1 unknown, 0 (free) .. 100 (occupied)
};

// Options of the localizer (config/localizer.yaml). Every field has its default inline;
// Validate() explains what is wrong and how to fix it.
struct LocalizerOptions {
  // ---- particles (KLD sampling, Fox 2003) ----
  int min_particles = 30;       // [-] fewest particles (the SLAM runs 30 with the same proposal)
  int max_particles = 1000;     // [-] most particles
  double kld_epsilon = 0.05;    // [-] bound on the KL divergence between the particle set and
                                //     the posterior (AMCL's pf_err)
  double kld_z = 2.33;          // [-] upper standard-normal quantile of 1 - δ (δ = 0.01; AMCL's
                                //     pf_z is 0.99, the same δ)
  double kld_bin_xy = 0.25;     // [m] KLD histogram bin size in x and y
  double kld_bin_theta = 0.17;  // [rad] ... and in heading (about 10°)
  double neff_threshold = 0.5;  // [-] resample when N_eff < neff_threshold * N (as the SLAM)
  double linear_update = 0.2;   // [m] run the filter only after this much odometry travel ...
  double angular_update = 0.1;  // [rad] ... or this much rotation (as the SLAM)
  // ---- initial pose (INITIAL_POSE is a bot_core.pose_t: no covariance, hence these) ----
  double initial_sigma_xy = 0.3;     // [m] std of the particles drawn around an initial pose
  double initial_sigma_theta = 0.2;  // [rad]
  // ---- global initialisation over the free space (no initial pose, or lost) ----
  double global_step_m = 0.25;   // [m] lattice step of the candidate positions (free cells)
  double global_step_rad = 0.1;  // [rad] heading step of the candidates
  int global_beams = 60;         // [-] beams (evenly spread) scoring each candidate
  double global_sigma = 0.15;    // [m] std of the likelihood field scoring the candidates: wider
                                 //     than matcher.sigma, since a candidate on the lattice is
                                 //     up to half a step (and half a heading step) off
  int global_hypotheses = 200;   // [-] best candidates refined by scan matching: the particles
  // ---- lost / wrong initial pose ----
  double lost_log_likelihood = -0.5;  // [-] a filter update whose best particle fits the scan
                                      //     with a mean log-likelihood per beam below this is a
                                      //     bad update (0 = every beam on an obstacle; about -3
                                      //     = no beam within the field); see docs/RBPF_SLAM.md
  int lost_updates = 5;               // [-] this many bad updates in a row: the filter is
                                      //     lost (or, before any good update since an initial
                                      //     pose, that pose is wrong) ...
  bool relocalize = true;             // [-] ... then the whole map is searched (a global
                                      //     initialisation) and the filter moves to the best
                                      //     place if the scan fits there better (below); only
                                      //     then is it reported lost / the initial pose
                                      //     rejected. false: reported at once, no search
  double relocalize_min_gain = 0.5;   // [-] the searched place must fit the scan by this much
                                      //     more (mean log-likelihood per beam) than where the
                                      //     filter is; else the filter stays (a map wrong
                                      //     there, people around: no better place exists)
  // ---- output ----
  double cluster_radius_m = 0.5;           // [m] particles this close to the best one form the
  double cluster_radius_rad = 0.5;         // [rad] ... cluster whose weighted mean is the pose
  double keyframe_distance = 0.5;          // [m] a relative-pose factor every this much travel ...
  double keyframe_angle = 0.35;            // [rad] ... or rotation (as the SLAM's keyframes)
  double factor_floor_sigma_xy = 0.02;     // [m] std added to each pose's cluster spread
  double factor_floor_sigma_theta = 0.01;  // [rad] (map and timing errors no spread shows)
  // ---- map and sensor ----
  double max_range = 30.0;          // [m] longer beams are ignored (as grid.max_range)
  double field_max_distance = 0.4;  // [m] the likelihood field's reach (as
                                    //     grid.field_max_distance; at most 15 map cells)
  int seed = 42;                    // [-] random seed (runs are reproducible)
  MotionOptions motion;             // the SLAM's motion model (options.hpp)
  MatcherOptions matcher;           // the SLAM's scan matcher and likelihood field (options.hpp)

  template <class A>
  void Serialize(A* a) {
    a->Visit("min_particles", &min_particles);
    a->Visit("max_particles", &max_particles);
    a->Visit("kld_epsilon", &kld_epsilon);
    a->Visit("kld_z", &kld_z);
    a->Visit("kld_bin_xy", &kld_bin_xy);
    a->Visit("kld_bin_theta", &kld_bin_theta);
    a->Visit("neff_threshold", &neff_threshold);
    a->Visit("linear_update", &linear_update);
    a->Visit("angular_update", &angular_update);
    a->Visit("initial_sigma_xy", &initial_sigma_xy);
    a->Visit("initial_sigma_theta", &initial_sigma_theta);
    a->Visit("global_step_m", &global_step_m);
    a->Visit("global_step_rad", &global_step_rad);
    a->Visit("global_beams", &global_beams);
    a->Visit("global_sigma", &global_sigma);
    a->Visit("global_hypotheses", &global_hypotheses);
    a->Visit("lost_log_likelihood", &lost_log_likelihood);
    a->Visit("lost_updates", &lost_updates);
    a->Visit("relocalize", &relocalize);
    a->Visit("relocalize_min_gain", &relocalize_min_gain);
    a->Visit("cluster_radius_m", &cluster_radius_m);
    a->Visit("cluster_radius_rad", &cluster_radius_rad);
    a->Visit("keyframe_distance", &keyframe_distance);
    a->Visit("keyframe_angle", &keyframe_angle);
    a->Visit("factor_floor_sigma_xy", &factor_floor_sigma_xy);
    a->Visit("factor_floor_sigma_theta", &factor_floor_sigma_theta);
    a->Visit("max_range", &max_range);
    a->Visit("field_max_distance", &field_max_distance);
    a->Visit("seed", &seed);
    a->Visit("motion", &motion);
    a->Visit("matcher", &matcher);
  }
  Status Validate() const;
};

// What the localizer is doing.
enum class LocalizerState {
  kWaiting,     // no scan yet
  kConverging,  // initialised (initial pose or global), not yet confirmed by a good update
  kLocalized,   // the last update fitted the map
  kLost,        // lost_updates bad updates in a row, not relocalizing (relocalize: false)
};
const char* LocalizerStateName(LocalizerState state);

// What AddScan did with one scan.
struct LocalizationResult {
  bool processed = false;                                // the filter ran on this scan
  fl::Pose2 T_map_base;                                  // the pose at the scan time, map frame
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // of the pose's cluster (x, y, θ)
  LocalizerState state = LocalizerState::kWaiting;
  int particles = 0;  // particle count after this scan
  double neff = 0.0;  // effective sample size of this update's weights
  bool resampled = false;
  double fit = 0.0;                     // mean log-likelihood per beam at the best-fitting particle
  int bad_updates = 0;                  // bad updates in a row so far
  bool initialized_from_pose = false;   // this scan drew the particles around an initial pose
  bool global_initialization = false;   // this scan started a global initialisation
  bool initial_pose_rejected = false;   // this scan rejected the initial pose (it did not fit)
  bool lost = false;                    // this scan found the filter lost (it had fitted before)
  bool relocalization_refused = false;  // lost_updates bad fits, but the search of the whole map
                                        // found no place that fits better: the filter stayed
  double search_fit = 0.0;              // that search's best fit (when one ran on this scan)
  bool odometry_jump = false;           // the odometry step was flagged as a jump, not trusted
  std::vector<KeyframeFactor> factors;  // relative-pose factors completed at this scan
  int valid_beams = 0;
};

struct LocalizerStats {
  int64_t scans = 0;                   // accepted scans
  int64_t processed = 0;               // filter updates
  int64_t dropped_time_backwards = 0;  // scans whose time did not increase
  int64_t rejected_bad_scan = 0;       // beam count / geometry changed, non-finite odometry
  int64_t invalid_beams = 0;           // NaN / inf / zero / over-range beams ignored
  int64_t odometry_jumps = 0;
  int64_t resamples = 0;
  int64_t match_failures = 0;           // particle updates whose match fell back to the sample
  int64_t bad_updates = 0;              // updates below lost_log_likelihood
  int64_t initial_poses = 0;            // initial poses applied
  int64_t initial_pose_rejections = 0;  // ... found wrong
  int64_t lost_detections = 0;          // lost after having fitted (kidnapped robot)
  int64_t global_initializations = 0;   // the particles replaced by a search of the whole map
  int64_t relocalizations_refused = 0;  // searches after bad fits that found no better place
  int64_t factors = 0;
  int max_particles_used = 0;  // largest particle count so far
};

class MonteCarloLocalizer {
 public:
  // Throws std::invalid_argument if options.Validate() fails or the map is malformed or has no
  // occupied cell.
  MonteCarloLocalizer(const LocalizerOptions& options, const OccupancyMap& map);

  // Sets the laser pose in the base frame (before the first scan; identity until then).
  fl::Status SetBaseLaser(const fl::Pose2& T_base_laser);
  // The robot's pose in the map frame: the next scan draws the particles around it (a Gaussian
  // of initial_sigma_xy / initial_sigma_theta) and runs the filter on that scan. Error (and
  // ignored) if not finite or outside the map.
  fl::Status SetInitialPose(const fl::Pose2& T_map_base);

  // Processes one scan with the odometry pose (T_odom_base) at the scan time. Returns an error
  // (and changes nothing) for a scan whose time does not increase, whose beam count or geometry
  // differs from the first scan, or with a non-finite odometry pose. The first scan
  // initialises the filter (around the initial pose if one was set, else globally).
  fl::Status AddScan(const LaserScan& scan, const fl::Pose2& odom_pose, LocalizationResult* result);

  // ---- the stages (public so that each can be tested) ----
  // Draws min_particles particles around `T_map_base` (initial_sigma_*).
  void InitializeAround(const fl::Pose2& T_map_base);
  // Global initialisation with the points (base frame) of the current scan; returns the best
  // hypothesis' fit (mean log-likelihood per point; -inf if there was nothing to score).
  double InitializeGlobal(const std::vector<Eigen::Vector2d>& points_base);
  // Every particle samples the odometry step `delta` (jump: the step was not trusted).
  void Predict(const fl::Pose2& delta, bool jump);
  // Scan matching and weighting of every particle; returns the fit (mean log-likelihood per
  // point) at the best-fitting particle.
  double Correct(const std::vector<Eigen::Vector2d>& points_base);
  // KLD-sampling resampling (always resamples); returns the new particle count.
  int ResampleKld();
  // KLD bound: particles needed for `bins` occupied bins (Fox 2003, eq. 13), before clamping.
  static int KldParticleCount(int bins, double epsilon, double z);
  // The weighted mean and covariance of the particles near the most likely one (map frame).
  fl::Pose2 ClusterMean(Eigen::Matrix3d* covariance = nullptr) const;

  // Current pose estimate (map frame) with the odometry since the last update.
  fl::Pose2 CurrentPose() const;
  LocalizerState state() const { return state_; }
  int num_particles() const { return static_cast<int>(particles_.size()); }
  // Particle poses (map frame) and normalised weights.
  std::vector<fl::Pose2> ParticlePoses() const;
  std::vector<double> NormalizedWeights() const;
  const LocalizerStats& stats() const { return stats_; }
  const LocalizerOptions& options() const { return opt_; }
  // The likelihood field of the map (grid frame: the map frame shifted by map_offset()).
  const TiledGrid& grid() const { return grid_; }
  // map frame = grid frame + this translation (under half a cell: the map's origin is not
  // a multiple of its resolution).
  Eigen::Vector2d map_offset() const { return offset_; }
  // Known-free cell centres (map frame) on the global lattice.
  std::vector<Eigen::Vector2d> GlobalCandidates() const;

 private:
  struct Particle {
    fl::Pose2 pose;  // grid frame
    double log_w = 0.0;
  };
  fl::Pose2 ToMap(const fl::Pose2& g) const {
    return {g.x + offset_.x(), g.y + offset_.y(), g.theta};
  }
  fl::Pose2 ToGrid(const fl::Pose2& m) const {
    return {m.x - offset_.x(), m.y - offset_.y(), m.theta};
  }
  void ConvertScan(const LaserScan& scan, LocalizationResult* result);
  int BestIndex() const;
  // Runs the correction on this scan's points and the lost / rejection logic.
  void Update(LocalizationResult* result);
  void MaybeAddFactor(fl::Utime utime, const fl::Pose2& pose, const Eigen::Matrix3d& covariance,
                      LocalizationResult* result);

  LocalizerOptions opt_;
  Eigen::Vector2d offset_ = Eigen::Vector2d::Zero();  // before grid_: its constructor sets it
  TiledGrid grid_;
  std::vector<Eigen::Vector2d> free_cells_;  // grid frame, on the global lattice
  fl::Pose2 T_base_laser_;
  std::mt19937 rng_;
  std::vector<Particle> particles_;

  LocalizerState state_ = LocalizerState::kWaiting;
  std::optional<fl::Pose2> pending_initial_pose_;  // map frame
  bool from_initial_pose_ = false;  // initialised from an initial pose, not yet fitted
  bool fitted_since_init_ = false;  // a good update since the last initialisation
  int bad_in_a_row_ = 0;

  ScanInput input_;              // validation, stamps, odometry with jumps removed
  fl::Pose2 odom_at_processed_;  // input_.odom() at the last filter update
  bool pending_jump_ = false;
  fl::Pose2 estimate_;  // cluster mean at the last update (grid frame)

  // Keyframes of the published factors.
  bool have_keyframe_ = false;
  int keyframe_id_ = -1;
  fl::Utime keyframe_utime_ = 0;
  fl::Pose2 keyframe_pose_;  // map frame
  Eigen::Matrix3d keyframe_cov_ = Eigen::Matrix3d::Zero();

  std::vector<Eigen::Vector2d> hits_base_, match_base_;
  LocalizerStats stats_;
};

// The likelihood field of a static map (cells >= occupied_percent are obstacles, cells in
// [0, free_percent] known free, the rest unknown; map_saver's 65 / 25) in the grid frame, cell
// (i, j) of the map at grid cell (i + round(origin_x / res), j + round(origin_y / res));
// `offset` (optional) receives map frame - grid frame. Throws std::invalid_argument for a
// malformed map.
TiledGrid GridFromOccupancyMap(const OccupancyMap& map, const GridOptions& grid_options,
                               Eigen::Vector2d* offset = nullptr, int occupied_percent = 65,
                               int free_percent = 25);

}  // namespace fl::rbpf
