// The stages of fl::vo::StereoVo::AddStereoFrame, one function each, so that tests can call
// them (detail header: StereoVo is the interface). In order:
//   CheckImages, CheckExposure     input and image quality checks
//   DetectFeatures                 FAST corners + ORB descriptors in both images
//   MatchStereoFrame               left <-> right matches, sub-pixel right x (RefineStereo)
//   SearchMotion                   the retry loop over temporal predictions; per attempt:
//     PredictByVelocity / EstimateGlobalShift + PredictByShift
//     MatchTemporalPair            prev -> cur in both images
//     CheckQuadrilaterals          the closed-loop check
//     BuildCorrespondences         triangulated 3D-3D pairs with the disparity offset
//     RansacMotion (motion.hpp)    3-point SVD hypotheses
//   RefineStage (+ SelectInliers)  bundle adjustment rounds with inlier re-selection
//   PropagateTracks, AssignNewTracks
//   NeedsKeyframe, MakeKeyframeFactor, KeyframePoints, KeyframeObservations
//   (local_ba.hpp: the keyframe window's bundle adjustment)
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "fusionloc/common/time.hpp"
#include "fusionloc/stereo_vo/laser_depth.hpp"
#include "fusionloc/stereo_vo/local_ba.hpp"
#include "fusionloc/stereo_vo/matching.hpp"
#include "fusionloc/stereo_vo/motion.hpp"
#include "fusionloc/stereo_vo/stereo_vo.hpp"

