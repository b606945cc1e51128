// Stereo visual odometry (MSIF §2 and §3.1.2): ORB features on a grid, quadrilateral matching,
// 3D-3D RANSAC with the SVD solution, Ceres refinement of the stereo reprojection error, and
// keyframe factors with the covariance of the refinement. Pure library: no LCM.
//
//   fl::vo::StereoVo vo(options, calibration);
//   fl::vo::StereoVoResult r = vo.AddStereoFrame(utime, left_gray, right_gray);
//   if (r.factor) publish(*r.factor);
//
// Frames: world = base frame at the first tracked frame; base x forward, y left, z up;
// camera optical x right, y down, z forward (left camera). T_a_b = pose of b in a.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/odometry_buffer.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/stereo_vo/laser_depth.hpp"
#include "fusionloc/stereo_vo/local_ba.hpp"
#include "fusionloc/stereo_vo/matching.hpp"
#include "fusionloc/stereo_vo/motion.hpp"

namespace fl::vo {
namespace stages {
struct StereoFrame;  // stereo_vo_stages.hpp
struct Refinement;
}  // namespace stages

// Largest image side a calibration may have (Validate; a bound on what the network sends).
constexpr int kMaxImageSidePx = 16384;

// Calibration of a rectified stereo rig (the library's own plain struct).
struct StereoCalibration {
  double fx = 0, fy = 0;      // [px] focal lengths (both cameras, rectified)
  double cx = 0, cy = 0;      // [px] principal point
  double baseline = 0;        // [m] right camera at +baseline along the left camera's x
  int width = 0, height = 0;  // [px] image size
  bool rectified = true;      // the pair must be rectified and row-aligned
  Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();  // left camera in base

