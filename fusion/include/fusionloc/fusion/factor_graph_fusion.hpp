// FactorGraphFusion: the MSIF fusion back-end (section 3). Laser-rate robot poses are the
// graph's nodes; laser between-factors from the RBPF-SLAM (eqs. 13-15), vision between-
// factors between stereo keyframes (eqs. 17-19), wheel odometry and a prior on the first pose
// are its factors; each costs d(e) = e^T Omega e (eqs. 11-12), optionally through a robust
// loss. Pure library: no LCM (the process fl-fusion adapts messages to these verbs).
//
// STATE: SE(2). A ground robot's laser, its RBPF map and its wheel odometry are planar, so
// every node is T_map_base = (x, y, theta) with a Pose2Manifold (wrapped angle). The SE(3)-
// with-planar-prior alternative would add three weakly observed dimensions per node (z,
// roll, pitch) that only the vision factors see, for no gain in the planar pose that the
// robot and the laser map need, and at twice the solve cost.
//
// VISION FACTORS IN SE(2): a relative_pose_factor_t is already expressed between robot BASE
// frames (the VO applies the camera-to-base extrinsic T_base_camera: T_bi_bj =
// T_b_c T_ci_cj T_c_b, with the information transformed by the adjoint). Its 6-DoF
// measurement is projected to (x, y, yaw of the rotated x axis) and its 6x6 information
// Omega is reduced by MARGINALISATION, not by cutting rows: Sigma = Omega^-1, keep the
// (x, y, yaw) block of Sigma (rows/cols 0, 1, 5), invert. Cutting the information rows
// instead would ignore the correlation with z/roll/pitch and be over-confident. Planar
// producers (laser) fill only rows/cols 0, 1, 5 (the rest zero): that 3x3 block is used
// directly.
//
// LATE LASER POSES: nodes are a chain in time order, so a laser pose that arrives after a newer
// one (late or reordered by the network) adds no node. PlaceLateLaserPose() places it by its
// stamp instead: on the timeline entry (active or retired node) nearest to it, within
// attach_max_gap_s, through the RBPF's own motion between the two,
//     T_map_t = T_map_n * T_rbpf(n)^-1 * T_rbpf(t),
// so that the scan still gets its fused pose. A stamp that already has a node or was placed
// (a repeated message) is rejected and counted, never placed twice. Late odometry is inserted in
// time order while the samples around it are still kept (AddOdometry).
//
// LASER OUTAGE: when no laser pose comes (a laser unplugged, the RBPF-SLAM down or refusing a
// jumping clock) the graph would have no node to put the vision factors on and the robot no
// fused pose. Once the wheel odometry runs odometry_nodes_after_s ahead of the newest laser pose,
// AddOdometry adds a node every odometry_node_period_s after the newest node, up to the
// odometry's time (the first ones fill the second it took to notice), each placed by the
// odometry's motion from the node before (which also stands in for the RBPF pose there, for the
// time interpolation below); its odometry factor and the vision factors of its times attach as
// for a laser node, so the VO corrects the odometry's drift until the laser is back. A laser pose
// from before the newest odometry node is then placed by its stamp (LATE LASER POSES); the next
// newer one is a node again; one of an odometry node's own stamp takes that node over
// (TakeOverOdometryNode: its RBPF pose replaces the stand-in; no second node). No odometry nodes before the first laser pose (it fixes the map
// frame) or without odometry around the newest node.
//
// ASYNCHRONOUS SENSORS / TIME ATTACHMENT: nodes exist at laser times (10 Hz); a factor's
// times utime_i, utime_j (e.g. 2 Hz vision keyframes) are attached to the NEAREST node if it
// is within attach_tolerance_s, or, when laser scans were lost, to the nearer of the two nodes
// around it if they are at most attach_max_gap_s apart; the time offset between the factor time t
// and its node time n is then corrected by INTERPOLATING the RBPF poses of the two nodes around t:
//     T_n_t = T_rbpf(n)^-1 * Interp(T_rbpf(a), T_rbpf(b), (t - a) / (b - a))
//     Interp(A, B, s) = A * Exp(s * Log(A^-1 B))   (SE(2) constant-velocity arc)
//     measurement used:  T_ni_nj = T_ni_ti * T_ti_tj * T_tj_nj
// (the information is kept: the correction spans < one laser period). A factor whose time
// lies beyond the newest node waits (pending) until the laser node for that time exists, so
// factors that arrive early, late or out of order are placed by their timestamps alone. A
// factor whose time has no node within the tolerance (before the first node, in a laser
// gap) is rejected with a counted warning, as is any factor with NaNs, a non-symmetric,
// singular or indefinite information, or both times on the same node. A rejected input never
// changes the graph.
//
// LASER CHAIN: the RBPF publishes a scan-matched pose per scan but ICP factors only between
// its keyframes, so a node pair between keyframes needs another factor. Wheel odometry is the
// first choice: it is independent of the laser, and along a corridor (where scan matching is
// degenerate and the RBPF slides) it is what keeps the along-axis motion right. A *chain*
// factor from the pair of consecutive RBPF poses (noise model chain_sigma_*, robust loss: the
// RBPF pose can jump when the filter resamples or its graph corrects) fills in only where
// odometry does not (laser_chain_factors = "odometry_gaps", the default): every pair when
// use_wheel_odometry is off, and pairs the odometry does not cover (a sample gap larger
// than odom_max_gap_s, or odometry later than odom_max_latency_s behind the newest node).
// "always" adds it to every pair (the RBPF pose already contains the odometry, so with
// odometry factors as well the odometry counts twice), "never" to none.
//
// WHEEL ODOMETRY: integrated poses T_odom_base; for each pair of consecutive nodes the
// odometry pose is interpolated at both node times and the relative motion becomes a
// between-factor with a motion-proportional noise model (options odom_*). Odometry later than
// the nodes is applied as soon as it covers them.
//
// INCREMENTAL OPTIMISATION (section 3.2): Update() optimises only the newest window_size
// nodes, holding the nodes just before the window constant (they fix the gauge); if new
// factors reach further back (a late factor), the window is extended down to the oldest
// affected node, up to max_window_nodes. A loop closure, a late factor beyond that reach, or
// every full_solve_every_n_nodes nodes, requests a full solve of the whole graph. FullSolve()
// runs it synchronously; for a non-blocking solve, PrepareFullSolve() copies the graph into
// a FullSolveJob whose Run() needs no access to this object (run it on another thread while
// this object keeps taking nodes and running Update()), then ApplyFullSolve() merges the
// result: nodes solved by the job take its values, nodes added meanwhile are moved rigidly
// with the newest solved node. Gauge: a prior on the first node (prior_sigma_*).
// Nodes that no factor touches (e.g. laser scans between RBPF keyframes while no vision
// factor arrives) are not optimised: after each solve they are placed by the RBPF's relative
// motion from the constrained nodes on both sides, blended linearly in time.
//
// BOUNDED GRAPH (a robot that runs for hours): nodes older than active_window_s behind the
// newest leave the optimised graph, in batches of 10 s of nodes (never while a full-solve job
// is out, never the newest max_window_nodes nodes, never a node whose odometry pair is still
// open, never a node no solve has placed yet: a journal restore adds its nodes without
// solving, so they retire only after its final full solve). Their fused poses are frozen into the
// retired trajectory (Trajectory(), PoseAt() still give every node). A retired node is kept as a
// FIXED MAP NODE unless a map node already lies within map_node_spacing_m and map_node_spacing_rad
// of it (a region already mapped); then it is merged into the nearest such map node: every factor
// between it and an active node is re-anchored onto the map node,
//     T_a_j = T_a_d * T_d_j    (T_a_d = T_map_a^-1 T_map_d, both frozen: exact),
// and a factor whose ends are all fixed (no longer able to move anything) is dropped. The
// map nodes are held constant in every solve and give the gauge once the first node has
// retired; late factors whose times are retired attach to the retired node of their time,
// re-anchored onto its map node. So the graph holds the active window plus at most one map
// node per spacing cell of the area driven: it stops growing once the route is mapped. What
// it gives up: a loop closure corrects the active window, not the frozen past.
// INFORMATION UNDER RE-ANCHORING: with e the between-cost error (in frame i) of Z and
// Z' = P Z Q (P, Q exact), e' = A e to first order, A = [R_P, R_P R_Z perp(t_Q); 0 0 1]
// (perp(x, y) = (-y, x)), so Omega' = A^-T Omega A^-1 (also for the time-offset corrections
// of ASYNCHRONOUS SENSORS above).
//
// Thread safety: one thread uses the object; only FullSolveJob::Run() may run elsewhere.
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/state_buffer.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/fusion/retired_trajectory.hpp"

