// Options of the laser RBPF-SLAM estimator (config/rbpf_slam.yaml). Every field has its default
// inline; Validate() explains what is wrong and how to fix it.
#pragma once

#include <string>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"

namespace fl::rbpf {

// Occupancy grid and likelihood field.
struct GridOptions {
  double resolution = 0.05;        // [m] side of one grid cell
  double max_range = 30.0;         // [m] maximum usable range: longer beams are ignored (like NaN,
                                   //     inf and zero readings)
  double field_max_distance = 0.4; // [m] the likelihood field stores the distance to the nearest
                                   //     obstacle up to this value (≤ 15 cells); also the matcher's basin
  double log_odds_hit = 0.9;       // [-] log-odds added to a beam's end cell
  double log_odds_miss = -0.3;     // [-] log-odds added to every cell a beam passes through
  double log_odds_clamp = 4.0;     // [-] |log-odds| is clamped to this (keeps the map adaptable)
  double log_odds_occupied = 0.5;  // [-] a cell becomes an obstacle when its log-odds exceeds this
  double log_odds_free = 0.45;     // [-] ... and stops being one when it falls below this
                                   //     (hysteresis: keeps the likelihood field from flickering)
  int free_space_beam_step = 1;    // [-] clear free space along every n-th beam (1 = all beams)
  int free_space_margin = 4;       // [cells] a hit stops clearing this many cells before its end
                                   //     cell (0 = up to the end cell; keeps walls from eroding).
                                   //     At least 2 sigma of the laser's range noise: a shorter
                                   //     margin lets long readings clear the short readings' hits,
                                   //     so obstacles drift away from where they were seen from and
                                   //     the map grows (simulated URG, 10 cm noise: 3.2 % larger
                                   //     after 300 s with 1 cell, 0.4 % with 4; RBPF_SLAM.md)
  double max_size_m = 2000.0;      // [m] the map's bounding box grows to at most this a side; a
                                   //     scan that would grow it further is left out of the map
                                   //     and counted (map_integrations_refused): an odometry jump,
                                   //     or a place larger than configured. Bounds the tile table
                                   //     (2000 m at 5 cm: 6.3 MB per particle)

  template <class A>
  void Serialize(A* a) {
    a->Visit("resolution", &resolution);
    a->Visit("max_range", &max_range);
    a->Visit("field_max_distance", &field_max_distance);
    a->Visit("log_odds_hit", &log_odds_hit);
    a->Visit("log_odds_miss", &log_odds_miss);
    a->Visit("log_odds_clamp", &log_odds_clamp);
    a->Visit("log_odds_occupied", &log_odds_occupied);
    a->Visit("log_odds_free", &log_odds_free);
    a->Visit("free_space_beam_step", &free_space_beam_step);
    a->Visit("free_space_margin", &free_space_margin);
    a->Visit("max_size_m", &max_size_m);
  }
  Status Validate() const;
};

// Odometry motion model (GMapping's srr/srt/str/stt: noise std grows with the motion).
struct MotionOptions {
  double srr = 0.1;   // [m/m] translation noise per metre travelled
  double srt = 0.05;  // [m/rad] translation noise per radian turned
  double str = 0.05;  // [rad/m] rotation noise per metre travelled
  double stt = 0.1;   // [rad/rad] rotation noise per radian turned
  double max_odometry_jump_m = 3.0;      // [m] an odometry step longer than this between two
                                         //     scans is flagged as a jump and not trusted (the
                                         //     corrected CARMEN logs have steps up to 1.8 m)
  double max_odometry_jump_rad = 2.0;    // [rad] same for rotation (logs: up to 1.4 rad)
  double max_odometry_speed_mps = 2.0;   // [m/s] ... or, between scans further apart, longer
                                         //     than this speed times the time between them (a
                                         //     gap in the scans is not a jump of the odometry)
  double max_odometry_yaw_rate_rps = 2.0;  // [rad/s] same for rotation
  double jump_sigma_m = 0.3;             // [m] position noise used instead of a flagged jump
  double jump_sigma_rad = 0.3;           // [rad] heading noise used instead of a flagged jump

