// Laser RBPF-SLAM (GMapping-style Rao-Blackwellised particle filter) refined by ICP keyframe
// constraints and a Ceres pose graph with loop closures (MSIF paper, §1 and §1.2).
//
// Per processed scan (after linear_update / angular_update of odometry motion):
//   1. every particle samples the odometry motion model (srr/srt/str/stt);
//   2. the sample is refined by scan-to-map matching on the particle's own likelihood field
//      (improved proposal) and its weight is multiplied by p(z | x, m) (eq. 3);
//   3. N_eff = 1 / Σ w̃² ; systematic resampling only when N_eff < N_th (eq. 4);
//   4. the scan is integrated into each particle's copy-on-write tiled map.
// Keyframes (every keyframe_distance / keyframe_angle of the best particle) get a point-to-line
// ICP factor to the keyframe the filter is anchored to (the previous one, or on a revisit the
// existing keyframe it reused instead of adding one: graph.reuse_*) (and, in the internal graph, a filter edge holding the
// keyframe where the filter put it, for what ICP leaves free); loop closures are searched by
// proximity and verified by ICP against a local submap; the pose graph is optimised with Ceres
// and the correction is fed back: the particles' maps are rebuilt from the corrected keyframes
// and their poses shifted by the correction of the latest keyframe.
//
// Not thread-safe; one instance per laser. No LCM: the process rbpf_slam_main.cpp adapts.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <random>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/rbpf_slam/icp.hpp"
#include "fusionloc/rbpf_slam/options.hpp"
#include "fusionloc/rbpf_slam/pose_graph.hpp"
#include "fusionloc/rbpf_slam/scan_input.hpp"
#include "fusionloc/rbpf_slam/tiled_grid.hpp"
#include "fusionloc/rbpf_slam/types.hpp"