namespace fl::fusion {

enum class FactorSource : int8_t { kLaser = 0, kVision = 1, kWheelOdometry = 2 };
const char* FactorSourceName(FactorSource source);

// Mirrors fusionloc::relative_pose_factor_t: the pose of base frame j in base frame i.
struct RelativePoseFactor {
  Utime utime_i = 0;
  Utime utime_j = 0;
  Eigen::Isometry3d T_i_j = Eigen::Isometry3d::Identity();
  // Information of [dx dy dz droll dpitch dyaw]; planar producers fill rows/cols 0, 1, 5.
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  FactorSource source = FactorSource::kLaser;
  bool is_loop_closure = false;
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW
};

struct FusionOptions {
  double attach_tolerance_s = 0.06;        // [s] factor time to nearest laser node (10 Hz: 0.05)
  double attach_max_gap_s = 0.35;          // [s] or between two nodes at most this far apart
                                           // (scans lost: interpolated across the gap)
  int window_size = 20;                    // [nodes] optimised by each Update()
  int max_window_nodes = 200;              // [nodes] largest window a late factor may extend to;
                                           // reaching further back requests a full solve
  int window_max_iterations = 10;          // LM iterations of an incremental update
  int full_max_iterations = 50;            // LM iterations of a full solve
  int full_solve_every_n_nodes = 100;      // [nodes] periodic full solve (0: never)
  bool full_solve_on_loop_closure = true;  // a loop-closure factor requests a full solve
  std::string robust_loss = "cauchy";      // laser/vision factors: "none", "huber" or "cauchy"
  double robust_loss_scale = 3.0;          // [sigma] whitened error where the loss bends
  double prior_sigma_xy = 0.001;           // [m] prior on the first node (gauge)
  double prior_sigma_theta = 0.001;        // [rad]
  // RBPF pose chain (between-factors from consecutive RBPF poses; see the file comment):
  // "odometry_gaps" (node pairs that wheel odometry does not cover), "always" or "never".
  std::string laser_chain_factors = "odometry_gaps";
  double chain_sigma_xy_min = 0.01;         // [m] per node pair
  double chain_sigma_xy_per_m = 0.05;       // [m/m]
  double chain_sigma_theta_min = 0.005;     // [rad]
  double chain_sigma_theta_per_rad = 0.05;  // [rad/rad]
  bool use_wheel_odometry = true;           // odometry between-factors for consecutive nodes
  double odom_sigma_xy_min = 0.02;          // [m] odometry noise floor per node pair
  double odom_sigma_xy_per_m = 0.05;        // [m/m] odometry xy noise per metre travelled
  double odom_sigma_theta_min = 0.005;      // [rad] heading noise floor per node pair
  double odom_sigma_theta_per_rad = 0.05;   // [rad/rad] heading noise per radian turned
  double odom_sigma_theta_per_m = 0.01;     // [rad/m] heading noise per metre travelled
  double odom_max_gap_s = 0.5;              // [s] no odometry factor across a larger sample gap
  double odom_max_latency_s = 0.5;          // [s] a node pair still without odometry when the
                                            // newest node is this much newer is a gap
  // Laser outage (see the file comment, LASER OUTAGE): once the odometry runs this far ahead of
  // the newest laser pose, a node every odometry_node_period_s placed by the wheel odometry
  // (0: never; the fused pose then stops until the laser is back).
  double odometry_nodes_after_s = 1.0;      // [s] of data time
  double odometry_node_period_s = 0.1;      // [s] between odometry nodes
  int max_pending_factors = 1000;           // factors waiting for their laser node; oldest dropped
  bool compute_covariance = true;           // marginal covariance of the newest node per Update()
  // Bounded graph (see the file comment):
  double active_window_s = 300.0;     // [s] nodes older than this leave the optimised graph
                                      // (0: keep every node; the graph grows with time)
  double map_node_spacing_m = 1.0;    // [m] a retired node within this distance ...
  double map_node_spacing_rad = 0.5;  // [rad] ... and heading of a map node merges into it