  template <class A>
  void Serialize(A* a) {
    a->Visit("srr", &srr);
    a->Visit("srt", &srt);
    a->Visit("str", &str);
    a->Visit("stt", &stt);
    a->Visit("max_odometry_jump_m", &max_odometry_jump_m);
    a->Visit("max_odometry_jump_rad", &max_odometry_jump_rad);
    a->Visit("max_odometry_speed_mps", &max_odometry_speed_mps);
    a->Visit("max_odometry_yaw_rate_rps", &max_odometry_yaw_rate_rps);
    a->Visit("jump_sigma_m", &jump_sigma_m);
    a->Visit("jump_sigma_rad", &jump_sigma_rad);
  }
  Status Validate() const;
  // Whether the odometry step T_prev_cur between two scans dt_s apart is a jump (a wheel-base
  // reset, a glitch): longer than max(max_odometry_jump_m, max_odometry_speed_mps * dt_s), or
  // turning more than max(max_odometry_jump_rad, max_odometry_yaw_rate_rps * dt_s).
  bool IsOdometryJump(const fl::Pose2& step, double dt_s) const;
};

// Scan-to-map matcher used as the improved proposal and the likelihood-field weights (eq. 3).
struct MatcherOptions {
  int beam_step = 1;               // [-] use every n-th beam for matching and weighting (2 halves
                                   //     the matcher cost but lost ~10x accuracy on Intel)
  int max_iterations = 12;         // [-] Gauss-Newton iterations per particle
  double converged_step = 1e-4;    // [m, rad] stop when a step is smaller in every component
  double function_tolerance = 3e-4;  // [-] ... or when an accepted step lowers the cost by
                                     //     less than this fraction of it (0 = off): a third
                                     //     fewer passes over the points at the same accuracy
                                     //     (12 seeds, BENCHMARKS.md)
  double sigma = 0.05;             // [m] std of the likelihood field (eq. 3)
  double z_hit = 0.95;             // [-] weight of the Gaussian part of the beam likelihood
  double z_rand = 0.05;            // [-] weight of the uniform part (random / unexplained beams)
  double likelihood_gain = 3.0;    // [-] log-likelihoods are divided by this (GMapping's "gain")
  double min_inlier_fraction = 0.3;// [-] a match with fewer beams inside the field falls back
                                   //     to the odometry prediction
  double max_correction_m = 0.5;   // [m] a match moving the pose farther than this is rejected
  double max_correction_rad = 0.35;// [rad] same for heading
  bool skip_unexplored = false;     // [-] end points in never-observed cells are left out of the
                                   //     matching and scored at the scan's mean (scan_matcher.hpp)
  double unexplored_margin = 0.2;  // [m] ... a point counts as observed if its cell or the cell
                                   //     this far back along its beam was (noisy hits just
                                   //     behind a wall or pillar)
  double degeneracy_ratio = 0.0;   // [-] a direction of (x, y, θ·L) whose Hessian eigenvalue is
                                   //     below this fraction of the largest is degenerate (a
                                   //     corridor's axis): the matcher does not move the pose
                                   //     along it, the motion model's sample stands (0 = off)

