// Keyframe local bundle adjustment (LV-SLAM §3.3; issue 26): the last few keyframes and the
// tracks they share, optimised together with Ceres (Schur complement of the points), so that a
// point seen from several keyframes constrains them all at once instead of through a chain of
// frame-to-frame motions.
//
// Window: keyframes k = 0..n-1, oldest first. The oldest is fixed (the gauge; stereo fixes the
// scale) and is the frame o of the problem. Unknowns: a right perturbation delta_k = [rho; phi]
// of every other keyframe's pose, T_o_k = T0_o_k [R(phi) | rho] (T0: the pose before the
// adjustment), and every shared track's point p_o in frame o. Residuals: the stereo
// reprojection (u_left, v, u_right) of p_o into each keyframe that observed the track,
//     k = 0:  project(p_o) - z_0k                                (StereoPointCostA)
//     k > 0:  project(R(-phi)(R0^T (p_o - t0) - rho)) - z_k      (StereoPointCostB, with rho and
//                                                                 phi as two parameter blocks)
// in pixels, under a Huber loss; a track counts when at least min_track_keyframes keyframes
// observed it. Laser-aided (laser_points and observations with has_point): the 3D point error
// s W (p_k - m) of LV-SLAM's improved objective (motion.hpp, PointMeasurement; s = the pixel
// noise) joins the reprojection of that observation, so laser depth holds the window's scale.
// With motion_prior, each keyframe's chained frame-to-frame motion from the one
// before it (what the plain VO would have reported, through every frame between them) joins as
// an SE(3) between factor with its covariance (fl::Se3BetweenCost): the window keeps what the
// intermediate frames measured and adds what the shared tracks say across keyframes. After a
// first solve the observations whose error exceeds outlier_threshold_px are removed and the
// window is solved again.
//
// Solver: by default an analytic Levenberg-Marquardt as the two-view refinement's (motion.cpp):
// each iteration linearises at the current poses and points, eliminates every point's 3x3
// block, solves the 6(n-1) pose system and back-substitutes the points, keeping the step if
// the robust cost fell. With q = R_k^T (p_o - t_k), the point in keyframe k:
//   reprojection  r = pi(q) - z:      d r/d p_o = Jpi(q) R_k^T,  d r/d delta_k = Jpi(q) [-I, [q]x]
//   laser point   r = s W (q - m):    d r/d p_o = s W R_k^T,     d r/d delta_k = s W [-I, [q]x]
// (keyframe 0: q = p_o, no pose block); the motion priors' Jacobians by autodiff of their
// functor. use_ceres solves the same residual blocks (BuildProblem) with Ceres instead.
//
// Covariance of the newest relative pose T_ij (i = n-2, j = n-1, camera frames): from the
// window's Hessian with the points marginalised (Schur complement of J^T J), scaled by
// the pixel noise sigma^2: T_ij = T_o_i^-1 T_o_j, delta_ij = delta_j - Ad(T_ij^-1) delta_i.
//
//   fl::vo::LocalBaResult r = fl::vo::LocalBundleAdjustment(camera, window, options, sigma_px);
//   if (r.ok) for (k) window[k].T_world_camera = r.T_world_camera[k];
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/stereo_vo/motion.hpp"

namespace ceres {
class Problem;
}