namespace fl::vo::stages {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

// One stereo pair as the VO keeps it.
struct StereoFrame {
  Utime utime = 0;
  cv::Mat left, right;         // gray
  std::vector<float> right_x;  // per left feature with a stereo match: right x [px]
  Features fl, fr;
  std::vector<int> stereo;        // left -> right
  std::vector<int64_t> track_id;  // per left feature with a stereo match, else -1
  int stereo_matches = 0;
  std::shared_ptr<const LaserDepthMap> laser;  // laser-aided mode: the usable scan, else null
};

// ---- input checks ----
// Why the pair is unusable (empty, sizes differ from the calibration, pixel type), or "" with
// the 8-bit gray views/conversions in *left, *right.
std::string CheckImages(const cv::Mat& left_in, const cv::Mat& right_in,
                        const StereoCalibration& calibration, cv::Mat* left, cv::Mat* right);
// Why `utime` cannot follow `last_utime` (-1: none yet), or "".
std::string CheckTimeStamp(Utime utime, Utime last_utime);
// "black frame ..." / "saturated frame ..." by the mean gray of the darker / brighter image,
// or "".
std::string CheckExposure(const cv::Mat& left, const cv::Mat& right,
                          const StereoVoOptions& options);

// ---- detection ----
// Features of frame->left and frame->right into frame->fl, frame->fr.
void DetectFeatures(FeatureExtractor* extractor, StereoFrame* frame);

// ---- stereo matching ----
// Sub-pixel disparity: frame->right_x of each stereo match by Lucas-Kanade alignment of the
// left patch in the right image (or the right corner's x without subpixel_refinement); drops
// (stereo = -1) matches whose alignment fails, moves more than subpixel_max_shift_px or leaves
// the row. Returns how many were dropped.
int RefineStereo(const StereoVoOptions& options, StereoFrame* frame);
// MatchStereo + RefineStereo; resets the track ids to -1 and counts frame->stereo_matches.
// Returns the number of matches the sub-pixel alignment dropped.
int MatchStereoFrame(const StereoVoOptions& options, StereoFrame* frame);

// ---- temporal matching ----
// Predicted positions in the current images per previous keypoint ((-1, -1): none) and the
// search half-window.
struct TemporalPrediction {
  std::vector<cv::Point2f> left, right;
  double radius_px = 0;
};
// Constant velocity: each stereo point of prev (raw keypoint disparity) moved by the inverse of
// the last motion T_prev_cur and projected; window matching.window_px.
TemporalPrediction PredictByVelocity(const StereoCamera& camera, const StereoFrame& prev,
                                     const Eigen::Isometry3d& T_prev_cur,
                                     const MatchOptions& options);
// The global image shift: median flow of a wide search (window_unpredicted_px) for a subset of
// at most about 200 of prev's stereo features. found: at least 8 wide matches.
struct GlobalShift {
  bool found = false;
  cv::Point2f shift{0, 0};  // [px] cur - prev
};
GlobalShift EstimateGlobalShift(const StereoFrame& prev, const StereoFrame& cur,
                                const MatchOptions& options);
// Every stereo feature of prev moved by the shift; window 3 window_px (capped at
// window_unpredicted_px) around a found shift, window_unpredicted_px without one.
TemporalPrediction PredictByShift(const StereoFrame& prev, const GlobalShift& shift,
                                  const MatchOptions& options);
// prev -> cur matches in the left and in the right images, in the predicted windows.
struct TemporalMatches {
  std::vector<int> left, right;
};
TemporalMatches MatchTemporalPair(const StereoFrame& prev, const StereoFrame& cur,
                                  const TemporalPrediction& prediction,
                                  const MatchOptions& options);

// ---- quadrilateral check ----
struct QuadMatches {
  std::vector<Quad> quads;
  QuadStats stats;
};
QuadMatches CheckQuadrilaterals(const StereoFrame& prev, const StereoFrame& cur,
                                const TemporalMatches& temporal, const MatchOptions& options);
// 3D-3D correspondences of the quads whose disparities (right x corrected by the offset
// estimate offset_px) are positive at both times; quad[k]: the quad of correspondence k.
struct Correspondences {
  std::vector<StereoCorrespondence> corr;
  std::vector<int> quad;
};
Correspondences BuildCorrespondences(const StereoCamera& camera, const StereoFrame& prev,
                                     const StereoFrame& cur, const std::vector<Quad>& quads,
                                     double offset_px);

// ---- motion (RANSAC + SVD), with the retry over predictions ----
struct FrameMatch {
  QuadMatches quads;
  Correspondences corr;
  RansacResult ransac;  // ok false: no attempt found a motion (then corr is the last attempt's)
  int attempt = -1;     // the attempt kept: 0 velocity prediction, 1 global shift
};
// The last motion, if it predicts this frame (its time within 0.75..1.33 of dt_s).
bool VelocityPredicts(double dt_s, double velocity_dt_s);
// Attempt 0 (if predict_velocity): the constant-velocity prediction T_prev_cur (narrow
// windows). Attempt 1: the global shift. Each attempt matches, closes quadrilaterals, builds
// correspondences and, with at least min_quads of them, runs RANSAC; the attempt with the most
// inliers is kept, and attempt 1 is skipped when attempt 0 has 2 min_quads inliers.
FrameMatch SearchMotion(const StereoCamera& camera, const StereoFrame& prev, const StereoFrame& cur,
                        bool predict_velocity, const Eigen::Isometry3d& T_prev_cur,
                        double offset_px, const StereoVoOptions& options);

// ---- refinement ----
// Correspondences whose reprojection error, both directions (max over u, v, u_right), is at
// most threshold_px under T_a_b.
std::vector<int> SelectInliers(const StereoCamera& camera,
                               const std::vector<StereoCorrespondence>& corr,
                               const Eigen::Isometry3d& T_a_b, double threshold_px);
struct Refinement {
  bool ok = false;  // false: a refinement round failed (degenerate geometry)
  Eigen::Isometry3d T_a_b = Eigen::Isometry3d::Identity();
  Matrix6d covariance = Matrix6d::Identity() * 1e-2;
  std::vector<int> inliers;
  double rms_px = 0;  // of the last successful round (0: none)
  RefineResult last;  // the last round's result (disparity offset, pixel sigma)
};
// refine_rounds rounds of RefineMotion from the RANSAC motion, re-selecting the inliers
// (SelectInliers, RANSAC threshold) between rounds while at least ransac.min_inliers remain.
// Without use_refinement: the RANSAC motion and inliers, covariance 1e-2 I.
// offset_prior: estimate the disparity offset increment (nullptr: not).
// measured: the laser-aided 3D point errors (nullptr: plain reprojection error).
Refinement RefineStage(const StereoCamera& camera, const std::vector<StereoCorrespondence>& corr,
                       const RansacResult& ransac, const OffsetPrior* offset_prior,
                       const StereoVoOptions& options, const PointMeasurements* measured = nullptr);

// ---- laser-aided mode ----
// The laser depth of each correspondence's feature at a (prev->laser) and at b (cur->laser),
// validated against its stereo depth, as 3D point measurements (PointMeasurement: m = depth *
// ray, depth sigma from the association, lateral sigma point_lateral_sigma_px * depth / fx). Counts
// what it gave and rejected.
// One feature's laser depth as a 3D point measurement: the association of LaserDepthMap
// validated against its stereo depth; kOk with *m = depth * ray (left camera frame [m]) and *W
// its square-root information (depth sigma along the ray, point_lateral_sigma_px across it),
// else why not (kTooFew also when the map gave only the stereo depth).
LaserDepthVerdict LaserPoint(const StereoCamera& camera, const LaserDepthMap& map,
                             const Eigen::Vector3d& obs, double stereo_depth_m,
                             const LaserDepthOptions& options, Eigen::Vector3d* m,
                             Eigen::Matrix3d* W);
struct LaserAssociation {
  PointMeasurements measured;
  int prev = 0, cur = 0;
  int inconsistent = 0, disagrees = 0;  // rejected: discontinuity / disagreement with stereo
};
LaserAssociation AssociateLaserDepth(const StereoCamera& camera, const StereoFrame& prev,
                                     const StereoFrame& cur,
                                     const std::vector<StereoCorrespondence>& corr,
                                     double pixel_sigma_px, const LaserDepthOptions& options);

// ---- tracks ----
// Carries prev's track ids over the inlier quads to cur; returns how many of them belong to the
// keyframe (id in [0, keyframe_max_track_id]).
int PropagateTracks(const StereoFrame& prev, const FrameMatch& match,
                    const std::vector<int>& inliers, int64_t keyframe_max_track_id,
                    StereoFrame* cur);
// New ids (from *next_track_id on) for the stereo features without one.
void AssignNewTracks(StereoFrame* frame, int64_t* next_track_id);

// ---- keyframe decision ----
// A new keyframe when the motion since the keyframe reaches keyframe_translation_m or
// keyframe_rotation_deg, fewer than keyframe_min_overlap of keyframe_tracks (the keyframe's
// tracks that the first frame after it carried over) remain, or keyframe_max_interval_s has
// passed (since_keyframe_us).
bool NeedsKeyframe(const Eigen::Isometry3d& T_kf_camera, int tracked_from_keyframe,
                   int keyframe_tracks, Utime since_keyframe_us, const StereoVoOptions& options);
// The factor's motion, covariance and information in the base frame (times and ids not set).
KeyframeFactor MakeKeyframeFactor(const Eigen::Isometry3d& T_base_camera,
                                  const Eigen::Isometry3d& T_kf_camera,
                                  const Matrix6d& cov_kf_camera);
// The triangulated stereo matches of a keyframe (left camera frame) with their gray levels.
void KeyframePoints(const StereoCamera& camera, const StereoFrame& frame, double offset_px,
                    std::vector<Eigen::Vector3f>* points, std::vector<float>* intensities);
// The local bundle adjustment's observations of a keyframe: every stereo feature with a track
// id, (u_left, v, u_right corrected by the disparity offset offset_px), with its validated laser
// depth point (LaserPoint) when laser_options is given and the frame has a usable scan.
std::vector<BaObservation> KeyframeObservations(const StereoCamera& camera,
                                                const StereoFrame& frame, double offset_px,
                                                const LaserDepthOptions* laser_options);

}  // namespace fl::vo::stages