  template <class A>
  void Serialize(A* a) {
    a->Visit("beam_step", &beam_step);
    a->Visit("max_iterations", &max_iterations);
    a->Visit("converged_step", &converged_step);
    a->Visit("function_tolerance", &function_tolerance);
    a->Visit("sigma", &sigma);
    a->Visit("z_hit", &z_hit);
    a->Visit("z_rand", &z_rand);
    a->Visit("likelihood_gain", &likelihood_gain);
    a->Visit("min_inlier_fraction", &min_inlier_fraction);
    a->Visit("max_correction_m", &max_correction_m);
    a->Visit("max_correction_rad", &max_correction_rad);
    a->Visit("skip_unexplored", &skip_unexplored);
    a->Visit("unexplored_margin", &unexplored_margin);
    a->Visit("degeneracy_ratio", &degeneracy_ratio);
  }
  Status Validate() const;
};

// Point-to-line ICP between keyframe scans.
struct IcpOptions {
  int max_iterations = 30;            // [-]
  double max_correspondence_m = 0.5;  // [m] first-iteration pairing distance (shrinks to `final`)
  double final_correspondence_m = 0.15;  // [m]
  int min_points = 40;                // [-] fewer matched points: ICP fails
  double min_inlier_fraction = 0.5;   // [-] fraction of query points matched at the end
  double max_rms = 0.05;              // [m] RMS point-to-line residual at convergence
  double normal_radius = 0.3;         // [m] reference normals: line fit over the scan neighbours
                                      //     within this distance of the point
  double normal_max_eigen_ratio = 0.3;// [-] ... accepted if (small / large) scatter eigenvalue is
                                      //     below this (rejects corners and clutter)
  double normal_max_gap = 0.3;        // [m] ... not across a step between consecutive points
                                      //     larger than this
  double normal_radius_per_noise = 10.0;  // [-] with range noise σ estimated from each scan
  double normal_gap_per_noise = 6.0;      //     (icp.hpp), radius and gap are at least these
                                          //     multiples of σ (a noisy sensor: wider fits)
  // Covariance of the result (icp.hpp explains the model): Σ = κ σ̂² H⁻¹ + Σ_floor.
  double min_sigma = 0.005;           // [m] lower bound of the per-point residual std σ̂
  double floor_sigma_xy = 0.015;      // [m] Σ_floor: error no fit can remove (map, timing)
  double floor_sigma_theta = 0.0075;   // [rad]
  double max_sigma_xy = 2.0;          // [m] cap of the std along unconstrained directions (keeps
                                      //     the information positive definite for the fusion)
  double degeneracy_ratio = 0.05;     // [-] eigen-directions of H (in (x, y, L·θ)) weaker than
                                      //     this fraction of the strongest are unconstrained: the
                                      //     information there comes from normal noise on a
                                      //     featureless wall, not from structure (icp.hpp)

  template <class A>
  void Serialize(A* a) {
    a->Visit("max_iterations", &max_iterations);
    a->Visit("max_correspondence_m", &max_correspondence_m);
    a->Visit("final_correspondence_m", &final_correspondence_m);
    a->Visit("min_points", &min_points);
    a->Visit("min_inlier_fraction", &min_inlier_fraction);
    a->Visit("max_rms", &max_rms);
    a->Visit("normal_radius", &normal_radius);
    a->Visit("normal_max_eigen_ratio", &normal_max_eigen_ratio);
    a->Visit("normal_max_gap", &normal_max_gap);
    a->Visit("normal_radius_per_noise", &normal_radius_per_noise);
    a->Visit("normal_gap_per_noise", &normal_gap_per_noise);
    a->Visit("min_sigma", &min_sigma);
    a->Visit("floor_sigma_xy", &floor_sigma_xy);
    a->Visit("floor_sigma_theta", &floor_sigma_theta);
    a->Visit("max_sigma_xy", &max_sigma_xy);
    a->Visit("degeneracy_ratio", &degeneracy_ratio);
  }
  Status Validate() const;
};

// Keyframes, loop closures and the Ceres pose graph (the paper's §1.2 improvement).
// Correlative search of loop-closure candidates (correlative_matcher.hpp documents the method).
struct CorrelativeOptions {
  bool enabled = true;          // [-] false: loop closures are verified by ICP from the graph's
                                //     relative pose alone (converges only within ~0.3 m)
  double linear_window = 1.0;   // [m] search ± this in x and y around the graph's relative pose
  double angular_window = 0.2;  // [rad] search ± this in heading
  double angular_step = 0.0;    // [rad] 0 = resolution / (95th-percentile point range)
  double resolution = 0.05;     // [m] lookup-grid cell and translation step
  double sigma = 0.05;          // [m] width of the lookup kernel
  int coarse_factor = 4;        // [-] coarse translation step, in cells (>= 1)
  int max_points = 150;         // [-] query points used (evenly subsampled); 0 = all
  double min_score = 0.3;       // [-] best mean lookup value below this: no loop closure