  template <class A>
  void Serialize(A* a) {
    a->Visit("attach_tolerance_s", &attach_tolerance_s);
    a->Visit("attach_max_gap_s", &attach_max_gap_s);
    a->Visit("window_size", &window_size);
    a->Visit("max_window_nodes", &max_window_nodes);
    a->Visit("window_max_iterations", &window_max_iterations);
    a->Visit("full_max_iterations", &full_max_iterations);
    a->Visit("full_solve_every_n_nodes", &full_solve_every_n_nodes);
    a->Visit("full_solve_on_loop_closure", &full_solve_on_loop_closure);
    a->Visit("robust_loss", &robust_loss);
    a->Visit("robust_loss_scale", &robust_loss_scale);
    a->Visit("prior_sigma_xy", &prior_sigma_xy);
    a->Visit("prior_sigma_theta", &prior_sigma_theta);
    a->Visit("laser_chain_factors", &laser_chain_factors);
    a->Visit("chain_sigma_xy_min", &chain_sigma_xy_min);
    a->Visit("chain_sigma_xy_per_m", &chain_sigma_xy_per_m);
    a->Visit("chain_sigma_theta_min", &chain_sigma_theta_min);
    a->Visit("chain_sigma_theta_per_rad", &chain_sigma_theta_per_rad);
    a->Visit("use_wheel_odometry", &use_wheel_odometry);
    a->Visit("odom_sigma_xy_min", &odom_sigma_xy_min);
    a->Visit("odom_sigma_xy_per_m", &odom_sigma_xy_per_m);
    a->Visit("odom_sigma_theta_min", &odom_sigma_theta_min);
    a->Visit("odom_sigma_theta_per_rad", &odom_sigma_theta_per_rad);
    a->Visit("odom_sigma_theta_per_m", &odom_sigma_theta_per_m);
    a->Visit("odom_max_gap_s", &odom_max_gap_s);
    a->Visit("odom_max_latency_s", &odom_max_latency_s);
    a->Visit("odometry_nodes_after_s", &odometry_nodes_after_s);
    a->Visit("odometry_node_period_s", &odometry_node_period_s);
    a->Visit("max_pending_factors", &max_pending_factors);
    a->Visit("compute_covariance", &compute_covariance);
    a->Visit("active_window_s", &active_window_s);
    a->Visit("map_node_spacing_m", &map_node_spacing_m);
    a->Visit("map_node_spacing_rad", &map_node_spacing_rad);
  }
  Status Validate() const;
};

// What one optimisation did (Ceres-style summary for the status message).
struct SolveSummary {
  bool ran = false;         // false: nothing to optimise
  bool full = false;        // full solve (true) or incremental window (false)
  std::string termination;  // Ceres termination type, e.g. "CONVERGENCE"
  int iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double time_ms = 0.0;  // wall time of building + solving
  int num_nodes = 0;     // nodes optimised
  int num_factors = 0;   // factors in the problem
  // "full: CONVERGENCE, iterations 5, cost 3.2 -> 1.1, 40 nodes, 80 factors, 2.5 ms"; without
  // the time when `with_time` is false (for what a log replay publishes: reproducible bytes).
  std::string ToString(bool with_time = true) const;
};

// Counters of everything rejected or dropped (all also warned, rate-limited).
struct FusionCounters {
  int64_t nodes = 0;
  int64_t factors_added = 0;
  int64_t rejected_node_time = 0;        // laser pose not newer than the previous one
  int64_t rejected_non_finite = 0;       // NaN/Inf in a pose or factor
  int64_t rejected_information = 0;      // non-symmetric / singular / indefinite information
  int64_t rejected_no_node = 0;          // a factor time matches no node
  int64_t rejected_same_node = 0;        // both factor times on one node
  int64_t dropped_pending_overflow = 0;  // pending factors dropped (max_pending_factors)
  int64_t rejected_odometry = 0;         // odometry sample too old, repeated or non-finite
  int64_t late_laser_poses_placed = 0;   // laser poses older than the newest node, placed by
                                         //   their stamp (PlaceLateLaserPose), no node added
  int64_t late_odometry_placed = 0;      // odometry samples inserted before newer ones
  int64_t odometry_gaps = 0;             // node pairs without odometry coverage
  int64_t odometry_factors = 0;          // wheel-odometry between-factors added
  int64_t chain_factors = 0;             // RBPF pose-chain factors added
  int64_t odometry_nodes = 0;            // nodes placed by the wheel odometry (laser outage;
                                         //   not those a laser pose took over)
  int64_t full_solves = 0;
  int64_t updates = 0;
  int64_t retired_nodes = 0;       // nodes that left the optimised graph (bounded graph)
  int64_t merged_nodes = 0;        // ... of which merged into a map node (not kept)
  int64_t reanchored_factors = 0;  // factors moved from a merged node onto its map node
  int64_t retired_factors = 0;     // factors dropped: all their ends fixed
  int64_t rejected_total() const {
    return rejected_node_time + rejected_non_finite + rejected_information + rejected_no_node +
           rejected_same_node + dropped_pending_overflow + rejected_odometry;
  }
};

struct TrajectoryPoint {
  Utime utime = 0;
  Pose2 T_map_base;
};

class FactorGraphFusion;

// A copy of the whole graph, optimised without touching the FactorGraphFusion it came from.
class FullSolveJob {
 public:
  // Runs the full solve (thread-safe with respect to the originating FactorGraphFusion).
  void Run();
  const SolveSummary& summary() const { return summary_; }