  // Error naming the bad field and the fix, or OK.
  fl::Status Validate() const;
  StereoCamera camera() const { return {fx, fy, cx, cy, baseline}; }
};

struct StereoVoOptions {
  FeatureOptions features;
  MatchOptions matching;
  RansacOptions ransac;
  RefineOptions refine;
  bool use_refinement = true;  // Ceres refinement after RANSAC (off: SVD only)
  // Sub-pixel disparities: each stereo match's right x by Lucas-Kanade alignment of the left
  // patch (left corners stay as detected; see docs/STEREO_VO.md for why not temporally).
  bool subpixel_refinement = true;
  int subpixel_window_px = 11;         // [px] LK patch size (odd)
  double subpixel_max_shift_px = 1.5;  // [px] larger corrections drop the match
  int refine_rounds = 2;               // refine, re-select inliers by reprojection, repeat
  // Online self-calibration of the disparity offset delta (measured disparity = true + delta;
  // see OffsetPrior in motion.hpp and docs/STEREO_VO.md): every refinement also estimates it,
  // a scalar Kalman filter (random walk) accumulates it over frames, and all disparities are
  // corrected by the current estimate. Unobservable without translation (the filter then keeps
  // its value). Needs the analytic two-view bundle adjustment (refine.optimize_points true,
  // refine.use_ceres false).
  bool estimate_disparity_offset = true;
  double disparity_offset_initial_px = 0.0;     // [px] start value (e.g. a previous run's)
  double disparity_offset_initial_sd_px = 0.3;  // [px] its uncertainty
  double disparity_offset_drift_px = 0.02;      // [px/sqrt(s)] random walk of the true offset
  double disparity_offset_max_px = 2.0;  // [px] larger |estimate|: reset, report (bad calibration)
  // Keyframes: a new one when the motion since the last keyframe or the loss of its features
  // exceeds one of these.
  double keyframe_translation_m = 1.0;   // [m]
  double keyframe_rotation_deg = 10.0;   // [deg]
  // [-] fraction still tracked of the keyframe's tracks that the first frame after it carried
  // over (the frame-to-frame inliers, not all stereo matches: a fraction of those never closes a
  // quadrilateral, so counting them made almost every frame a keyframe)
  double keyframe_min_overlap = 0.5;
  double keyframe_max_interval_s = 2.0;  // [s] at least one keyframe this often
  // Frame checks.
  double min_mean_intensity = 8.0;    // [gray] darker: "black frame", not tracked
  double max_mean_intensity = 247.0;  // [gray] brighter: "saturated frame", not tracked
  int min_features = 40;              // fewer corners in the left image: "low texture"
  int min_quads = 15;                 // fewer closed quadrilaterals: not tracked
  double max_speed_mps = 40.0;        // [m/s] faster estimated motion is rejected as wrong
  double max_gap_s = 1.0;             // [s] longer since the last good frame: new segment
  // Wheel odometry (AddOdometry; ODOMETRY in fl-stereo-vo) as the motion prior: it predicts the
  // motion between two frames for temporal matching (in place of the constant-velocity guess,
  // which fails when a turn starts or frames were lost) and carries the pose across a gap that
  // starts a new segment. Without odometry samples around a frame (KITTI, a robot without
  // ODOMETRY): as when off. On by default, for cameras at 10 Hz or more: in the simulator at
  // 10 Hz it brings the VO alone to the wheel odometry's accuracy and improves the fused ATE.
  // At the MSIF paper's 2 Hz (config/stereo_vo_2hz.yaml: off) the frames it tracks through the
  // 23-degree steps of a turn make the fused ATE worse (0.056 -> 0.089 m; docs/STEREO_VO.md).
  bool use_odometry_prior = true;
  // Laser-aided mode (LV-SLAM; laser_depth.hpp, docs/STEREO_VO.md "Laser-aided mode"): features
  // with a validated laser depth add a 3D point error to the motion refinement. Off: the plain
  // stereo VO, unchanged.
  LaserDepthOptions laser_depth;
  double laser_max_time_offset_s = 0.05;  // [s] a scan farther in time from the images: unused
  // Keyframe local bundle adjustment (local_ba.hpp): at every new keyframe the last
  // local_ba.window_keyframes keyframes and their shared tracks are adjusted together; the
  // adjusted newest keyframe pose continues the chain and the keyframe factor is the adjusted
  // relative pose with the window's covariance. Off: the chained frame-to-frame motions.
  LocalBaOptions local_ba;
  template <class A>
  void Serialize(A* a) {
    a->Visit("features", &features);
    a->Visit("matching", &matching);
    a->Visit("ransac", &ransac);
    a->Visit("refine", &refine);
    a->Visit("use_refinement", &use_refinement);
    a->Visit("subpixel_refinement", &subpixel_refinement);
    a->Visit("subpixel_window_px", &subpixel_window_px);
    a->Visit("subpixel_max_shift_px", &subpixel_max_shift_px);
    a->Visit("refine_rounds", &refine_rounds);
    a->Visit("estimate_disparity_offset", &estimate_disparity_offset);
    a->Visit("disparity_offset_initial_px", &disparity_offset_initial_px);
    a->Visit("disparity_offset_initial_sd_px", &disparity_offset_initial_sd_px);
    a->Visit("disparity_offset_drift_px", &disparity_offset_drift_px);
    a->Visit("disparity_offset_max_px", &disparity_offset_max_px);
    a->Visit("keyframe_translation_m", &keyframe_translation_m);
    a->Visit("keyframe_rotation_deg", &keyframe_rotation_deg);
    a->Visit("keyframe_min_overlap", &keyframe_min_overlap);
    a->Visit("keyframe_max_interval_s", &keyframe_max_interval_s);
    a->Visit("min_mean_intensity", &min_mean_intensity);
    a->Visit("max_mean_intensity", &max_mean_intensity);
    a->Visit("min_features", &min_features);
    a->Visit("min_quads", &min_quads);
    a->Visit("max_speed_mps", &max_speed_mps);
    a->Visit("max_gap_s", &max_gap_s);
    a->Visit("use_odometry_prior", &use_odometry_prior);
    a->Visit("laser_depth", &laser_depth);
    a->Visit("laser_max_time_offset_s", &laser_max_time_offset_s);
    a->Visit("local_ba", &local_ba);
  }
  fl::Status Validate() const;
};

enum class TrackingState {
  kInitialized,  // first frame (or first of a new segment): keyframe made, no motion yet
  kTracked,      // motion estimated relative to the previous good frame
  kNotTracked,   // this frame could not be used (message says why); no factor; state kept
  kRejected,     // the input was invalid (sizes, time stamps); nothing changed
};
const char* ToString(TrackingState s);

// Relative-pose factor between two keyframes, in the BASE frame:
// T_i_j = T_world_base_i^-1 T_world_base_j, information of [dx dy dz droll dpitch dyaw]
// (right perturbation, translation first), as fusionloc.relative_pose_factor_t.
struct KeyframeFactor {
  Utime utime_i = 0, utime_j = 0;
  int64_t keyframe_id_i = -1, keyframe_id_j = -1;
  Eigen::Isometry3d T_i_j = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Identity();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
};

struct FrameStats {
  int features_left = 0, features_right = 0;
  int stereo_matches = 0;    // at this frame
  QuadStats quads;           // quadrilateral check against the previous good frame
  int subpixel_dropped = 0;  // stereo matches dropped by the sub-pixel alignment
  int ransac_inliers = 0;    // RANSAC inliers
  int inliers = 0;           // inliers of the final refinement
  int ransac_iterations = 0;
  // The temporal matching was predicted by the wheel odometry (use_odometry_prior).
  bool odometry_prior = false;
  double reprojection_rms_px = 0;
  // Disparity offset estimate after this frame [px] (measured minus true disparity; already
  // subtracted from every disparity) and its standard deviation [px].
  double disparity_offset_px = 0, disparity_offset_sd_px = 0;
  double ms_total = 0, ms_features = 0, ms_matching = 0, ms_motion = 0;
  // Laser-aided mode: scan points projected into this frame's image, and over the closed
  // correspondences the features given a laser depth at the previous / this frame and those
  // whose laser depth was rejected (depth discontinuity; disagreement with stereo), both frames.
  int laser_points_in_view = 0;
  int laser_depth_prev = 0, laser_depth_cur = 0;
  int laser_depth_inconsistent = 0, laser_depth_disagrees = 0;
  double ms_laser = 0;  // [ms] projection and association
  // Local bundle adjustment at this keyframe (local_ba.enabled): adjusted (false: not a
  // keyframe, or the window could not be adjusted; then the message says why), its tracks,
  // observations kept, observations dropped as outliers, reprojection RMS after [px], time.
  bool local_ba = false;
  int ba_points = 0, ba_observations = 0, ba_outliers = 0;
  double ba_rms_px = 0;
  double ms_ba = 0;
};

// A laser scan for the laser-aided mode, taken at `utime`: its points as the laser measured them
// and the extrinsic that maps them into the LEFT camera optical frame. The VO applies it while it
// projects the scan (one pass; a Velodyne scan has ~120k points, of which ~20k fall in the image).
struct LaserCloud {
  Utime utime = 0;
  std::vector<Eigen::Vector3f> points;  // [m] laser frame (the frame T_camera_laser maps from)
  // p_camera = T_camera_laser p_laser; identity when the points are already in the camera frame.
  Eigen::Isometry3d T_camera_laser = Eigen::Isometry3d::Identity();
};

struct StereoVoResult {
  TrackingState state = TrackingState::kRejected;
  std::string message;  // human-readable: why not tracked, new segment, ...
  Utime utime = 0;
  bool pose_valid = false;  // T_world_* meaningful (false before the first good frame)
  Eigen::Isometry3d T_world_base = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_world_camera = Eigen::Isometry3d::Identity();
  // Motion of the camera since the previous good frame (T_prev_cur), when tracked.
  Eigen::Isometry3d T_prev_camera = Eigen::Isometry3d::Identity();
  int segment = 0;           // increments when the motion chain breaks (gap too long)
  bool new_segment = false;  // this frame starts a new segment (no factor links it back)
  bool is_keyframe = false;
  int64_t keyframe_id = -1;              // id of this frame if it is a keyframe
  std::optional<KeyframeFactor> factor;  // from the previous keyframe to this one
  // Keyframe points, left camera frame of this keyframe [m], with gray levels in [0, 1].
  std::vector<Eigen::Vector3f> keyframe_points;
  std::vector<float> keyframe_intensities;
  FrameStats stats;
  // Laser-aided mode: "" when the scan was used (or the mode is off), else why this frame runs
  // on plain stereo (no scan, scan too far in time, too few points in front of the camera).
  std::string laser_message;
};

class StereoVo {
 public:
  // Throws std::invalid_argument with the reason if options or calibration are invalid.
  StereoVo(const StereoVoOptions& options, const StereoCalibration& calibration);
  ~StereoVo();
  StereoVo(const StereoVo&) = delete;
  StereoVo& operator=(const StereoVo&) = delete;