  template <class A>
  void Serialize(A* a) {
    a->Visit("enabled", &enabled);
    a->Visit("linear_window", &linear_window);
    a->Visit("angular_window", &angular_window);
    a->Visit("angular_step", &angular_step);
    a->Visit("resolution", &resolution);
    a->Visit("sigma", &sigma);
    a->Visit("coarse_factor", &coarse_factor);
    a->Visit("max_points", &max_points);
    a->Visit("min_score", &min_score);
  }
  // `key` names the struct in the error messages (it is used twice in GraphOptions).
  Status Validate(const std::string& key = "graph.loop_search") const;
};

// Defaults of the lost-track search (GraphOptions::recovery_search): a window around the
// filter's pose as wide as an odometry error the matcher cannot correct (its basin is
// matcher.max_correction_*), and no score floor (the map decides, see recovery_min_gain).
inline CorrelativeOptions RecoverySearchDefaults() {
  CorrelativeOptions o;
  o.linear_window = 0.5;
  o.angular_window = 0.5;
  o.min_score = 0.0;
  return o;
}

// Defaults of the search that places a scan taken in a fast turn (RbpfSlamOptions::turn_search):
// a window as wide as the odometry's heading error there (raw CSAIL: up to ~25°).
inline CorrelativeOptions TurnSearchDefaults() {
  CorrelativeOptions o;
  o.linear_window = 0.5;
  o.angular_window = 0.45;
  return o;
}

struct GraphOptions {
  bool enabled = true;                 // [-] false: plain RBPF, no keyframe graph
  double keyframe_distance = 0.5;      // [m] new keyframe after this much travel
  double keyframe_angle = 0.35;        // [rad] or this much rotation
  double loop_search_radius = 3.0;     // [m] keyframes closer than this are loop candidates
  int loop_closure_spacing = 1;        // [keyframes] after a keyframe closed a loop, the next
                                       //     loop search is this many keyframes later (1 = at
                                       //     every keyframe); the first closure of a revisit is
                                       //     still searched for at every keyframe. 3 on
                                       //     the laser benchmark (seeds 1-4): intel 0.084 ->
                                       //     0.075 m at about half the time, csail 0.118 ->
                                       //     0.108, aces 0.244 -> 0.229, but raw CSAIL 0.099
                                       //     -> 0.110 m; hence 1
  int loop_max_candidates = 2;         // [-] candidates tried per new keyframe (nearest first,
                                       //     each from a different submap)
  double loop_min_travel = 10.0;       // [m] path length between candidate and current keyframe
  int loop_submap_half_width = 5;      // [-] keyframes on each side of a candidate merged as
                                       //     reference (more overlap, fewer missed closures)
  double loop_min_inlier_fraction = 0.6;  // [-] stricter ICP verification for loop closures
  double loop_max_rms = 0.04;          // [m]
  double loop_huber_m = 0.1;           // [m] robust loss scale on loop-closure edges
  double loop_max_residual_m = 0.3;    // [m] after optimisation, a loop edge still off by more
  double loop_max_residual_rad = 0.3;  // [rad] than this is rejected as wrong and re-optimised
                                       //     (1.0 m before the filter edges: the stiffer graph
                                       //     no longer bends to an aliased closure, which then
                                       //     stays 0.3-1 m off; at 1.0 m the simulated
                                       //     corridor's fusion got 0.71 m instead of 0.20 m)
  double edge_sigma = 0.3;             // [m] ICP edges of this internal graph weigh H/edge_sigma²
                                       //     (chosen on the multi-seed laser benchmark: 0.03
                                       //     made the chain too stiff for loop closures to
                                       //     bend, 1.0 let wrong closures in); 0 = use the
                                       //     calibrated information published to the fusion
                                       //     (icp.hpp). Published factors always carry the
                                       //     calibrated one.
  // Noisy scans: a sequential keyframe ICP that failed only its RMS gate (icp.max_rms), with
  // its RMS within noisy_factor_rms_per_noise times the keyframe scan's range noise
  // (ScanRangeNoise) and within 0.5 m / 0.3 rad of the filter's relative pose, is still
  // published as a factor (its calibrated information) for the fusion, which has no better
  // laser evidence between those keyframes; the internal graph keeps the filter's pose there (a
  // weak edge), since at that noise the filter's scan-to-map estimate beats a pairwise fit. In
  // the simulator (10 cm range noise) a right fit has an RMS of 5-7 cm and 61 of 81 keyframe
  // ICPs of `paper` failed the 5 cm gate, leaving the fusion 4-8 laser factors a run; these
  // factors' chi2 median there is 3.3 (calibrated: ~2.4-3). Letting them into the internal graph
  // too made the RBPF's own `paper` ATE 0.070 -> 0.111 m. The real logs (range noise <= 3 cm)
  // never reach it. 0 = off.
  double noisy_factor_rms_per_noise = 0.8;  // [-]
  // Filter edges: besides the ICP edge, an edge from keyframe i to the next keyframe j holding
  // j where the filter put it (after a divergence or lost-track correction), with the motion
  // model's std times filter_edge_sigma_scale: σ_xy = k (srr·d + srt·|Δθ|), σ_θ = k (stt·|Δθ| +
  // str·d) for the odometry's motion (d, Δθ) between the two keyframes, at least
  // filter_edge_min_sigma_*; Huber-robust. ICP edges are strong where the scene constrains
  // them and weak along a corridor's axis, where the few features ICP sees (door frames, range
  // noise on the walls) may put it 0.2-0.5 m off (ACES); there the filter's estimate (odometry
  // plus the scan-to-map match) holds the chain instead. Not added where ICP failed (the weak
  // edge holds j there) or across a flagged odometry jump. On the laser benchmark
  // (BENCHMARKS.md, 8 seeds, with loop_max_residual_m 0.3) they moved ACES 0.276 -> 0.228 m and
  // raw CSAIL 0.126 -> 0.101 m, csail-corrected 0.109 -> 0.114 and intel 0.089 -> 0.096 m.
  // Scale 1 (seeds 1-6) bent csail and intel more (0.142, 0.118 m). Odometry edges instead (the
  // odometry's own relative pose) helped the synthetic-noise logs but pulled raw CSAIL, whose
  // real odometry is biased (2 % short, turns 8 % short), from 0.12 to 0.23 m.
  bool filter_edges = true;
  double filter_edge_sigma_scale = 2.0;      // [-] k
  double filter_edge_min_sigma_m = 0.02;     // [m]
  double filter_edge_min_sigma_rad = 0.01;   // [rad]
  double filter_edge_huber = 3.0;            // [-] Huber scale on the whitened residual
  int max_iterations = 50;             // [-] Levenberg-Marquardt iterations per optimisation
  // [-] ... which also stops when a step lowers the cost by less than this fraction of it
  // (Ceres' default). 1e-4 is a fifth to a third faster on the laser logs but moves every run:
  // over 24 seeds raw CSAIL 0.1019 -> 0.1055 m, intel 0.0995 -> 0.0886 m (BENCHMARKS.md).
  double function_tolerance = 1e-6;
  bool feed_back = true;               // [-] rebuild the particle maps from the corrected keyframes
  double feedback_min_correction_m = 0.05;  // [m] ... when the newest keyframe moved this much
                                            //     (or 0.02 rad)
  CorrelativeOptions loop_search;      // correlative search before the ICP verification
  // [-] Loop ICP from the graph's relative pose that converged within 0.1 m / 0.05 rad of it,
  // with its RMS within loop_max_rms, failed only on the inlier fraction: the start was inside
  // ICP's basin and the overlap is what is missing. false: no correlative search then (intel,
  // seed 1: it ran 436 times and rescued 7 candidates; 177 of them were such failures and
  // rescued one, a fraction of 0.598; the other 176 led ICP to within 5 cm of where it was).
  bool loop_search_after_partial_overlap = false;
  bool divergence_check = true;        // [-] at each keyframe also run ICP from the odometry's
                                       //     relative pose; if it fits clearly better than the
                                       //     one from the filter's, the filter has locked onto
                                       //     a wrong match: its pose is corrected and its maps
                                       //     rebuilt from the keyframes
  double divergence_min_gain = 0.05;   // [-] inlier-fraction gain that counts as "clearly"
  // [-] The odometry's ICP also wins, though it fits no better, when the filter's relative pose
  // from the previous keyframe is this unlikely under the motion model (χ² of its difference
  // from the odometry's, 3 dof, with σ as for the filter edges at k = 1; 6.25 is the 90 %
  // quantile) and ICP from the odometry's fits nearly as well (RMS within
  // divergence_odometry_rms_ratio of the filter's). Along a featureless corridor both fit: the
  // scans do not constrain the axis, and the likelihood field pulls the filter toward the
  // map's frontier, 0.5 m per keyframe where the odometry says 1-2 m (chi² 40-50); there the
  // odometry's motion is kept. Simulated corridor, 3 seeds: RBPF ATE 6.79 -> 1.13 m (χ² 30:
  // 4.22, 9: 1.52, 4: 1.07); paper world and the real logs within their seed spread (RBPF_SLAM.md).
  // 0 = off.
  double divergence_odometry_chi2 = 6.25;
  double divergence_odometry_rms_ratio = 1.2;  // [-]
  // Along directions that only the scan's noise seemed to constrain (ICP's noise_made_dims: a
  // featureless corridor's axis seen by a noisy sensor, icp.hpp) a new keyframe takes the
  // odometry's motion since the previous one, not the filter's: its scan matcher is fooled by
  // the same noise (the map's texture) and measures the motion short there. Node j, its ICP
  // edge and the particles move by the difference along those directions (not across a flagged
  // odometry jump). Simulated corridor, 6 seeds: RBPF ATE 1.06 -> 0.17 m. Not along every
  // unconstrained direction: where clean scans leave a keyframe pair's axis free, the filter's
  // map still knows it (ACES 0.225 -> 0.73 m when it did, 6 seeds).
  bool degenerate_from_odometry = true;
  // Lost track (an odometry error beyond the matcher's reach, e.g. a 0.36 rad heading error in
  // one step): when ICP of a new keyframe against the previous one fails, the keyframe's scan
  // is searched against the previous keyframe's (correlative search, then scan-to-map match
  // from its best pose); if the scan fits the filter's map (before this scan entered it) better
  // there by recovery_min_gain per beam, the filter was lost: its pose is corrected and its
  // maps rebuilt from the keyframes (as for a divergence).
  CorrelativeOptions recovery_search = RecoverySearchDefaults();  // enabled: false = off
  // [-] When the filter's relative pose to the previous keyframe differs from the odometry's
  // (> 5 cm or 0.03 rad), the search also runs around the odometry's and the better score
  // wins: the filter may have been pulled away from a right odometry step, beyond the window
  // around its own pose (csail-corrected: 3 seeds in 24 ended 1.34-1.37 m off that way).
  bool recovery_search_from_odometry = true;
  double recovery_min_gain = 0.5;      // [-] mean log-likelihood gain per beam that counts
                                       //     (the scan-to-map fit of a keyframe varies by
                                       //     ~0.2 per beam between neighbouring poses)
  // Revisits (what keeps the keyframes, the graph and the map rebuilds bounded where the robot
  // has been before): when a keyframe is due, the filter's anchor closed a loop or is itself a
  // reuse, and a keyframe at least loop_min_travel back along the path lies within
  // reuse_distance and reuse_angle of the filter's pose, the scan is matched against the
  // submap around the nearest such keyframe (ICP from their graph poses, the loop closures'
  // submap and thresholds). If that verifies and moves the scan by less than
  // reuse_max_correction_m / _rad, the keyframe is reused: no node is added, the filter is
  // anchored to it (the next keyframe is due keyframe_distance from there; the scans are
  // stored relative to it), and a factor from it to the scan is published (is_loop_closure,
  // keyframe_id_j -1). A correction beyond feedback_min_correction_m (or 0.02 rad) moves the
  // particles onto the map and gives them the keyframes' map, as a loop closure's feedback
  // does. The first keyframes of a return are new and close the loop; a revisit that drifted
  // beyond the correction adds keyframes and closes its loop again. Reusing recent keyframes,
  // or before the loop closed, cost ACES 0.24 -> 1.3 m (3 seeds). reuse_distance 0 = off: a
  // keyframe every keyframe_distance for ever (the 30-minute soak, RELIABILITY.md: +816
  // keyframes and +10.7 MB per 10 minutes, map rebuilds of 2.5 s).
  // Distance and angle: the keyframe spacing, so every scan of a mapped path is within them of
  // a keyframe. Correction: in the simulator (10 cm range noise) the filter sits 5-15 cm off
  // the graph's keyframes on a revisit; larger offsets are left to the loop closures.
  double reuse_distance = 0.5;             // [m]
  double reuse_angle = 0.35;               // [rad]
  double reuse_max_correction_m = 0.15;    // [m]
  double reuse_max_correction_rad = 0.05;  // [rad]
  // Keyframe density bound: a keyframe due where this many keyframes at least loop_min_travel
  // back already lie within reuse_distance and reuse_angle of the filter's pose is not added,
  // whatever the state of the loop: the scan is first verified against the nearest of them as
  // a reuse (even before the return closed its loop) and, if that fails (an ICP fit above
  // loop_max_rms in noisy data, a drift beyond reuse_max_correction), the filter is anchored to
  // it unverified: its pose relative to the keyframe as the filter has it, no factor, no
  // correction. The next keyframe due outside the mapped region starts its edges there. With
  // keyframes 0.5 m apart a pass puts about two within reuse_distance of a pose: 3 = the first
  // pass and part of the second. Bounds the graph by the mapped area, not by the time driven
  // (the 30-minute soak, RELIABILITY.md; 3 hours of simulation, RBPF_SLAM.md item 7: fewer
  // keyframes and a lower error than 4 on every seed). 0 = no bound.
  int max_keyframes_per_place = 3;