 private:
  friend class FactorGraphFusion;
  struct JobFactor {
    int i = -1, j = -1;  // j = -1: unary (prior)
    std::shared_ptr<ceres::CostFunction> cost;
    std::shared_ptr<ceres::LossFunction> loss;
  };
  std::vector<Eigen::Vector3d> states_;
  std::vector<char> fixed_;  // map nodes: held constant
  std::vector<JobFactor> factors_;
  int max_iterations_ = 50;
  int num_factors_at_snapshot_ = 0;
  SolveSummary summary_;
};

class FactorGraphFusion {
 public:
  explicit FactorGraphFusion(const FusionOptions& options);
  ~FactorGraphFusion();
  FactorGraphFusion(FactorGraphFusion&&) noexcept;
  FactorGraphFusion& operator=(FactorGraphFusion&&) noexcept;

  // A laser-rate pose from the RBPF-SLAM (T_map_base at utime): creates a node. Times must
  // increase; the pose initialises the node (relative to the previous fused node) and
  // interpolates factor times. Returns an error (counted, graph unchanged) if rejected.
  Status AddLaserPose(Utime utime, const Pose2& T_map_base);
  // A laser pose not newer than the newest node (late on the network): no node; its fused pose
  // is placed by its stamp on the nearest node (see LATE LASER POSES above) into *out. Error
  // (counted as rejected_node_time, nothing changes) if that stamp has a node or was placed, if
  // the nearest node is more than attach_max_gap_s away or the stamp is before the first node.
  Status PlaceLateLaserPose(Utime utime, const Pose2& T_map_base, TrajectoryPoint* out);
  // Stamp of the newest node (0 if none): a laser pose at or before it is late.
  Utime newest_node_utime() const { return nodes_.empty() ? 0 : nodes_.back().utime; }
  // The newest node was placed by the wheel odometry (LASER OUTAGE).
  bool newest_node_from_odometry() const { return !nodes_.empty() && nodes_.back().from_odometry; }
  // LASER OUTAGE: a laser pose whose stamp is that of an active node the odometry placed
  // becomes that node's RBPF pose (no node added, its fused pose already out): true if it was
  // taken so; false if there is no such node (then it is a new or a late laser pose).
  bool TakeOverOdometryNode(Utime utime, const Pose2& T_map_base);
  // A relative-pose factor; attached to nodes by its times (see the file comment). OK also
  // when the factor waits for its laser node (pending).
  Status AddFactor(const RelativePoseFactor& factor);
  // An integrated wheel-odometry pose T_odom_base at utime. One older than the newest sample is
  // inserted in time order if the samples around it are still kept (else rejected, counted).
  Status AddOdometry(Utime utime, const Pose2& T_odom_base);