namespace fl::vo {

struct LocalBaOptions {
  // Off: keyframe factors are the chained frame-to-frame motions (the plain VO, unchanged).
  bool enabled = false;
  int window_keyframes = 6;           // [-] keyframes in the window (>= 2; the oldest is fixed)
  int min_track_keyframes = 2;        // [-] a track enters when this many keyframes observed it
  int max_iterations = 5;             // Levenberg-Marquardt iterations per solve (4-5 suffice)
  // [-] a solve stops after an accepted step that lowers the robust cost by less than this
  // fraction (Ceres' function_tolerance). On KITTI the 4th and 5th steps lower it by ~2e-4 and
  // ~8e-5 and move the poses by < 0.1 mm: 1e-3 ends most solves after 4 steps.
  double function_tolerance = 1e-3;
  double huber_px = 1.0;              // [px] Huber loss width
  double outlier_threshold_px = 2.0;  // [px] larger error (max of u, v, u_right) after solve 1: out
  int min_points = 20;  // fewer shared tracks: the window is not adjusted (chained poses kept)
  // The chained motions between consecutive keyframes as priors (see above); their covariance,
  // already times refine.covariance_scale (10), multiplied by motion_prior_covariance_scale:
  // 10x the unscaled chain in all, because the frame-to-frame covariance is about 5x
  // overconfident (chi^2 in bench sim, docs/STEREO_VO.md) and the chain and the window share the
  // keyframes' observations (config/stereo_vo_2hz.yaml: 1 and 10, the same product). Without
  // the prior, a window whose tracks are short (the simulator: ~2.2 keyframes per track) knows
  // less than the chain it replaces.
  bool motion_prior = true;
  double motion_prior_covariance_scale = 1.0;
  // Laser-aided mode: the observations' laser depth points as 3D point errors (see above). Off
  // by default: on the KITTI 04 snippet (the only sequence with laser data) they make the
  // laser-aided run worse, 0.615 -> 0.659 % drift (its laser depths put the path 0.3 % long
  // where stereo puts it 0.4 % short; docs/STEREO_VO.md); the frame-to-frame laser terms stay.
  bool laser_points = false;
  // [-] false: the analytic Levenberg-Marquardt on the reduced (Schur complement) system below
  // (fast); true: the same problem (BuildProblem) solved by Ceres, the reference.
  bool use_ceres = false;
  // [-] use_ceres only: sparse Schur (true) or dense Schur (false) linear solver; dense is
  // faster for the small windows (at most ~10 keyframes) this is meant for.
  bool sparse_schur = false;
  template <class A>
  void Serialize(A* a) {
    a->Visit("enabled", &enabled);
    a->Visit("window_keyframes", &window_keyframes);
    a->Visit("min_track_keyframes", &min_track_keyframes);
    a->Visit("max_iterations", &max_iterations);
    a->Visit("function_tolerance", &function_tolerance);
    a->Visit("huber_px", &huber_px);
    a->Visit("outlier_threshold_px", &outlier_threshold_px);
    a->Visit("min_points", &min_points);
    a->Visit("motion_prior", &motion_prior);
    a->Visit("motion_prior_covariance_scale", &motion_prior_covariance_scale);
    a->Visit("laser_points", &laser_points);
    a->Visit("use_ceres", &use_ceres);
    a->Visit("sparse_schur", &sparse_schur);
  }
  fl::Status Validate() const;
};

// One observation of a track by a keyframe: (u_left, v, u_right) [px], u_right already
// corrected by the disparity offset estimate (CorrectRightX), so u_left - u_right > 0 is the
// true disparity.
// Laser-aided mode: a validated laser depth makes the observation also a 3D point measurement
// (PointMeasurement in motion.hpp) in the keyframe's camera frame.
struct BaObservation {
  int64_t track_id = -1;
  Eigen::Vector3d uvu = Eigen::Vector3d::Zero();
  bool has_point = false;
  Eigen::Vector3d m_camera = Eigen::Vector3d::Zero();  // [m] measured point, keyframe camera
  Eigen::Matrix3d W_camera = Eigen::Matrix3d::Zero();  // [1/m] its square-root information
};

struct BaKeyframe {
  int64_t id = -1;
  Utime utime = 0;
  Eigen::Isometry3d T_world_camera = Eigen::Isometry3d::Identity();  // left camera in world
  std::vector<BaObservation> observations;  // one per tracked stereo feature
  // The chained frame-to-frame motion from the previous keyframe of the window to this one
  // (camera frames) and its covariance (right perturbation [rho; phi]); has_motion false for
  // the first keyframe of a segment.
  bool has_motion = false;
  Eigen::Isometry3d T_prev_camera = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> motion_covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

// A track shared by the window: its point in frame o and who observed it.
struct BaTrack {
  int64_t track_id = -1;
  Eigen::Vector3d p_o = Eigen::Vector3d::Zero();  // [m] initial point, oldest keyframe's frame
  std::vector<std::pair<int, BaObservation>> observations;  // (keyframe index, observation)
};

// Stage 1: the tracks observed by at least min_track_keyframes keyframes, each triangulated from
// its observation with the largest disparity and moved into frame o by the window's poses.
// Observations with a disparity <= 0 are skipped.
std::vector<BaTrack> CollectTracks(const StereoCamera& camera,
                                   const std::vector<BaKeyframe>& window, int min_track_keyframes);

// Unknowns of the problem (owned here; Ceres holds pointers into them).
struct BaState {
  std::vector<Eigen::Isometry3d> T0_o_k;  // linearisation points, T0_o_0 = identity
  // Per keyframe [rho; phi] (two parameter blocks: delta.data(), delta.data() + 3); delta[0]
  // stays zero (fixed).
  std::vector<std::array<double, 6>> delta;
  std::vector<std::array<double, 3>> point;  // per track, frame o
};

// Stage 2: the initial state (T0_o_k from the window's poses, the tracks' points) and the
// problem's residual blocks: the reprojections (keyframe 0's are StereoPointCostA on the point
// alone) and, with motion_prior, the keyframe motions (keyframe 0's delta then enters as a
// constant block); observations where `keep` is false are left out (keep[t][m]: track t's m-th
// observation; empty: keep all).
BaState InitialState(const std::vector<BaKeyframe>& window, const std::vector<BaTrack>& tracks);
// sigma_px: the pixel noise s of the laser point errors.
void BuildProblem(const StereoCamera& camera, const std::vector<BaKeyframe>& window,
                  const std::vector<BaTrack>& tracks, const LocalBaOptions& options,
                  double sigma_px, const std::vector<std::vector<bool>>& keep, BaState* state,
                  ceres::Problem* problem);

struct LocalBaResult {
  bool ok = false;
  std::string message;                            // why not adjusted, when ok is false
  std::vector<Eigen::Isometry3d> T_world_camera;  // refined, one per window keyframe
  // Covariance of the newest relative pose T_{n-2}_{n-1} (camera frames, right perturbation,
  // [rho; phi]) with sigma_px as the pixel noise; covariance_ok false if Ceres could not
  // compute it (rank deficient), then zero.
  bool covariance_ok = false;
  Eigen::Matrix<double, 6, 6> covariance_last = Eigen::Matrix<double, 6, 6>::Zero();
  int points = 0, observations = 0, outliers = 0, iterations = 0;
  int laser_points = 0;                         // observations with a laser depth point error
  double initial_rms_px = 0, final_rms_px = 0;  // reprojection RMS before / after [px]
};

// Adjusts the window (at least 2 keyframes). sigma_px: the pixel noise of the covariance.
LocalBaResult LocalBundleAdjustment(const StereoCamera& camera,
                                    const std::vector<BaKeyframe>& window,
                                    const LocalBaOptions& options, double sigma_px);

}  // namespace fl::vo
