#include "fusionloc/stereo_vo/stereo_vo.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "fusionloc/stereo_vo/stereo_vo_stages.hpp"

namespace fl::vo {
namespace {

double NowMs() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// Disparity offset prior: the filter's prediction (random walk since its last update), its
// variance halved because every frame's observations enter two frame pairs; the update counts
// the data's information kReuse times likewise.
constexpr double kReuse = 0.5;

}  // namespace

const char* ToString(TrackingState s) {
  switch (s) {
    case TrackingState::kInitialized:
      return "initialized";
    case TrackingState::kTracked:
      return "tracked";
    case TrackingState::kNotTracked:
      return "not tracked";
    case TrackingState::kRejected:
      return "rejected";
  }
  return "?";
}

fl::Status StereoCalibration::Validate() const {
  if (!rectified) {
    return fl::Status::Error(
        "stereo calibration is not rectified: fl-stereo-vo needs rectified, row-aligned pairs; "
        "rectify the images (e.g. cv::stereoRectify + remap) and publish rectified=true");
  }
  if (!(fx > 0 && fy > 0 && std::isfinite(fx) && std::isfinite(fy))) {
    return fl::Status::Error("stereo calibration: focal lengths fx, fy must be > 0");
  }
  if (!(std::isfinite(cx) && std::isfinite(cy))) {
    return fl::Status::Error("stereo calibration: principal point cx, cy must be finite");
  }
  if (!(baseline > 0 && std::isfinite(baseline))) {
    return fl::Status::Error(
        "stereo calibration: baseline must be > 0 m (right camera at +x of the left)");
  }
  if (width < 64 || height < 64) {
    return fl::Status::Error("stereo calibration: image size " + std::to_string(width) + "x" +
                             std::to_string(height) + " is too small (>= 64x64)");
  }
  // A bound for what arrives over the network (images and buffers are sized from it).
  if (width > kMaxImageSidePx || height > kMaxImageSidePx) {
    return fl::Status::Error("stereo calibration: image size " + std::to_string(width) + "x" +
                             std::to_string(height) + " is larger than " +
                             std::to_string(kMaxImageSidePx) + " px a side (corrupt message?)");
  }
  const Eigen::Matrix3d R = T_base_camera.linear();
  if (!T_base_camera.matrix().allFinite() ||
      (R * R.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-6 || R.determinant() < 0) {
    return fl::Status::Error("stereo calibration: T_base_camera is not a rigid transform");
  }
  return fl::Status::Ok();
}

fl::Status StereoVoOptions::Validate() const {
  if (auto s = features.Validate(); !s.ok()) return s;
  if (auto s = matching.Validate(); !s.ok()) return s;
  if (ransac.max_iterations < 1) return fl::Status::Error("ransac.max_iterations must be >= 1");
  if (!(ransac.confidence > 0 && ransac.confidence < 1)) {
    return fl::Status::Error("ransac.confidence must be in (0, 1)");
  }
  if (!(ransac.inlier_threshold_px > 0)) {
    return fl::Status::Error("ransac.inlier_threshold_px must be > 0");
  }
  if (ransac.min_inliers < 3) return fl::Status::Error("ransac.min_inliers must be >= 3");
  if (refine.max_iterations < 1) return fl::Status::Error("refine.max_iterations must be >= 1");
  if (!(refine.huber_px > 0 && refine.min_sigma_px > 0 && refine.covariance_scale > 0)) {
    return fl::Status::Error("refine.huber_px, min_sigma_px and covariance_scale must be > 0");
  }
  if (!(keyframe_translation_m > 0 && keyframe_rotation_deg > 0 && keyframe_max_interval_s > 0)) {
    return fl::Status::Error(
        "keyframe_translation_m, keyframe_rotation_deg, keyframe_max_interval_s must be > 0");
  }
  if (!(keyframe_min_overlap >= 0 && keyframe_min_overlap <= 1)) {
    return fl::Status::Error("keyframe_min_overlap must be in [0, 1]");
  }
  if (!(min_mean_intensity >= 0 && max_mean_intensity <= 255 &&
        min_mean_intensity < max_mean_intensity)) {
    return fl::Status::Error("need 0 <= min_mean_intensity < max_mean_intensity <= 255");
  }
  if (subpixel_window_px < 5 || subpixel_window_px > 31 || subpixel_window_px % 2 == 0) {
    return fl::Status::Error("subpixel_window_px must be odd, in [5, 31]");
  }
  if (!(subpixel_max_shift_px > 0)) return fl::Status::Error("subpixel_max_shift_px must be > 0");
  if (refine_rounds < 1 || refine_rounds > 5) {
    return fl::Status::Error("refine_rounds must be in [1, 5]");
  }
  if (min_features < 3 || min_quads < 3) {
    return fl::Status::Error("min_features and min_quads must be >= 3");
  }
  if (estimate_disparity_offset &&
      (!use_refinement || !refine.optimize_points || refine.use_ceres)) {
    return fl::Status::Error(
        "estimate_disparity_offset needs the analytic two-view bundle adjustment: set "
        "use_refinement true, refine.optimize_points true and refine.use_ceres false, or "
        "estimate_disparity_offset false");
  }
  if (!(std::isfinite(disparity_offset_initial_px) && disparity_offset_initial_sd_px > 0 &&
        disparity_offset_drift_px >= 0 && disparity_offset_max_px > 0 &&
        std::abs(disparity_offset_initial_px) < disparity_offset_max_px)) {
    return fl::Status::Error(
        "disparity offset: need disparity_offset_initial_sd_px > 0, disparity_offset_drift_px >= "
        "0 and |disparity_offset_initial_px| < disparity_offset_max_px");
  }
  if (!(max_speed_mps > 0 && max_gap_s > 0)) {
    return fl::Status::Error("max_speed_mps and max_gap_s must be > 0");
  }
  if (auto s = laser_depth.Validate(); !s.ok()) return s;
  if (auto s = local_ba.Validate(); !s.ok()) return s;
  if (!(laser_max_time_offset_s >= 0)) {
    return fl::Status::Error("laser_max_time_offset_s must be >= 0");
  }
  if (laser_depth.enabled && (!use_refinement || !refine.optimize_points || refine.use_ceres)) {
    return fl::Status::Error(
        "laser_depth.enabled needs the analytic two-view bundle adjustment (the 3D point errors "
        "live there): set use_refinement true, refine.optimize_points true and refine.use_ceres "
        "false, or laser_depth.enabled false");
  }
  return fl::Status::Ok();
}

StereoVo::StereoVo(const StereoVoOptions& options, const StereoCalibration& calibration)
    : options_(options),
      calibration_(calibration),
      camera_(calibration.camera()),
      extractor_(options.features) {
  if (auto s = options.Validate(); !s.ok()) {
    throw std::invalid_argument("stereo VO options: " + s.message());
  }
  if (auto s = calibration.Validate(); !s.ok()) throw std::invalid_argument(s.message());
  T_world_camera_ = calibration_.T_base_camera;
  offset_px_ = options_.disparity_offset_initial_px;
  offset_var_px2_ =
      options_.disparity_offset_initial_sd_px * options_.disparity_offset_initial_sd_px;
}

StereoVo::~StereoVo() = default;

StereoVoResult StereoVo::AddStereoFrame(Utime utime, const cv::Mat& left_in,
                                        const cv::Mat& right_in, const LaserCloud* laser) {
  const double t_start = NowMs();
  StereoVoResult result;
  result.utime = utime;
  result.segment = segment_;
  auto cur = std::make_unique<stages::StereoFrame>();
  cur->utime = utime;

  // ---- input checks, image quality ----
  std::string why = stages::CheckImages(left_in, right_in, calibration_, &cur->left, &cur->right);
  if (why.empty()) why = stages::CheckTimeStamp(utime, last_utime_);
  if (!why.empty()) return Reject(std::move(result), TrackingState::kRejected, why, t_start);
  last_utime_ = utime;
  why = stages::CheckExposure(cur->left, cur->right, options_);
  if (!why.empty()) return Reject(std::move(result), TrackingState::kNotTracked, why, t_start);

  // ---- detection ----
  double t0 = NowMs();
  stages::DetectFeatures(&extractor_, cur.get());
  result.stats.ms_features = NowMs() - t0;
  result.stats.features_left = cur->fl.size();
  result.stats.features_right = cur->fr.size();
  const int corners = std::min(cur->fl.size(), cur->fr.size());
  if (corners < options_.min_features) {
    return Reject(std::move(result), TrackingState::kNotTracked,
                  "low texture (" + std::to_string(corners) + " corners, need " +
                      std::to_string(options_.min_features) + ")",
                  t_start);
  }

  // ---- stereo matching ----
  t0 = NowMs();
  result.stats.subpixel_dropped = stages::MatchStereoFrame(options_, cur.get());
  result.stats.stereo_matches = cur->stereo_matches;
  result.stats.ms_matching = NowMs() - t0;
  if (cur->stereo_matches < options_.min_quads) {
    return Reject(std::move(result), TrackingState::kNotTracked,
                  "too few stereo matches (" + std::to_string(cur->stereo_matches) + ")", t_start);
  }

  // ---- laser-aided mode: the scan projected into the image ----
  if (options_.laser_depth.enabled) AttachLaser(laser, cur.get(), &result);

  // ---- first frame, or the first after a gap too long to bridge ----
  if (!last_good_ || static_cast<double>(utime - last_good_->utime) * 1e-6 > options_.max_gap_s) {
    return Initialize(std::move(cur), std::move(result), t_start);
  }

  return Track(std::move(cur), std::move(result), t_start);
}

// Motion against the last good frame: temporal matching, quadrilateral check, RANSAC + SVD (the
// retry loop of SearchMotion), refinement; then the pose chain, tracks and keyframe decision.
StereoVoResult StereoVo::Track(std::unique_ptr<stages::StereoFrame> cur, StereoVoResult result,
                               double t_start) {
  const stages::StereoFrame& prev = *last_good_;
  const Utime utime = cur->utime;
  const double dt_s = static_cast<double>(utime - prev.utime) * 1e-6;
  double t0 = NowMs();
  // The motion prediction: the wheel odometry's if there is one, else constant velocity.
  Eigen::Isometry3d T_prev_predicted = T_prev_velocity_;
  result.stats.odometry_prior = OdometryMotion(prev.utime, utime, &T_prev_predicted);
  const bool predict = result.stats.odometry_prior ||
                       stages::VelocityPredicts(dt_s, velocity_dt_s_);
  const stages::FrameMatch match = stages::SearchMotion(camera_, prev, *cur, predict,
                                                        T_prev_predicted, offset_px_, options_);
  const std::vector<StereoCorrespondence>& corr = match.corr.corr;
  result.stats.quads = match.quads.stats;
  result.stats.ms_matching += NowMs() - t0;
  if (static_cast<int>(corr.size()) < options_.min_quads) {
    return Reject(std::move(result), TrackingState::kNotTracked,
                  "only " + std::to_string(corr.size()) + " closed quadrilaterals (need " +
                      std::to_string(options_.min_quads) + ") against the frame " +
                      std::to_string(dt_s) + " s earlier",
                  t_start);
  }
  t0 = NowMs();
  result.stats.ransac_iterations = match.ransac.iterations;
  result.stats.ransac_inliers = static_cast<int>(match.ransac.inliers.size());
  if (!match.ransac.ok) {
    result.stats.ms_motion = NowMs() - t0;
    return Reject(std::move(result), TrackingState::kNotTracked,
                  "RANSAC found no consistent motion (" +
                      std::to_string(match.ransac.inliers.size()) + " inliers of " +
                      std::to_string(corr.size()) + ")",
                  t_start);
  }

  // ---- refinement (laser-aided: with the 3D point errors of the features with laser depth) ----
  const double offset_pred_var = PredictedOffsetVariance(utime);
  OffsetPrior offset_prior;
  offset_prior.variance_px2 = kReuse * offset_pred_var;
  offset_prior.sigma_px = pixel_sigma_px_;
  stages::LaserAssociation laser;
  const bool use_laser = options_.laser_depth.enabled && (prev.laser || cur->laser);
  if (use_laser) {
    const double tl = NowMs();
    laser = stages::AssociateLaserDepth(camera_, prev, *cur, corr, pixel_sigma_px_,
                                        options_.laser_depth);
    result.stats.laser_depth_prev = laser.prev;
    result.stats.laser_depth_cur = laser.cur;
    result.stats.laser_depth_inconsistent = laser.inconsistent;
    result.stats.laser_depth_disagrees = laser.disagrees;
    result.stats.ms_laser += NowMs() - tl;
  }
  const stages::Refinement refined = stages::RefineStage(
      camera_, corr, match.ransac, options_.estimate_disparity_offset ? &offset_prior : nullptr,
      options_, use_laser ? &laser.measured : nullptr);
  result.stats.reprojection_rms_px = refined.rms_px;
  if (!refined.ok) {
    result.stats.ms_motion = NowMs() - t0;
    return Reject(std::move(result), TrackingState::kNotTracked,
                  "motion refinement failed (degenerate geometry)", t_start);
  }
  const Eigen::Isometry3d& T_a_b = refined.T_a_b;
  result.stats.inliers = static_cast<int>(refined.inliers.size());
  result.stats.ms_motion = NowMs() - t0;
  const double speed = T_a_b.translation().norm() / std::max(dt_s, 1e-6);
  if (speed > options_.max_speed_mps) {
    return Reject(std::move(result), TrackingState::kNotTracked,
                  "implausible motion " + std::to_string(speed) + " m/s (max_speed_mps " +
                      std::to_string(options_.max_speed_mps) + ")",
                  t_start);
  }

  // ---- accept: disparity offset filter, pose chain, tracks, keyframe decision ----
  UpdateOffset(refined.last, offset_pred_var, utime, &result);
  AdvancePose(refined, dt_s, &result);
  const int tracked_from_keyframe =
      stages::PropagateTracks(prev, match, refined.inliers, keyframe_max_track_id_, cur.get());
  stages::AssignNewTracks(cur.get(), &next_track_id_);
  AddKeyframeFactorIfDue(*cur, tracked_from_keyframe, &result);
  result.state = TrackingState::kTracked;
  std::ostringstream msg;
  msg << "tracked: " << result.stats.inliers << "/" << corr.size() << " inliers, rms "
      << result.stats.reprojection_rms_px << " px";
  if (!result.message.empty()) msg << "; " << result.message;
  result.message = msg.str();
  last_good_ = std::move(cur);
  return Finish(std::move(result), t_start);
}

void StereoVo::AttachLaser(const LaserCloud* laser, stages::StereoFrame* frame,
                           StereoVoResult* result) const {
  const double t0 = NowMs();
  std::string why;
  if (laser == nullptr) {
    why = "no laser scan for this frame";
  } else if (std::abs(static_cast<double>(laser->utime - frame->utime)) * 1e-6 >
             options_.laser_max_time_offset_s) {
    why = "laser scan " + std::to_string(static_cast<double>(laser->utime - frame->utime) * 1e-6) +
          " s from the images (laser_max_time_offset_s " +
          std::to_string(options_.laser_max_time_offset_s) + ")";
  } else {
    auto map = std::make_shared<const LaserDepthMap>(
        options_.laser_depth, camera_, calibration_.width, calibration_.height, laser->points,
        laser->T_camera_laser);
    result->stats.laser_points_in_view = map->points_in_view();
    if (map->usable()) {
      frame->laser = std::move(map);
    } else {
      why = "laser scan has " + std::to_string(map->points_in_view()) + " of " +
            std::to_string(laser->points.size()) + " points in front of the camera in the image (" +
            "laser_depth.min_points_in_view " +
            std::to_string(options_.laser_depth.min_points_in_view) +
            "): is its extrinsic T_camera_laser right?";
    }
  }
  if (!why.empty()) {
    result->laser_message = why + "; plain stereo for this frame";
    result->message = "laser: " + result->laser_message;
  }
  result->stats.ms_laser = NowMs() - t0;
}

StereoVoResult StereoVo::Reject(StereoVoResult result, TrackingState state, const std::string& why,
                                double t_start) const {
  result.state = state;
  result.message = (state == TrackingState::kRejected ? "rejected: " : "not tracked: ") + why;
  return Finish(std::move(result), t_start);
}

StereoVoResult StereoVo::Finish(StereoVoResult result, double t_start) const {
  result.pose_valid = initialized_;
  result.T_world_camera = T_world_camera_;
  result.T_world_base = T_world_camera_ * calibration_.T_base_camera.inverse();
  result.stats.disparity_offset_px = offset_px_;
  result.stats.disparity_offset_sd_px = std::sqrt(offset_var_px2_);
  result.stats.ms_total = NowMs() - t_start;
  return result;
}

// The first frame, or the first of a new segment after a gap (then last_good_ is set).
StereoVoResult StereoVo::Initialize(std::unique_ptr<stages::StereoFrame> frame,
                                    StereoVoResult result, double t_start) {
  if (last_good_) {
    ++segment_;
    result.new_segment = true;
    result.segment = segment_;
    // The pose across the gap: the wheel odometry's motion if there is one, else unchanged.
    Eigen::Isometry3d T_gap = Eigen::Isometry3d::Identity();
    const bool bridged = OdometryMotion(last_good_->utime, frame->utime, &T_gap);
    T_world_camera_ = T_world_camera_ * T_gap;
    result.message =
        "initialized a new segment: " + std::to_string((frame->utime - last_good_->utime) * 1e-6) +
        " s since the last tracked frame (max_gap_s " + std::to_string(options_.max_gap_s) +
        "); no factor links it" +
        (bridged ? ", the pose is carried across it by the wheel odometry"
                 : ", and the motion across it is unknown (no wheel odometry)");
  } else {
    result.message = "initialized";
  }
  initialized_ = true;
  velocity_dt_s_ = 0;
  ba_window_.clear();  // no factor links the segments: neither does the window
  stages::AssignNewTracks(frame.get(), &next_track_id_);
  StartKeyframe(*frame, &result);
  result.state = TrackingState::kInitialized;
  last_good_ = std::move(frame);
  return Finish(std::move(result), t_start);
}

void StereoVo::StartKeyframe(const stages::StereoFrame& frame, StereoVoResult* result) {
  result->is_keyframe = true;
  result->keyframe_id = next_keyframe_id_;
  keyframe_id_ = next_keyframe_id_++;
  keyframe_utime_ = frame.utime;
  T_kf_camera_.setIdentity();
  cov_kf_camera_.setZero();
  keyframe_max_track_id_ = next_track_id_ - 1;
  keyframe_tracks_ = -1;  // set by the next tracked frame (AddKeyframeFactorIfDue)
  stages::KeyframePoints(camera_, frame, offset_px_, &result->keyframe_points,
                         &result->keyframe_intensities);
  if (options_.local_ba.enabled) {
    BaKeyframe kf;
    kf.id = keyframe_id_;
    kf.utime = frame.utime;
    kf.T_world_camera = T_world_camera_;
    // The laser depth points only if the window uses them (an association per observation).
    kf.observations = stages::KeyframeObservations(
        camera_, frame, offset_px_,
        options_.local_ba.laser_points ? &options_.laser_depth : nullptr);
    ba_window_.push_back(std::move(kf));
    const size_t window = static_cast<size_t>(options_.local_ba.window_keyframes);
    if (ba_window_.size() > window) {
      ba_window_.erase(ba_window_.begin(), ba_window_.end() - static_cast<long>(window));
    }
  }
}

double StereoVo::PredictedOffsetVariance(Utime utime) const {
  double var = offset_var_px2_;
  if (offset_utime_ >= 0) {
    var += options_.disparity_offset_drift_px * options_.disparity_offset_drift_px *
           static_cast<double>(utime - offset_utime_) * 1e-6;
  }
  return var;
}

void StereoVo::UpdateOffset(const RefineResult& refined, double predicted_variance, Utime utime,
                            StereoVoResult* result) {
  if (refined.ok) pixel_sigma_px_ = std::clamp(refined.sigma_px, 0.1, 2.0);
  if (!refined.ok || !refined.offset_estimated) return;
  // Kalman update with the data's information counted kReuse times (see kReuse).
  offset_px_ += refined.offset_px;
  offset_var_px2_ = 1.0 / (1.0 / predicted_variance + kReuse * refined.offset_data_information);
  offset_utime_ = utime;
  if (std::abs(offset_px_) > options_.disparity_offset_max_px) {
    result->message = "disparity offset estimate " + std::to_string(offset_px_) +
                      " px exceeds disparity_offset_max_px " +
                      std::to_string(options_.disparity_offset_max_px) +
                      ": reset to the initial value; check the stereo calibration";
    offset_px_ = options_.disparity_offset_initial_px;
    offset_var_px2_ =
        options_.disparity_offset_initial_sd_px * options_.disparity_offset_initial_sd_px;
  }
}

// The frame-to-frame motion onto the world pose, the velocity and the keyframe chain.
void StereoVo::AdvancePose(const stages::Refinement& refined, double dt_s, StereoVoResult* result) {
  const Eigen::Isometry3d& T_a_b = refined.T_a_b;
  T_world_camera_ = T_world_camera_ * T_a_b;
  T_prev_velocity_ = T_a_b;
  velocity_dt_s_ = dt_s;
  result->T_prev_camera = T_a_b;
  cov_kf_camera_ = ComposeCovariance(cov_kf_camera_, T_a_b, refined.covariance);
  T_kf_camera_ = T_kf_camera_ * T_a_b;
}

fl::Status StereoVo::AddOdometry(Utime utime, const Pose2& T_odom_base) {
  return odometry_.Add(utime, T_odom_base);
}

bool StereoVo::OdometryMotion(Utime a, Utime b, Eigen::Isometry3d* T_a_b_camera) const {
  if (!options_.use_odometry_prior || odometry_.empty()) return false;
  Pose2 T_odom_a, T_odom_b;
  if (!odometry_.Lookup(a, &T_odom_a).ok() || !odometry_.Lookup(b, &T_odom_b).ok()) return false;
  const Eigen::Isometry3d& T_base_camera = calibration_.T_base_camera;
  *T_a_b_camera = T_base_camera.inverse() * T_odom_a.between(T_odom_b).ToIsometry3() *
                  T_base_camera;
  return true;
}

void StereoVo::AddKeyframeFactorIfDue(const stages::StereoFrame& frame, int tracked_from_keyframe,
                                      StereoVoResult* result) {
  if (keyframe_tracks_ < 0) keyframe_tracks_ = tracked_from_keyframe;
  if (!stages::NeedsKeyframe(T_kf_camera_, tracked_from_keyframe, keyframe_tracks_,
                             frame.utime - keyframe_utime_, options_)) {
    return;
  }
  KeyframeFactor f =
      stages::MakeKeyframeFactor(calibration_.T_base_camera, T_kf_camera_, cov_kf_camera_);
  f.utime_i = keyframe_utime_;
  f.utime_j = frame.utime;
  f.keyframe_id_i = keyframe_id_;
  const Eigen::Isometry3d T_chain = T_kf_camera_;
  const Eigen::Matrix<double, 6, 6> cov_chain = cov_kf_camera_;
  StartKeyframe(frame, result);
  f.keyframe_id_j = keyframe_id_;
  if (options_.local_ba.enabled) {
    // The chained motion from the previous keyframe: the window's motion prior.
    BaKeyframe& kf = ba_window_.back();
    kf.has_motion = ba_window_.size() >= 2;
    kf.T_prev_camera = T_chain;
    kf.motion_covariance = cov_chain;
    AdjustWindow(cov_chain, &f, result);
  }
  if (f.information.allFinite()) result->factor = f;
}

void StereoVo::AdjustWindow(const Eigen::Matrix<double, 6, 6>& cov_chain, KeyframeFactor* factor,
                            StereoVoResult* result) {
  const double t0 = NowMs();
  const LocalBaResult ba =
      LocalBundleAdjustment(camera_, ba_window_, options_.local_ba, pixel_sigma_px_);
  FrameStats& stats = result->stats;
  stats.ms_ba = NowMs() - t0;
  stats.ba_points = ba.points;
  stats.ba_observations = ba.observations;
  stats.ba_outliers = ba.outliers;
  stats.ba_rms_px = ba.final_rms_px;
  if (!ba.ok) {
    result->message = "local BA not applied: " + ba.message;
    return;
  }
  stats.local_ba = true;
  const size_t n = ba_window_.size();
  for (size_t k = 0; k < n; ++k) ba_window_[k].T_world_camera = ba.T_world_camera[k];
  T_world_camera_ = ba.T_world_camera[n - 1];
  const Eigen::Isometry3d T_i_j = ba.T_world_camera[n - 2].inverse() * ba.T_world_camera[n - 1];
  // Without the window's covariance (rank deficient), the chained one.
  const Eigen::Matrix<double, 6, 6> cov =
      ba.covariance_ok
          ? Eigen::Matrix<double, 6, 6>(options_.refine.covariance_scale * ba.covariance_last)
          : cov_chain;
  KeyframeFactor f = stages::MakeKeyframeFactor(calibration_.T_base_camera, T_i_j, cov);
  f.utime_i = factor->utime_i;
  f.utime_j = factor->utime_j;
  f.keyframe_id_i = factor->keyframe_id_i;
  f.keyframe_id_j = factor->keyframe_id_j;
  *factor = f;
}

}  // namespace fl::vo