  // Processes one rectified pair (8-bit gray or 3-channel BGR; converted to gray) taken at
  // `utime`. Never throws on bad images: returns kRejected / kNotTracked with a message.
  // `laser` (laser-aided mode only; ignored when laser_depth.enabled is false): the scan nearest
  // in time; nullptr, or an unusable scan, runs the frame on plain stereo (laser_message says
  // why).
  StereoVoResult AddStereoFrame(Utime utime, const cv::Mat& left, const cv::Mat& right,
                                const LaserCloud* laser = nullptr);

  // Wheel odometry T_odom_base at `utime` (the ODOMETRY message), the motion prior of
  // use_odometry_prior; give it before the stereo frames of the same time. Error (sample
  // ignored) if the pose is not finite or the time does not increase.
  fl::Status AddOdometry(Utime utime, const Pose2& T_odom_base);

  const StereoCalibration& calibration() const { return calibration_; }
  const StereoVoOptions& options() const { return options_; }

 private:
  // Steps of AddStereoFrame besides the stages of stereo_vo_stages.hpp.
  StereoVoResult Reject(StereoVoResult result, TrackingState state, const std::string& why,
                        double t_start) const;
  StereoVoResult Finish(StereoVoResult result, double t_start) const;
  StereoVoResult Initialize(std::unique_ptr<stages::StereoFrame> frame, StereoVoResult result,
                            double t_start);
  StereoVoResult Track(std::unique_ptr<stages::StereoFrame> cur, StereoVoResult result,
                       double t_start);
  void StartKeyframe(const stages::StereoFrame& frame, StereoVoResult* result);
  // Laser-aided mode: projects the scan into frame->laser if usable, else says why in result.
  void AttachLaser(const LaserCloud* laser, stages::StereoFrame* frame,
                   StereoVoResult* result) const;
  void AdvancePose(const stages::Refinement& refined, double dt_s, StereoVoResult* result);
  double PredictedOffsetVariance(Utime utime) const;
  void UpdateOffset(const RefineResult& refined, double predicted_variance, Utime utime,
                    StereoVoResult* result);
  void AddKeyframeFactorIfDue(const stages::StereoFrame& frame, int tracked_from_keyframe,
                              StereoVoResult* result);
  // Local BA over ba_window_ (the new keyframe is its last): moves the window's poses and the
  // chain, and makes *factor the adjusted relative pose of the last two (covariance from the
  // window, or cov_chain, the chained camera-frame one, if the window's is rank deficient). If
  // the window cannot be adjusted, factor and chain stay and result->message says why.
  void AdjustWindow(const Eigen::Matrix<double, 6, 6>& cov_chain, KeyframeFactor* factor,
                    StereoVoResult* result);
  // The camera's motion T_a_b from time a to b by the wheel odometry (use_odometry_prior and
  // samples around both times); false otherwise.
  bool OdometryMotion(Utime a, Utime b, Eigen::Isometry3d* T_a_b_camera) const;
  StereoVoOptions options_;
  StereoCalibration calibration_;
  StereoCamera camera_;
  FeatureExtractor extractor_;
  fl::OdometryBuffer odometry_;                     // AddOdometry samples (the motion prior)
  std::unique_ptr<stages::StereoFrame> last_good_;  // previous successfully processed frame
  Utime last_utime_ = -1;                           // last accepted input time
  bool initialized_ = false;
  int segment_ = 0;
  // Pose chain.
  Eigen::Isometry3d T_world_camera_ = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_prev_velocity_ = Eigen::Isometry3d::Identity();  // last T_prev_cur
  double velocity_dt_s_ = 0;  // time of that motion (0: no prediction)
  // Keyframe chain.
  int64_t next_keyframe_id_ = 0;
  int64_t keyframe_id_ = -1;
  Utime keyframe_utime_ = 0;
  Eigen::Isometry3d T_kf_camera_ = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> cov_kf_camera_ = Eigen::Matrix<double, 6, 6>::Zero();
  int64_t keyframe_max_track_id_ = -1;
  // Tracks of the keyframe carried into the first frame after it (the overlap's reference);
  // -1 until that frame is tracked.
  int keyframe_tracks_ = -1;
  int64_t next_track_id_ = 0;
  // Local BA: the last keyframes of this segment, oldest first (local_ba.enabled).
  std::vector<BaKeyframe> ba_window_;
  // Disparity offset filter (scalar Kalman, random walk).
  double offset_px_ = 0;
  double offset_var_px2_ = 0;
  Utime offset_utime_ = -1;      // time of the last update (for the random walk)
  double pixel_sigma_px_ = 0.5;  // reprojection noise of the last refinement (scales the prior)
};

}  // namespace fl::vo