namespace fl::rbpf {

// What AddScan did with one scan.
struct ScanResult {
  bool processed = false;         // the filter ran (the robot had moved enough since the last one)
  fl::Pose2 T_world_base;         // best estimate at the scan time
  double neff = 0.0;              // effective sample size after this scan's weights
  bool resampled = false;
  bool odometry_jump = false;     // the odometry step was flagged as a jump and not trusted
  bool new_keyframe = false;
  // AddScan(..., defer_keyframe = true) only: the keyframe stage still has to run (FinishScan).
  bool keyframe_pending = false;
  std::vector<KeyframeFactor> factors;  // new ICP factors (sequential and loop closures)
  bool graph_changed = false;     // keyframe poses were corrected by the pose graph
  int valid_beams = 0;            // beams used (others were NaN, inf, <= 0 or over range)
};

// The valid beams of `scan` (finite, > 0 and <= max_range) as points in the base frame, in
// beam order; `points_base` is cleared first. Returns the number of beams left out.
int ScanToBasePoints(const LaserScan& scan, const fl::Pose2& T_base_laser, double max_range,
                     std::vector<Eigen::Vector2d>* points_base);

struct RbpfSlamStats {
  int64_t scans = 0;                    // accepted scans
  int64_t processed = 0;                // scans the filter ran on
  int64_t dropped_time_backwards = 0;   // scans whose time did not increase (and late scans
                                        //     PlaceLateScan could not place)
  int64_t rejected_bad_scan = 0;        // beam count / geometry changed, non-finite odometry
  int64_t invalid_beams = 0;            // NaN / inf / zero / over-range beams ignored
  int64_t map_integrations_refused = 0; // scans a particle's map (or a rebuilt map) left out:
                                        // beyond grid.max_size_m or absurd coordinates
  int64_t skipped_fast_turn = 0;        // scans not used: odometry turning > max_turn_rate
  int64_t matched_between_updates = 0;  // scans between updates matched alone (their pose)
  int64_t scans_refined = 0;            // scan poses refined by ICP against their keyframe
                                        //     (refine_scans_with_icp)
  int64_t turn_searches = 0;            // scans in or just after a fast turn that the
                                        //     refinement could not place, searched against
                                        //     their keyframe (turn_search)
  int64_t turn_scans_placed = 0;        // ... and placed by the search and ICP
  int64_t late_scans_placed = 0;        // scans delivered after newer ones, placed by their
                                        //     stamp (PlaceLateScan); refused ones count as
                                        //     dropped_time_backwards
  int64_t odometry_jumps = 0;
  int64_t resamples = 0;
  int64_t match_failures = 0;           // particle updates that fell back to odometry
  int64_t matcher_evaluations = 0;      // scan-matcher cost evaluations (passes over the points)
  int64_t degenerate_matches = 0;       // particle updates with a degenerate direction (corridor)
  int64_t keyframes = 0;
  int64_t icp_failures = 0;             // sequential keyframe ICP that failed verification
  int64_t noisy_factors = 0;            // ... of which published anyway: only the RMS gate, at
                                        //     the scan's noise (graph.noisy_factor_rms_per_noise)
  int64_t loop_candidates = 0;
  int64_t loop_searches = 0;            // correlative searches after a failed loop ICP
  int64_t loop_searches_skipped = 0;    // ... not run: ICP failed on partial overlap only
                                        //     (graph.loop_search_after_partial_overlap)
  int64_t loop_closures = 0;            // verified, added to the graph and kept
  int64_t loop_rejections = 0;          // loop edges dropped after optimisation (gross residual)
  int64_t optimizations = 0;            // pose-graph optimisations (each up to 5 Ceres solves)
  int64_t map_rebuilds = 0;             // corrections fed back to the filter
  int64_t map_rebuilds_continued = 0;   // ... that continued the previous rebuild's map
  int64_t divergences = 0;              // keyframes where ICP from odometry overruled the filter
  int64_t degenerate_kept = 0;          // keyframes moved to the odometry's motion along a
                                        // direction ICP could not see (degenerate_from_odometry)
  int64_t recoveries = 0;               // keyframes where the lost-track search moved the filter
  int64_t keyframe_reuses = 0;          // keyframes due where an existing one was reused (revisit)
  int64_t reuse_rejections = 0;         // ... where the nearby one did not verify (a new one came)
  int64_t reuse_corrections = 0;        // reuses that moved the filter onto the map (> feedback
                                        //     correction)
  int64_t keyframes_bounded = 0;        // keyframes due where the place was full
                                        //     (graph.max_keyframes_per_place) and the reuse did
                                        //     not verify: anchored to the nearest unverified
};

class RbpfSlam {
 public:
  // Throws std::invalid_argument if options.Validate() fails.
  explicit RbpfSlam(const RbpfSlamOptions& options);

  // Processes one scan with the odometry pose (T_odom_base) at the scan time. Returns an error
  // (and changes nothing) for a scan whose time does not increase, whose beam count or
  // geometry differs from the first scan, or with a non-finite odometry pose.
  //
  // With defer_keyframe (for a caller that publishes the pose at once, such as the LCM node),
  // AddScan returns after the filter: result->T_world_base is the filter's pose, and
  // result->keyframe_pending says that the keyframe stage (keyframe, ICP factors, divergence
  // check, loop closures, pose graph) is still to run; FinishScan(result) runs it, fills in the
  // factors and the pose it corrected. The filter's state afterwards is the same as without
  // deferring. A pending stage left when the next AddScan comes is run by it first, its
  // factors put in that scan's result.
  fl::Status AddScan(const LaserScan& scan, const fl::Pose2& odom_pose, ScanResult* result,
                     bool defer_keyframe = false);
  void FinishScan(ScanResult* result);

  // A scan delivered after newer ones were processed (delayed or reordered by the network), at
  // most options.late_scan_max_age_s older than the newest: placed by its stamp without the
  // filter, the maps or the graph seeing it. Its pose is the final pose of the scan before it
  // carried by the odometry between the two, refined by ICP against that scan's keyframe as
  // refine_scans_with_icp refines every scan; *T_world_base gets it and, with the scan path
  // kept, the scan enters Trajectory() in time order. Error (counted, nothing changes) for a
  // stamp already taken (a repeated message), one older than that or than every scan kept,
  // one not older than the newest (AddScan's), or a scan AddScan would refuse.
  fl::Status PlaceLateScan(const LaserScan& scan, const fl::Pose2& odom_pose,
                           fl::Pose2* T_world_base);

