// Motion from stereo correspondences: the closed-form 3D-3D solution (Arun et al. 1987 /
// Umeyama 1991, MSIF eqs. 16-18), RANSAC over it, and the nonlinear refinement of the stereo
// reprojection error with its covariance.
//
// Frames: camera optical frame (x right, y down, z forward) of the LEFT camera; the right
// camera is at +baseline along x. T_a_b is the pose of frame b in frame a (p_a = T_a_b p_b).
// In frame-to-frame use, a = camera at time t ("previous"), b = camera at time t+1 ("current").
//
// Perturbation convention for covariances: T = T_hat * Exp(delta), delta = [rho; phi] with rho
// the translation part and phi the rotation vector (right perturbation, translation first), the
// order of fusionloc.relative_pose_factor_t's information matrix [dx dy dz droll dpitch dyaw].
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <random>
#include <vector>

namespace fl::vo {

// Pinhole model of a rectified stereo pair (both cameras share fx, fy, cx, cy).
struct StereoCamera {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  double baseline = 0;  // [m] right camera is at +baseline along the left camera's x axis

  // Projects a point in the left camera frame to (u_left, v, u_right) [px]; false if z <= 0.
  bool Project(const Eigen::Vector3d& p_camera, Eigen::Vector3d* uvu) const {
    if (p_camera.z() <= 1e-9) return false;
    const double inv_z = 1.0 / p_camera.z();
    (*uvu)(0) = fx * p_camera.x() * inv_z + cx;
    (*uvu)(1) = fy * p_camera.y() * inv_z + cy;
    (*uvu)(2) = fx * (p_camera.x() - baseline) * inv_z + cx;
    return true;
  }
  // Triangulates from the left pixel (u, v) and the disparity d = u_left - u_right > 0 [px].
  Eigen::Vector3d Triangulate(double u, double v, double disparity) const {
    const double z = fx * baseline / disparity;
    return {(u - cx) * z / fx, (v - cy) * z / fy, z};
  }
};

// One correspondence of the quadrilateral matching: the same scene point seen by the stereo
// pair at time a (previous) and at time b (current). Observations are (u_left, v_left, u_right).
struct StereoCorrespondence {
  Eigen::Vector3d obs_a;  // [px] at time a
  Eigen::Vector3d obs_b;  // [px] at time b
  Eigen::Vector3d p_a;    // [m] triangulated at time a, camera a frame
  Eigen::Vector3d p_b;    // [m] triangulated at time b, camera b frame
};

// Closed-form rigid transform T with p_a ~= T * p_b minimizing sum |p_a - T p_b|^2 (Arun's SVD
// with Umeyama's reflection fix). `idx` selects the correspondences (all if empty); `weights`
// (optional, one per point of p_a) weights each squared residual. Returns false if fewer than 3
// points or a degenerate (collinear) configuration.
bool SolveRigidSvd(const std::vector<Eigen::Vector3d>& p_a, const std::vector<Eigen::Vector3d>& p_b,
                   const std::vector<int>& idx, Eigen::Isometry3d* T_a_b,
                   const std::vector<double>* weights = nullptr);

struct RansacOptions {
  int max_iterations = 300;          // upper bound on random minimal samples
  double confidence = 0.995;         // [-] stop when an all-inlier sample is this likely
  double inlier_threshold_px = 2.0;  // [px] max reprojection error (left u, v, right u) at b
  int min_inliers = 12;              // fewer inliers: no motion
  int seed = 42;                     // fixed seed: deterministic results
  template <class A>
  void Serialize(A* a) {
    a->Visit("max_iterations", &max_iterations);
    a->Visit("confidence", &confidence);
    a->Visit("inlier_threshold_px", &inlier_threshold_px);
    a->Visit("min_inliers", &min_inliers);
    a->Visit("seed", &seed);
  }
};

struct RansacResult {
  bool ok = false;
  Eigen::Isometry3d T_a_b = Eigen::Isometry3d::Identity();
  std::vector<int> inliers;  // indices into the correspondences
  int iterations = 0;
};

// Reprojection error (max over left u, v and right u) of p_a seen from camera b, [px].
double ForwardReprojectionError(const StereoCamera& cam, const Eigen::Isometry3d& T_a_b,
                                const StereoCorrespondence& c);

// RANSAC over minimal 3-point SVD solutions drawn from the nearer half of the points; inliers by
// reprojection of p_a into the stereo pair at b. The best hypothesis is re-estimated by SVD on
// all its inliers weighted by depth precision (disparity_a^2 disparity_b^2), kept if it has at
// least as many inliers.
RansacResult RansacMotion(const StereoCamera& cam, const std::vector<StereoCorrespondence>& corr,
                          const RansacOptions& options);

struct RefineOptions {
  int max_iterations = 5;     // Levenberg-Marquardt iterations (converges in 2-4)
  double huber_px = 1.0;      // [px] Huber loss width (down-weights remaining outliers)
  double min_sigma_px = 0.2;  // [px] lower bound on the measured reprojection noise
  // Multiplies the covariance. Chained over the ~10 frame-to-frame motions of a keyframe at
  // 10 Hz, the frame-to-frame covariances are about 5x overconfident (the frames share their
  // features, the chain treats them as independent): the keyframe factors' chi^2 median against
  // the simulator's truth is 10 with 1 (2.4 expected), 1.06 with 10 (docs/STEREO_VO.md). At the
  // paper's 2 Hz (config/stereo_vo_2hz.yaml): 1.
  double covariance_scale = 10.0;
  // true: two-view bundle adjustment (pose and points, unbiased); false: points fixed at
  // their triangulation, reprojected both ways (faster, but the motion comes out too long).
  bool optimize_points = true;
  // Two-view bundle adjustment solver: false = the analytic Schur-complement
  // Levenberg-Marquardt below (fast; can estimate the disparity offset); true = Ceres with the
  // autodiff functors of reprojection_cost.hpp (reference; no disparity offset).
  bool use_ceres = false;
  template <class A>
  void Serialize(A* a) {
    a->Visit("max_iterations", &max_iterations);
    a->Visit("huber_px", &huber_px);
    a->Visit("min_sigma_px", &min_sigma_px);
    a->Visit("covariance_scale", &covariance_scale);
    a->Visit("optimize_points", &optimize_points);
    a->Visit("use_ceres", &use_ceres);
  }
};

// Self-calibration of the stereo rectification's residual yaw. If the rectified right camera
// is yawed by a small angle psi relative to the left (calibration error or mechanical drift),
// every right image point moves horizontally by f psi (1 + x^2), x = (u_right - cx) / fx, so
// the measured disparity is d_true + delta g(u_right) with delta = -f psi the offset at the
// image centre [px] and g = OffsetBasis. Far points are hit hardest (relative depth error
// -delta / d): with delta < 0 the estimated motion comes out too long (docs/STEREO_VO.md: about
// -0.3 px on the KITTI drive, +1.5 % path length). A constant offset (right principal point
// error) fits that drive clearly worse than the yaw model.
// The caller passes observations whose u_right is already corrected by its current estimate
// (CorrectRightX) and this prior; the refinement then also estimates the remaining increment
// c of delta, shared by all points:
//   u_right predicted = fx (x - b) / z + cx, residual = predicted - (u_right_obs + c g).
// The prior adds (sigma_px^2 / variance_px2) c^2 to the cost (whose residuals are in pixels).
inline double OffsetBasis(const StereoCamera& cam, double u_right) {
  const double x = (u_right - cam.cx) / cam.fx;
  return 1.0 + x * x;
}
// Right image x corrected by the offset estimate delta: the disparity u_left - corrected is the
// true disparity.
inline double CorrectRightX(const StereoCamera& cam, double u_right, double delta_px) {
  return u_right + delta_px * OffsetBasis(cam, u_right);
}
struct OffsetPrior {
  double variance_px2 = 0.25;  // [px^2] prior variance of the increment c (mean 0)
  double sigma_px = 0.5;       // [px] pixel noise that scales the prior against the residuals
};

struct RefineResult {
  bool ok = false;
  Eigen::Isometry3d T_a_b = Eigen::Isometry3d::Identity();
  // Covariance of delta (T_a_b = T_hat Exp(delta), delta = [rho; phi]) from the Gauss-Newton
  // Hessian: sigma^2 (J^T J)^-1, sigma^2 estimated from the residuals.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  double rms_px = 0;        // [px] residual RMS at the solution
  double sigma_px = 0;      // [px] pixel noise estimate behind the covariance (analytic solver)
  double initial_cost = 0;  // Ceres cost (1/2 sum rho(r^2)) before
  double final_cost = 0;    // and after
  int iterations = 0;
  // Disparity offset increment c (only with an OffsetPrior): estimate [px], its posterior
  // variance [px^2] (sigma^2 from the residuals, pose and points marginalised) and the
  // information the data alone gave about it [1/px^2] (0: unobservable, e.g. no translation).
  bool offset_estimated = false;
  double offset_px = 0;
  double offset_variance_px2 = 0;
  double offset_data_information = 0;
};

// Measured 3D positions of the correspondences' points (laser-aided mode, laser_depth.hpp): the
// improved objective of LV-SLAM. A point with a measurement at time a adds to the two-view
// bundle adjustment the 3D point error
//   r_a = s W_a (p_a - m_a)                       [px-equivalent, 3 components]
// and one with a measurement at time b
//   r_b = s W_b (p_b - m_b),  p_b = T_a_b^-1 p_a  (frame b)
// where m is the measured point [m], W its square-root information [1/m] (W^T W = Sigma^-1,
// Sigma the point's own covariance, see PointSqrtInformation) and s = pixel_sigma_px the pixel
// noise of the reprojection residuals, so that both kinds of residual are whitened alike and
// share the robust (Huber) loss. Points without a measurement keep only the stereo
// reprojection error.
struct PointMeasurement {
  bool has_a = false, has_b = false;
  Eigen::Vector3d m_a = Eigen::Vector3d::Zero();  // [m] frame a
  Eigen::Vector3d m_b = Eigen::Vector3d::Zero();  // [m] frame b
  Eigen::Matrix3d W_a = Eigen::Matrix3d::Zero();  // [1/m] square-root information at a
  Eigen::Matrix3d W_b = Eigen::Matrix3d::Zero();  // [1/m] at b
};
struct PointMeasurements {
  std::vector<PointMeasurement> per_correspondence;  // one per correspondence (or empty)
  double pixel_sigma_px = 0.5;                       // [px] s above
};
// Square-root information of a point m = z ray (ray = (x_n, y_n, 1), the pixel's normalised
// ray) measured with depth noise sigma_depth_m along the ray and lateral noise
// sigma_lateral_m across it: Sigma = sigma_lat^2 I + (sigma_depth^2 - sigma_lat^2) e e^T
// (e = ray / |ray|), W = Sigma^-1/2.
Eigen::Matrix3d PointSqrtInformation(const Eigen::Vector3d& ray, double sigma_depth_m,
                                     double sigma_lateral_m);

// Refines T_a_b on the inliers by minimizing the stereo reprojection error (u_left, v, u_right).
// optimize_points: two-view bundle adjustment over the pose and every point (the pose
// covariance is the Schur complement of the points), by the analytic solver or, with
// use_ceres, by Ceres; else (Ceres) the triangulated points are fixed and reprojected both ways
// (p_a into b, p_b into a). `points_a` (optional) receives the
// refined points in frame a.
// `offset` (optional, analytic joint solver only): also estimate the disparity offset
// increment (see OffsetPrior); the pose covariance is conditional on it (calibration-like).
// `measured` (optional, analytic joint solver only; else the refinement is refused: ok false):
// add the 3D point errors of PointMeasurement; a measured point starts at m_a.
RefineResult RefineMotion(const StereoCamera& cam, const std::vector<StereoCorrespondence>& corr,
                          const std::vector<int>& inliers, const Eigen::Isometry3d& T_a_b_initial,
                          const RefineOptions& options,
                          std::vector<Eigen::Vector3d>* points_a = nullptr,
                          const OffsetPrior* offset = nullptr,
                          const PointMeasurements* measured = nullptr);

// Adjoint of T for the [rho; phi] ordering: Exp(Ad(T) d) = T Exp(d) T^-1.
Eigen::Matrix<double, 6, 6> Adjoint(const Eigen::Isometry3d& T);

// First-order covariance of T_ac = T_ab * T_bc (both with right perturbations, independent).
Eigen::Matrix<double, 6, 6> ComposeCovariance(const Eigen::Matrix<double, 6, 6>& cov_ab,
                                              const Eigen::Isometry3d& T_bc,
                                              const Eigen::Matrix<double, 6, 6>& cov_bc);

// Covariance of T_x = S * T * S^-1 (a change of frame by the fixed transform S, e.g. camera to
// base): Ad(S) cov Ad(S)^T.
Eigen::Matrix<double, 6, 6> ChangeFrameCovariance(const Eigen::Matrix<double, 6, 6>& cov,
                                                  const Eigen::Isometry3d& S);

}  // namespace fl::vo
