// Trajectory error metrics (definitions and formulas in docs/EVALUATION.md):
//  - ATE: absolute trajectory error after a least-squares alignment (none, SE(2), SE(3), Sim(3);
//    Horn/Umeyama closed form);
//  - RPE: relative pose error over a step in frames, metres or seconds;
//  - KITTI segment drift, exactly the devkit's definition (evaluate_odometry.cpp);
//  - relation error of Kuemmerle et al. 2009 from a relations file.
// All functions associate est with ref by time first (see Associate) and throw EvalError on
// bad input.
#pragma once

#include <string>
#include <vector>

#include "fusionloc/eval/trajectory.hpp"

namespace fl::eval {

enum class Alignment { kNone, kSE2, kSE3, kSim3 };
// "none", "se2", "se3", "sim3" (case-insensitive); throws EvalError otherwise.
Alignment ParseAlignment(const std::string& text);
std::string AlignmentName(Alignment alignment);

struct ErrorStats {
  double rmse = 0, mean = 0, median = 0, std = 0, max = 0;  // std: population (1/n)
  size_t count = 0;
};
// Statistics of non-negative error values (empty input gives all zeros).
ErrorStats ComputeErrorStats(std::vector<double> values);

struct AteResult {
  ErrorStats trans_m, rot_deg;
  // The alignment applied to est: p_ref ≈ scale * R * p_est + t, with (R, t) = T_ref_est.
  Eigen::Isometry3d T_ref_est = Eigen::Isometry3d::Identity();
  double scale = 1;
  // Per associated pair, in time order:
  std::vector<fl::Utime> utimes;                  // [us] est time stamps
  std::vector<double> trans_errors_m;             // |p_ref - p_aligned_est|
  std::vector<double> rot_errors_deg;             // angle of R_ref^-1 * R_aligned_est
  std::vector<double> err_x_m, err_y_m, err_z_m;  // signed p_aligned_est - p_ref, world x y z
  std::vector<double> err_yaw_deg;                // signed wrapped yaw(aligned est) - yaw(ref)
  Trajectory est_aligned;                         // aligned est poses (the associated ones)
  Trajectory ref_matched;                         // their ref poses
  std::string warning;                            // non-empty if the alignment is ill-conditioned
};
// Needs at least 1 pair (kNone), 2 (kSE2) or 3 (kSE3, kSim3).
AteResult ComputeAte(const Trajectory& est, const Trajectory& ref, Alignment alignment,
                     fl::Utime max_dt_us);

// Repeatability of a stochastic estimator without a reference: the ATE (translation RMSE after
// `alignment`) of each run against each other run, over all pairs of runs of the same input
// (e.g. particle-filter seeds). If the runs scatter independently with RMS σ about a common
// trajectory, the mean is about √2 σ; an error against a reference well above it is shared by
// the runs (the estimator's bias, or the reference's own error). Needs at least 2 runs.
struct RunSpreadResult {
  double mean_m = 0, min_m = 0, max_m = 0;  // over the pairs
  size_t pairs = 0;
};
RunSpreadResult ComputeRunSpread(const std::vector<Trajectory>& runs, Alignment alignment,
                                 fl::Utime max_dt_us);
// The runs' average trajectory: every run aligned onto the first (as ComputeAte aligns est to
// ref), then, at each time stamp of the first run that every run has (within max_dt_us), the
// mean position and the chordal mean of the rotations. Its ATE against a reference is the
// part of the error that the runs share; their scatter averages out (as 1/√n). Throws
// EvalError if `runs` is empty or a run cannot be aligned.
Trajectory AverageRuns(const std::vector<Trajectory>& runs, Alignment alignment,
                       fl::Utime max_dt_us);

// The least-squares alignment alone, of point sets (columns), dst ≈ s R src + t.
// SE2 rotates about z and translates in x, y only. Returns T (R, t) and sets *scale.
Eigen::Isometry3d AlignPoints(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst,
                              Alignment alignment, double* scale);

enum class DeltaUnit { kFrames, kMeters, kSeconds };
// "frames", "m", "s" (also "meters", "seconds"); throws EvalError otherwise.
DeltaUnit ParseDeltaUnit(const std::string& text);

struct RpeResult {
  ErrorStats trans_m, rot_deg;
  std::vector<fl::Utime> utimes;  // [us] est time of the first pose of each pair
  std::vector<double> trans_errors_m, rot_errors_deg;
};
// For each associated pose i, the pose j = the first one at least `delta` later (frames of the
// associated sequence, metres of reference path, or seconds); error E = (Ref_i^-1 Ref_j)^-1 *
// (Est_i^-1 Est_j), trans = |t(E)|, rot = angle(R(E)). No alignment needed.
RpeResult ComputeRpe(const Trajectory& est, const Trajectory& ref, double delta, DeltaUnit unit,
                     fl::Utime max_dt_us);

struct DriftResult {
  double trans_pct = 0;         // mean over all segments of |t(err)| / length * 100
  double rot_deg_per_100m = 0;  // mean over all segments of angle(err) / length, deg/100 m
  size_t segments = 0;
  std::vector<double> lengths_m;  // lengths that had at least one segment
  std::vector<double> trans_pct_per_length, rot_deg_per_100m_per_length;
  std::vector<size_t> segments_per_length;
};
// KITTI devkit segment error on the associated pairs: first frames 0, step, 2*step, ...; for
// each length L the last frame is the first whose reference path distance exceeds the first
// frame's by more than L; err = (Est_f^-1 Est_l)^-1 (Ref_f^-1 Ref_l). Throws if no segment
// fits (the message gives the path length).
DriftResult ComputeKittiDrift(const Trajectory& est, const Trajectory& ref,
                              const std::vector<double>& lengths_m, fl::Utime max_dt_us,
                              int step_frames = 10);

// The devkit's lengths 100, 200, ..., 800 m that are shorter than the path if the path is at
// least 200 m long; otherwise 8 lengths k * s (k = 1..8), s the largest of 1, 2, 5 x 10^n
// with 8 s <= 0.8 * path (e.g. 107 m -> 10, 20, ..., 80 m). Throws if the path is < 0.1 m.
std::vector<double> DefaultKittiLengths(double path_length_m);

// One line of a relations file: the reference motion from the pose at t1 to the pose at t2,
// expressed in the frame of the pose at t1.
struct Relation {
  fl::Utime utime1 = 0, utime2 = 0;
  Eigen::Isometry3d T_1_2 = Eigen::Isometry3d::Identity();
};
// Text lines "t1 t2 x y z roll pitch yaw" (seconds, metres, radians; R = Rz Ry Rx), '#'
// comments. Throws EvalError naming file:line on malformed lines.
std::vector<Relation> ReadRelations(const std::string& path);
// Relations between reference poses i and i + step_frames, for all i (e.g. the corrected poses
// of a CARMEN log, consecutive scans: step 1).
std::vector<Relation> RelationsFromTrajectory(const Trajectory& ref, size_t step_frames = 1);
// Writes relations in the same format (e.g. to make a relations file from a reference).
void WriteRelations(const std::vector<Relation>& relations, const std::string& path);

struct RelationResult {
  ErrorStats trans_m, rot_deg;  // |t(E)| and angle(R(E)), E = T_rel_ref^-1 * T_rel_est
  double trans_sq_mean_m2 = 0;  // mean of squared translation errors (Kuemmerle's epsilon_t^2)
  double rot_sq_mean_deg2 = 0;
  size_t used = 0;     // relations whose two times were found in est
  size_t skipped = 0;  // relations with a time not within max_dt of an est pose
};
// Kuemmerle et al. 2009. Each relation's times are looked up in est (nearest within
// max_dt_us). Throws if no relation can be evaluated.
RelationResult ComputeRelationError(const Trajectory& est, const std::vector<Relation>& relations,
                                    fl::Utime max_dt_us);
RelationResult ComputeRelationError(const Trajectory& est, const std::string& relations_file,
                                    fl::Utime max_dt_us);

}  // namespace fl::eval