  // Final pose-graph optimisation (call at the end of a log before Trajectory()).
  void Finish();

  fl::Pose2 CurrentPose() const;
  // Pose of every accepted scan (the final, smoothed trajectory at the sensor rate): keyframe
  // poses from the graph composed with the scan's pose relative to its keyframe (the best
  // particle's, refined by ICP against the keyframe's scan: refine_scans_with_icp); a scan
  // the filter did not run on is blended between the filtered scans around it (the next
  // one's correction of the odometry spread over the scans before it).
  // Without the scan path (SetKeepScanPath(false)): KeyframePoses().
  std::vector<StampedPose2> Trajectory() const;
  std::vector<StampedPose2> KeyframePoses() const;
  // Whether every scan's record is kept for Trajectory() (default: yes). It costs 64 bytes per
  // accepted scan (2.3 MB per hour of a 10 Hz laser), unbounded on a robot that runs for hours,
  // so the LCM node keeps it only when asked (--scan-trajectory). false drops what was kept.
  void SetKeepScanPath(bool keep);
  bool keeps_scan_path() const { return keep_scan_path_; }
  // The keyframe pose graph (nodes = keyframes; ICP, filter, weak and loop-closure edges).
  const PoseGraph2D& graph() const { return graph_; }
  // Map of the best particle.
  const TiledGrid& BestMap() const;
  std::vector<double> NormalizedWeights() const;
  int num_particles() const { return static_cast<int>(particles_.size()); }
  const RbpfSlamStats& stats() const { return stats_; }
  const RbpfSlamOptions& options() const { return opt_; }
  // Sets the laser pose in the base frame (before the first scan; identity until then). It is
  // the robot description's (LASER_TO_BASE, docs/ROBOT.md), not an option.
  fl::Status SetBaseLaser(const fl::Pose2& T_base_laser);

  // N_eff = 1 / Σ w_i² of normalised weights.
  static double EffectiveSampleSize(const std::vector<double>& normalized_weights);
  // Systematic (low-variance) resampling: the parent index of each of the n new particles.
  static std::vector<int> SystematicResample(const std::vector<double>& normalized_weights,
                                             double u0);

 private:
  struct PathRecord {
    fl::Utime utime;
    int keyframe;          // latest keyframe when the scan arrived
    fl::Pose2 T_kf_base;   // pose relative to that keyframe
    fl::Pose2 odom;        // odometry pose (flagged jumps removed) at the scan
    bool filtered;         // its pose is scan-matched (the filter ran on it, or it was matched
                           //     alone between updates: match_between_updates)
  };
  struct Keyframe {
    fl::Utime utime;
    std::vector<Eigen::Vector2d> points_base;  // valid hits, base frame, scan order
    std::vector<PointNormal> normals_base;
    double path_length;                       // [m] travelled when created
    fl::Pose2 odom;                           // odometry pose (flagged jumps removed) then
    int64_t odometry_jumps = 0;               // flagged odometry jumps before it
    double range_noise = 0.0;                 // [m] ScanRangeNoise of its scan
  };
  struct Particle {
    fl::Pose2 pose;
    double log_w = 0.0;
    TiledGrid map;
  };
  // The keyframe the filter is anchored to: the newest one, or on a revisit the existing one it
  // reused. The next keyframe is due, and its edges and factors start, from the anchoring scan.
  struct Anchor {
    int keyframe = -1;
    fl::Pose2 T_kf_anchor;        // the anchoring scan in the keyframe's frame (identity for a
                                  //     new keyframe; the filter's pose on a reuse)
    fl::Pose2 odom;               // odometry pose (flagged jumps removed) at the anchoring scan
    int64_t odometry_jumps = 0;   // flagged odometry jumps before it
    bool reused = false;          // an existing keyframe reused on a revisit
  };