  template <class A>
  void Serialize(A* a) {
    a->Visit("enabled", &enabled);
    a->Visit("keyframe_distance", &keyframe_distance);
    a->Visit("keyframe_angle", &keyframe_angle);
    a->Visit("loop_search_radius", &loop_search_radius);
    a->Visit("loop_max_candidates", &loop_max_candidates);
    a->Visit("loop_closure_spacing", &loop_closure_spacing);
    a->Visit("loop_min_travel", &loop_min_travel);
    a->Visit("loop_submap_half_width", &loop_submap_half_width);
    a->Visit("loop_min_inlier_fraction", &loop_min_inlier_fraction);
    a->Visit("loop_max_rms", &loop_max_rms);
    a->Visit("loop_huber_m", &loop_huber_m);
    a->Visit("loop_max_residual_m", &loop_max_residual_m);
    a->Visit("loop_max_residual_rad", &loop_max_residual_rad);
    a->Visit("edge_sigma", &edge_sigma);
    a->Visit("noisy_factor_rms_per_noise", &noisy_factor_rms_per_noise);
    a->Visit("filter_edges", &filter_edges);
    a->Visit("filter_edge_sigma_scale", &filter_edge_sigma_scale);
    a->Visit("filter_edge_min_sigma_m", &filter_edge_min_sigma_m);
    a->Visit("filter_edge_min_sigma_rad", &filter_edge_min_sigma_rad);
    a->Visit("filter_edge_huber", &filter_edge_huber);
    a->Visit("max_iterations", &max_iterations);
    a->Visit("function_tolerance", &function_tolerance);
    a->Visit("feed_back", &feed_back);
    a->Visit("feedback_min_correction_m", &feedback_min_correction_m);
    a->Visit("loop_search", &loop_search);
    a->Visit("loop_search_after_partial_overlap", &loop_search_after_partial_overlap);
    a->Visit("divergence_check", &divergence_check);
    a->Visit("divergence_min_gain", &divergence_min_gain);
    a->Visit("divergence_odometry_chi2", &divergence_odometry_chi2);
    a->Visit("divergence_odometry_rms_ratio", &divergence_odometry_rms_ratio);
    a->Visit("degenerate_from_odometry", &degenerate_from_odometry);
    a->Visit("recovery_search", &recovery_search);
    a->Visit("recovery_search_from_odometry", &recovery_search_from_odometry);
    a->Visit("recovery_min_gain", &recovery_min_gain);
    a->Visit("reuse_distance", &reuse_distance);
    a->Visit("reuse_angle", &reuse_angle);
    a->Visit("reuse_max_correction_m", &reuse_max_correction_m);
    a->Visit("reuse_max_correction_rad", &reuse_max_correction_rad);
    a->Visit("max_keyframes_per_place", &max_keyframes_per_place);
  }
  Status Validate() const;
};

struct RbpfSlamOptions {
  int particles = 30;              // [-] number of particles
  double neff_threshold = 0.5;     // [-] resample when N_eff < neff_threshold * particles (eq. 4)
  double linear_update = 0.2;      // [m] process a scan only after this much travel ...
  double angular_update = 0.1;     // [rad] ... or this much rotation (GMapping linear/angularUpdate)
  double max_turn_rate = 1.0;      // [rad/s] a scan taken while the odometry turns faster than
                                   //     this (since the previous scan) is not used by the filter:
                                   //     a scan stamped 0.2 s off is 0.3 rad off at 1.5 rad/s
                                   //     (raw CSAIL's fast turns, RBPF_SLAM.md); 0 = off
  double turn_skip_max_gap = 0.3;  // [s] ... only if it came this soon after the previous scan:
                                   //     in a sparse log, skipping a scan doubles the motion the
                                   //     matcher must absorb at the next one (0.5 s made one ACES
                                   //     seed of six 0.16 m worse)
  // A scan the filter does not run on (too little motion since the last update, or a fast turn)
  // is matched alone against the best particle's map, from the best particle's pose plus the
  // odometry since; the match (if it converged within the matcher's bounds) is that scan's
  // pose (RBPF_POSE and the final trajectory). The filter's particles are not changed.
  // Off: the odometry carries the pose between updates.
  bool match_between_updates = true;
  // Each scan's pose relative to its keyframe (RBPF_POSE and the final trajectory) refined by
  // point-to-line ICP of the scan against the keyframe's scan, from the filter's pose (the
  // keyframe factors' ICP and options): the grid matcher places a scan to about its cell
  // (5 cm), ICP to millimetres. Kept if ICP passed its checks with every direction constrained
  // and moved the pose by at most refine_max_correction_m / _rad; else the filter's pose.
  bool refine_scans_with_icp = true;
  double refine_max_correction_m = 0.10;    // [m]
  double refine_max_correction_rad = 0.05;  // [rad]
  // A scan taken in a fast turn (faster than max_turn_rate), or within turn_search_after_s
  // after one, that the refinement above could not place is placed by a correlative search of
  // its keyframe's scan around the filter's pose, then ICP from the search's best pose (kept
  // if ICP passed its checks with every direction constrained). There the odometry's heading
  // can be 20° off what the laser saw (raw CSAIL: its turns start and end ~0.1-0.2 s before
  // the laser's), beyond the grid matcher's and the refinement's reach. The scan's pose only
  // (RBPF_POSE, the final trajectory); the particles are not changed.
  CorrelativeOptions turn_search = TurnSearchDefaults();  // enabled: false = off
  double turn_search_after_s = 2.0;  // [s]
  // A scan that arrives after newer ones were processed (delayed or reordered by the network
  // beyond the node's merge window) and at most this much older than the newest is placed by
  // its stamp (PlaceLateScan): its pose is the scan before it carried by the odometry, refined by
  // ICP against that scan's keyframe. The filter, maps and graph do not see it. 0 = off.
  // By stamps alone a sensor clock that jumps back by less than this looks the same: its scans
  // are placed at the stamps they carry until it has caught up (the filter is never touched).
  double late_scan_max_age_s = 1.0;  // [s]
  int seed = 42;                   // [-] random seed (runs are reproducible)
  GridOptions grid;
  MotionOptions motion;
  MatcherOptions matcher;
  IcpOptions icp;
  GraphOptions graph;

  template <class A>
  void Serialize(A* a) {
    a->Visit("particles", &particles);
    a->Visit("neff_threshold", &neff_threshold);
    a->Visit("linear_update", &linear_update);
    a->Visit("angular_update", &angular_update);
    a->Visit("max_turn_rate", &max_turn_rate);
    a->Visit("turn_skip_max_gap", &turn_skip_max_gap);
    a->Visit("match_between_updates", &match_between_updates);
    a->Visit("refine_scans_with_icp", &refine_scans_with_icp);
    a->Visit("refine_max_correction_m", &refine_max_correction_m);
    a->Visit("refine_max_correction_rad", &refine_max_correction_rad);
    a->Visit("turn_search", &turn_search);
    a->Visit("turn_search_after_s", &turn_search_after_s);
    a->Visit("late_scan_max_age_s", &late_scan_max_age_s);
    a->Visit("seed", &seed);
    a->Visit("grid", &grid);
    a->Visit("motion", &motion);
    a->Visit("matcher", &matcher);
    a->Visit("icp", &icp);
    a->Visit("graph", &graph);
  }
  Status Validate() const;
};

}  // namespace fl::rbpf