  // Incremental update of the window; cheap. Returns what it did.
  SolveSummary Update();
  // Full solve of the whole graph, synchronously.
  SolveSummary FullSolve();
  // True if a loop closure, a far-reaching late factor or the period asks for a full solve.
  bool full_solve_requested() const { return full_solve_requested_; }
  // Non-blocking full solve: snapshot -> job.Run() elsewhere -> ApplyFullSolve(job).
  std::unique_ptr<FullSolveJob> PrepareFullSolve();
  void ApplyFullSolve(const FullSolveJob& job);

  // Fused estimate of the newest node (false if there is no node yet).
  bool Latest(TrajectoryPoint* out) const;
  // Covariance of (x, y, theta) of the newest node from the last Update() (window-relative:
  // the nodes before the window are treated as known). Zero if unavailable.
  const Eigen::Matrix3d& latest_covariance() const { return latest_covariance_; }
  // Fused pose at any time inside the trajectory, interpolated between nodes.
  bool PoseAt(Utime utime, Pose2* T_map_base) const;
  // Fused pose of every laser scan at or after `from` (0: the whole trajectory), in time order.
  std::vector<TrajectoryPoint> Trajectory(Utime from = 0) const;

  // Nodes in the graph: the fixed map nodes and the active window.
  int num_nodes() const { return static_cast<int>(nodes_.size()); }
  int num_map_nodes() const { return num_fixed_; }
  int64_t num_retired_nodes() const { return static_cast<int64_t>(retired_.size()); }
  // The retired trajectory (in memory and spilled; spill_error()).
  const RetiredTrajectory& retired_trajectory() const { return retired_; }
  // Spills the retired trajectory older than the newest keep_in_memory poses into `file`, so
  // that memory and the saved state stay bounded on a robot that runs for days
  // (retired_trajectory.hpp). Only while nothing is retired (std::logic_error otherwise); a
  // LoadState keeps this object's file.
  void SpillRetiredTrajectory(std::shared_ptr<RetiredSpillFile> file,
                              size_t keep_in_memory = RetiredTrajectory::kDefaultKeepInMemory,
                              size_t batch = RetiredTrajectory::kDefaultSpillBatch) {
    retired_.SpillTo(std::move(file), keep_in_memory, batch);
  }
  // Poses at or before this time are final (retired, frozen); 0 while nothing is retired.
  Utime final_until() const { return retired_.empty() ? 0 : retired_.back().utime; }
  int num_factors() const { return static_cast<int>(factors_.size()); }
  int num_pending_factors() const { return static_cast<int>(pending_.size()); }
  const FusionCounters& counters() const { return counters_; }
  const SolveSummary& last_summary() const { return last_summary_; }
  const FusionOptions& options() const { return options_; }