  // An accepted scan, kept for late_scan_max_age_s: late scans are placed from these.
  struct RecentScan {
    fl::Utime utime;
    int keyframe;
    fl::Pose2 T_kf_base;
    fl::Pose2 odom;      // flagged jumps removed (PathRecord::odom)
    fl::Pose2 odom_raw;  // as it came
  };

  void ConvertScan(const LaserScan& scan, ScanResult* result);
  // Into path_ (if kept) and recent_ (the current scan; input_.odom_raw() is its raw odometry).
  void RecordScan(const PathRecord& record);
  // The current scan's pose T_world_base against the anchor keyframe's scan: refined
  // (RefineAgainstKeyframe), or if that failed and the scan is in or just after a fast turn,
  // placed by the turn search (SearchAgainstKeyframe); true if *T_world_base moved.
  bool PlaceAgainstKeyframe(fl::Utime utime, fl::Pose2* T_world_base);
  // The anchor keyframe the current scan is placed against; nullptr if there is none or the
  // scan is its own.
  const Keyframe* PlacementKeyframe(fl::Utime utime) const;
  // Correlative search (turn_search) around T_world_base, then ICP; true if ICP passed its
  // checks with every direction constrained (then *T_world_base moved there).
  bool SearchAgainstKeyframe(fl::Utime utime, fl::Pose2* T_world_base);
  // ICP from T_world_base (refine_scans_with_icp); true if refined within the bounds.
  bool RefineAgainstKeyframe(fl::Utime utime, fl::Pose2* T_world_base);
  // ICP of points_base against `keyframe` (at T_world_kf) from *T_world_base; true (and
  // *T_world_base moved) if it passed its checks with every direction constrained and moved the
  // pose by at most refine_max_correction_m / _rad.
  bool RefineAgainst(const Keyframe& keyframe, const fl::Pose2& T_world_kf,
                     const std::vector<Eigen::Vector2d>& points_base,
                     fl::Pose2* T_world_base) const;
  void ProcessFilter(const fl::Pose2& delta, bool jump, ScanResult* result);
  bool Integrate(Particle* p);
  // Integrates points (base frame) seen from T_world_base into map.
  bool IntegrateInto(TiledGrid* map, const fl::Pose2& T_world_base,
                     const std::vector<Eigen::Vector2d>& points_base);
  // Whether a best-particle pose would become a keyframe (distance or angle from the anchor).
  bool KeyframeDue(const fl::Pose2& pose) const;
  void MaybeAddKeyframe(fl::Utime utime, ScanResult* result);
  // Revisit (graph.reuse_*): the keyframes at least loop_min_travel back along the path within
  // reuse_distance and reuse_angle of `pose`: the nearest (-1 if none) and how many.
  struct Revisit {
    int nearest = -1;
    int count = 0;
  };
  Revisit EarlierKeyframesNear(const fl::Pose2& pose) const;
  // Anchors the filter to keyframe c for this scan at `pose` if ICP of the scan against c
  // verifies within the reuse correction; the factor from c to the scan goes in result.
  bool ReuseKeyframe(int c, fl::Utime utime, const fl::Pose2& pose, ScanResult* result);
  // The odometry's relative pose from anchor `from`'s keyframe to keyframe j.
  fl::Pose2 OdometryFromAnchor(const Anchor& from, int j) const;
  // ICP's relative pose with its components along the unconstrained directions of its Hessian
  // (icp.degeneracy_ratio) replaced by odom_rel's (graph.degenerate_from_odometry).
  fl::Pose2 OdometryAlongDegenerate(const IcpResult& icp, const fl::Pose2& odom_rel) const;
  // The motion model's std (σ_xy [m], σ_θ [rad]) for the odometry's motion from anchor `from`
  // to keyframe j, times `scale`, at least graph.filter_edge_min_sigma_*.
  Eigen::Vector2d OdometrySigma(const Anchor& from, int j, double scale) const;
  // χ² of a relative pose T_i_j from `from`'s keyframe to keyframe j against the odometry's
  // (OdometryFromAnchor), whitened by OdometrySigma with scale 1.
  double OdometryChi2(const Anchor& from, int j, const fl::Pose2& T_i_j) const;
  // Lost-track search for new keyframe j (options.hpp, recovery_*), `map_before_scan` the best
  // particle's map before j's scan entered it, `icp_from_filter` the successful ICP against
  // keyframe i from the filter's pose (nullptr if it failed: then a correlative search
  // proposes the candidate): true if the filter's pose `pose` should move to `*corrected`;
  // `*icp` is then ICP against keyframe i from there (ok false if it failed).
  // `odom_rel` is the odometry's relative pose from keyframe i to j.
  bool SearchLostTrack(int i, int j, const fl::Pose2& pose, const fl::Pose2& odom_rel,
                       const TiledGrid& map_before_scan, const IcpResult* icp_from_filter,
                       fl::Pose2* corrected, IcpResult* icp) const;
  // Moves the newest keyframe j from `pose` to `corrected`, the particles with it, and
  // rebuilds their maps from the keyframes.
  void CorrectNewestKeyframe(int j, const fl::Pose2& pose, const fl::Pose2& corrected);
  void SearchLoopClosure(int kf, ScanResult* result);
  // The points of keyframe `cand` and its loop_submap_half_width neighbours on each side, in
  // cand's base frame; only keyframes at least loop_min_travel of path before `path_length`.
  std::vector<PointNormal> LoopSubmap(int cand, double path_length) const;
  // Matches keyframe j against the submap around keyframe `cand` (correlative search, then
  // ICP); true and the ICP result if verified.
  bool VerifyLoopClosure(int cand, int j, IcpResult* icp);
  Eigen::Matrix3d GraphEdgeInformation(const IcpResult& icp) const;
  // The filter edge from anchor `from`'s keyframe to the new keyframe j at their current graph
  // poses (options.hpp, graph.filter_edges).
  PoseGraphEdge FilterEdge(const Anchor& from, int j) const;
  // The published factor of an ICP result between keyframes i and j (calibrated information).
  KeyframeFactor Factor(int i, int j, const IcpResult& icp, bool is_loop_closure) const;
  bool OptimizeAndFeedBack(ScanResult* result);
  void RebuildMaps();
  int BestIndex() const;

  RbpfSlamOptions opt_;
  fl::Pose2 T_base_laser_;
  std::mt19937 rng_;
  std::vector<Particle> particles_;
  int best_ = 0;

  ScanInput input_;              // validation, stamps, odometry with jumps removed
  fl::Pose2 odom_at_processed_;  // input_.odom() when the filter last ran
  std::optional<fl::Utime> last_fast_turn_;  // the latest scan taken in a fast turn
  bool pending_jump_ = false;
  bool keyframe_pending_ = false;  // AddScan deferred the keyframe stage of ...
  fl::Utime pending_utime_ = 0;    // ... the scan at this time
  double path_length_ = 0.0;

  // Per-scan buffers (reused).
  std::vector<Eigen::Vector2d> hits_base_;     // valid beams within max range, base frame
  std::vector<Eigen::Vector2d> match_base_;    // every beam_step-th of them
  std::vector<Eigen::Vector2d> endpoints_world_;
  std::vector<uint8_t> is_hit_;

  std::vector<Keyframe> keyframes_;
  Anchor anchor_;
  // The best particle's map before the scan of a keyframe-to-be entered it (lost-track search);
  // a copy-on-write copy, held only until the keyframe is added.
  std::optional<TiledGrid> pre_scan_map_;
  // The last map rebuild and the keyframe poses it used (RebuildMaps continues it when they
  // did not change).
  TiledGrid rebuild_map_;
  std::vector<fl::Pose2> rebuild_poses_;
  PoseGraph2D graph_;
  int graph_loop_edges_ = 0;
  int last_closure_keyframe_ = -1;  // newest keyframe with an accepted loop closure (-1: none)
  int optimized_loop_edges_ = 0;
  bool keep_scan_path_ = true;
  std::vector<PathRecord> path_;  // every accepted scan (if keep_scan_path_)
  std::deque<RecentScan> recent_;  // accepted scans of the last late_scan_max_age_s, in order
  RbpfSlamStats stats_;
};

}  // namespace fl::rbpf