  // Saved state (the fusion process's journal snapshot, FUSION.md "Respawn"): everything later
  // calls depend on (nodes, factors, pending factors, odometry, retired nodes, counters), so
  // that a fusion loaded from it and given the same inputs goes on exactly as this one would.
  // The options are not saved: the loader's are used (the caller checks they are the same).
  // Of a spilled retired trajectory only the count is saved: the loader must be bound to the
  // same file (SpillRetiredTrajectory), which must still hold those poses. Not while a full-solve job is outstanding (std::logic_error). LoadState replaces this
  // object's state, or throws StateError (naming the byte offset) and leaves it unchanged.
  void SaveState(StateWriter* out) const;
  void LoadState(StateReader* in);

 private:
  struct Node {
    Utime utime = 0;
    Pose2 T_map_base_rbpf;  // input pose (for initialisation/interpolation)
    Eigen::Vector3d state = Eigen::Vector3d::Zero();  // fused T_map_base (x, y, theta)
    std::vector<int> factors;                         // indices into factors_
    bool fixed = false;                               // a map node (retired, constant)
    bool from_odometry = false;  // placed by the wheel odometry in a laser outage
  };
  struct Factor {
    int i = -1, j = -1;  // node indices; j = -1 for the prior
    Pose2 T_i_j;
    Eigen::Matrix3d information = Eigen::Matrix3d::Zero();
    Eigen::Matrix3d sqrt_information = Eigen::Matrix3d::Zero();  // the cost's (MakeCost)
    FactorSource source = FactorSource::kLaser;
    bool is_loop_closure = false;
    bool is_prior = false;
    std::shared_ptr<ceres::CostFunction> cost;
    std::shared_ptr<ceres::LossFunction> loss;
  };
  struct PendingFactor {
    RelativePoseFactor factor;
    Pose2 T_i_j;
    Eigen::Matrix3d information;
    EIGEN_MAKE_ALIGNED_OPERATOR_NEW
  };
  struct OdomSample {
    Utime utime;
    Pose2 T_odom_base;
  };

  Status Reject(int64_t* counter, const std::string& message);
  // The cost and loss of `f` from its T_i_j, sqrt_information, source and is_prior: a prior
  // holds node i at T_i_j; wheel odometry is not robustified.
  void MakeCost(Factor* f) const;
  // Resolves a time to a node and the correction T_node_t; false if no node is near.
  bool Attach(Utime t, int* node, Pose2* T_node_t) const;
  Status AttachFactor(const RelativePoseFactor& f, const Pose2& T_i_j,
                      const Eigen::Matrix3d& information);
  void AddGraphFactor(Factor factor);
  void AttachPendingFactors();
  void AddOdometryFactors();
  void AddChainFactor(int j);  // between nodes j-1 and j, from their RBPF poses
  // Between-factor (j-1, j) with a diagonal noise model.
  void AddSequentialFactor(int j, const Pose2& motion, double sigma_xy, double sigma_theta,
                           FactorSource source);
  bool OdometryAt(Utime t, Pose2* T_odom_base) const;
  SolveSummary SolveWindow(int first_node);
  // Nodes (from `first` on) that no factor touches are placed by the RBPF's relative motion
  // from the constrained nodes before and after them (blended linearly in time).
  void FillUnconstrained(int first);
  // Bounded graph: retires the nodes older than active_window_s (see the file comment).
  void RetireOldNodes();
  // Appends `node` (newer than every node) and what follows from it: the gauge prior of the
  // first node, an RBPF chain factor (laser nodes), pending and odometry factors, retirement.
  void AddNode(Node node, bool from_laser);
  // LASER OUTAGE: a node at odometry time t if the laser has been silent long enough.
  void AddOdometryNodeIfLaserSilent(Utime t);
  // The input poses in time order: the retired nodes, then the active nodes.
  int TimelineSize() const;
  Utime TimelineUtime(int k) const;
  Pose2 TimelinePose(int k) const;  // fused pose of timeline entry k (frozen if retired)
  Pose2 TimelineRbpf(int k) const;
  // The first timeline entry at or after t (TimelineSize() if none).
  int TimelineLowerBound(Utime t) const;
  // The graph node and T_node_k of timeline entry k (a retired one: its map node).
  void TimelineNode(int k, int* node, Pose2* T_node_k) const;

  FusionOptions options_;
  std::deque<Node> nodes_;
  std::vector<Factor> factors_;
  std::deque<PendingFactor> pending_;
  std::deque<OdomSample> odometry_;
  // Stamps of the newest late laser poses placed (PlaceLateLaserPose): a repeat is refused.
  static constexpr size_t kMaxLatePlacedStamps = 4096;
  std::set<Utime> late_placed_;
  Utime newest_laser_utime_ = 0;  // newest laser pose taken (a node or placed late)
  int next_odom_pair_ = 1;        // next node j needing an odometry factor (j-1, j)
  int oldest_touched_node_ = -1;  // oldest node touched by factors since last Update
  bool full_solve_requested_ = false;
  int64_t nodes_at_last_full_solve_ = 0;  // counters_.nodes at the last full solve
  RetiredTrajectory retired_;  // the nodes that left the graph, their fused poses frozen
  int num_fixed_ = 0;             // nodes_[0, num_fixed_) are the map nodes
  bool job_outstanding_ = false;  // PrepareFullSolve() ... ApplyFullSolve(): indices held
  Utime optimised_until_ = 0;     // newest node of the last Update() or applied full solve
  Eigen::Matrix3d latest_covariance_ = Eigen::Matrix3d::Zero();
  SolveSummary last_summary_;
  FusionCounters counters_;
  std::unique_ptr<ceres::Manifold> manifold_;
  std::shared_ptr<ceres::LossFunction> robust_loss_;
  struct Warnings;
  std::unique_ptr<Warnings> warnings_;
};

// Reduces a 6x6 information of [x y z roll pitch yaw] to (x, y, yaw) by marginalisation (see
// the file comment). False (with a reason) if it is not finite, not symmetric, singular or
// indefinite.
// Information of Z' = P Z Q (P, Q exact) from that of Z: A^-T Omega A^-1 (see the file
// comment, INFORMATION UNDER RE-ANCHORING).
Eigen::Matrix3d TransformBetweenInformation(const Eigen::Matrix3d& information, const Pose2& P,
                                            const Pose2& Z, const Pose2& Q);

bool ReduceInformationToPlanar(const Eigen::Matrix<double, 6, 6>& information,
                               Eigen::Matrix3d* planar, std::string* reason);

}  // namespace fl::fusion
