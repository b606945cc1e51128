#include "fusionloc/stereo_vo/stereo_vo.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

#include "fusionloc/common/geometry.hpp"

namespace fl::vo {
namespace {

double NowMs() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

std::string SizeText(const cv::Mat& m) {
  return std::to_string(m.cols) + "x" + std::to_string(m.rows);
}

// 8-bit gray view or conversion of an 8-bit 1/3/4-channel image; empty if unsupported.
cv::Mat ToGray(const cv::Mat& image) {
  if (image.depth() != CV_8U) return {};
  if (image.channels() == 1) return image;
  cv::Mat gray;
  if (image.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  if (image.channels() == 4) cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  return gray;
}

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
  return fl::Status::Ok();
}

struct StereoVo::Frame {
  Utime utime = 0;
  cv::Mat left, right;         // gray
  std::vector<float> right_x;  // per left feature with a stereo match: right x [px]
  Features fl, fr;
  std::vector<int> stereo;        // left -> right
  std::vector<int64_t> track_id;  // per left feature with a stereo match, else -1
  int stereo_matches = 0;
};

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

// Sub-pixel disparity: the right position of each stereo match by Lucas-Kanade alignment of
// the left patch (at the detected left corner) in the right image. The left corners stay as
// detected: aligning patches across time would be biased by the scale change of forward
// motion (features appear to move too far), which makes the motion too long. Matches whose
// alignment fails, moves more than subpixel_max_shift_px or leaves the row are dropped.
int StereoVo::RefineStereo(Frame* f) const {
  f->right_x.assign(f->stereo.size(), -1.0f);
  const bool subpixel = options_.subpixel_refinement;
  const int half = options_.subpixel_window_px / 2;
  const float max_shift = static_cast<float>(options_.subpixel_max_shift_px);
  int dropped = 0;
  for (size_t i = 0; i < f->stereo.size(); ++i) {
    const int j = f->stereo[i];
    if (j < 0) continue;
    const cv::Point2f pl = f->fl.keypoints[i].pt;
    const cv::Point2f pr = f->fr.keypoints[static_cast<size_t>(j)].pt;
    if (!subpixel) {
      f->right_x[i] = pr.x;
      continue;
    }
    cv::Point2f refined = pr;
    if (!AlignPatch(f->left, pl, f->right, half, &refined) ||
        std::abs(refined.x - pr.x) > max_shift || std::abs(refined.y - pl.y) > 1.0f ||
        !(pl.x - refined.x > 0)) {
      f->stereo[i] = -1;
      ++dropped;
      continue;
    }
    f->right_x[i] = refined.x;
  }
  return dropped;
}

StereoVoResult StereoVo::AddStereoFrame(Utime utime, const cv::Mat& left_in,
                                        const cv::Mat& right_in) {
  const double t_start = NowMs();
  StereoVoResult result;
  result.utime = utime;
  result.segment = segment_;
  const Eigen::Isometry3d T_camera_base = calibration_.T_base_camera.inverse();
  auto fill_pose = [&]() {
    result.pose_valid = initialized_;
    result.T_world_camera = T_world_camera_;
    result.T_world_base = T_world_camera_ * T_camera_base;
    result.stats.disparity_offset_px = offset_px_;
    result.stats.disparity_offset_sd_px = std::sqrt(offset_var_px2_);
    result.stats.ms_total = NowMs() - t_start;
  };
  auto reject = [&](TrackingState state, const std::string& why) {
    result.state = state;
    result.message = (state == TrackingState::kRejected ? "rejected: " : "not tracked: ") + why;
    fill_pose();
    return result;
  };

  // ---- input checks ----
  if (left_in.empty() || right_in.empty()) {
    return reject(TrackingState::kRejected,
                  std::string(left_in.empty() ? "left" : "right") + " image is empty");
  }
  if (left_in.size() != right_in.size() || left_in.cols != calibration_.width ||
      left_in.rows != calibration_.height) {
    return reject(TrackingState::kRejected,
                  "image sizes left " + SizeText(left_in) + ", right " + SizeText(right_in) +
                      " do not match the calibration " + std::to_string(calibration_.width) + "x" +
                      std::to_string(calibration_.height) +
                      "; publish the rectified images the calibration was made for");
  }
  const cv::Mat left = ToGray(left_in), right = ToGray(right_in);
  if (left.empty() || right.empty()) {
    return reject(TrackingState::kRejected,
                  "unsupported pixel type (need 8-bit gray, BGR or BGRA)");
  }
  if (last_utime_ >= 0 && utime <= last_utime_) {
    return reject(TrackingState::kRejected,
                  "time stamp " + std::to_string(utime) + " us is not after the previous " +
                      std::to_string(last_utime_) + " us (repeated or out of order)");
  }
  last_utime_ = utime;

  // ---- image quality ----
  const double mean_l = cv::mean(left)[0], mean_r = cv::mean(right)[0];
  if (std::min(mean_l, mean_r) < options_.min_mean_intensity) {
    return reject(TrackingState::kNotTracked,
                  "black frame (mean gray " +
                      std::to_string(static_cast<int>(std::min(mean_l, mean_r))) + ")");
  }
  if (std::max(mean_l, mean_r) > options_.max_mean_intensity) {
    return reject(TrackingState::kNotTracked,
                  "saturated frame (mean gray " +
                      std::to_string(static_cast<int>(std::max(mean_l, mean_r))) + ")");
  }

  // ---- features and stereo matching ----
  auto cur = std::make_unique<Frame>();
  cur->utime = utime;
  cur->left = left;
  cur->right = right;
  double t0 = NowMs();
  extractor_.Extract(left, &cur->fl);
  extractor_.Extract(right, &cur->fr);
  result.stats.ms_features = NowMs() - t0;
  result.stats.features_left = cur->fl.size();
  result.stats.features_right = cur->fr.size();
  if (std::min(cur->fl.size(), cur->fr.size()) < options_.min_features) {
    return reject(TrackingState::kNotTracked,
                  "low texture (" + std::to_string(std::min(cur->fl.size(), cur->fr.size())) +
                      " corners, need " + std::to_string(options_.min_features) + ")");
  }
  t0 = NowMs();
  cur->stereo = MatchStereo(cur->fl, cur->fr, options_.matching);
  result.stats.subpixel_dropped = RefineStereo(cur.get());
  cur->track_id.assign(cur->stereo.size(), -1);
  for (int j : cur->stereo) cur->stereo_matches += j >= 0 ? 1 : 0;
  result.stats.stereo_matches = cur->stereo_matches;
  result.stats.ms_matching = NowMs() - t0;
  if (cur->stereo_matches < options_.min_quads) {
    return reject(TrackingState::kNotTracked,
                  "too few stereo matches (" + std::to_string(cur->stereo_matches) + ")");
  }

  auto make_keyframe = [&](Frame* f) {
    result.is_keyframe = true;
    result.keyframe_id = next_keyframe_id_;
    keyframe_id_ = next_keyframe_id_++;
    keyframe_utime_ = f->utime;
    T_kf_camera_.setIdentity();
    cov_kf_camera_.setZero();
    keyframe_max_track_id_ = next_track_id_ - 1;
    keyframe_tracks_ = f->stereo_matches;
    result.keyframe_points.reserve(static_cast<size_t>(f->stereo_matches));
    result.keyframe_intensities.reserve(static_cast<size_t>(f->stereo_matches));
    for (int i = 0; i < f->fl.size(); ++i) {
      const int j = f->stereo[static_cast<size_t>(i)];
      if (j < 0) continue;
      const cv::Point2f pl = f->fl.keypoints[static_cast<size_t>(i)].pt;
      const double d =
          pl.x - CorrectRightX(camera_, f->right_x[static_cast<size_t>(i)], offset_px_);
      if (!(d > 0)) continue;
      result.keyframe_points.push_back(camera_.Triangulate(pl.x, pl.y, d).cast<float>());
      result.keyframe_intensities.push_back(f->left.at<uint8_t>(cvRound(pl.y), cvRound(pl.x)) /
                                            255.0f);
    }
  };
  auto assign_new_tracks = [&](Frame* f) {
    for (size_t i = 0; i < f->stereo.size(); ++i) {
      if (f->stereo[i] >= 0 && f->track_id[i] < 0) f->track_id[i] = next_track_id_++;
    }
  };

  // ---- first frame, or the first after a gap too long to bridge ----
  const bool gap_too_long =
      last_good_ && static_cast<double>(utime - last_good_->utime) * 1e-6 > options_.max_gap_s;
  if (!last_good_ || gap_too_long) {
    if (gap_too_long) {
      ++segment_;
      result.new_segment = true;
      result.segment = segment_;
      result.message =
          "initialized a new segment: " + std::to_string((utime - last_good_->utime) * 1e-6) +
          " s since the last tracked frame (max_gap_s " + std::to_string(options_.max_gap_s) +
          "); the motion across the gap is unknown and no factor links it";
    } else {
      result.message = "initialized";
    }
    initialized_ = true;
    velocity_dt_s_ = 0;
    assign_new_tracks(cur.get());
    make_keyframe(cur.get());
    result.state = TrackingState::kInitialized;
    last_good_ = std::move(cur);
    fill_pose();
    return result;
  }

  // ---- temporal matching and quadrilaterals against the last good frame ----
  Frame& prev = *last_good_;
  const double dt_s = static_cast<double>(utime - prev.utime) * 1e-6;
  t0 = NowMs();
  const bool can_predict =
      velocity_dt_s_ > 0 && dt_s / velocity_dt_s_ > 0.75 && dt_s / velocity_dt_s_ < 1.33;
  std::vector<Quad> quads;
  QuadStats qstats;
  std::vector<StereoCorrespondence> corr;
  std::vector<int> corr_quad;  // correspondence -> quad index
  RansacResult ransac;
  std::vector<Quad> best_quads;
  std::vector<StereoCorrespondence> best_corr;
  std::vector<int> best_corr_quad;
  QuadStats best_stats;
  // Attempt 0: constant-velocity prediction (narrow windows). Attempt 1: the global image
  // shift (median flow of a wide search on a subset, which captures fast turns), then narrow
  // windows around the shifted positions; without enough wide matches, wide windows.
  for (int attempt = can_predict ? 0 : 1; attempt < 2; ++attempt) {
    const bool predict = attempt == 0;
    std::vector<cv::Point2f> pred_l(static_cast<size_t>(prev.fl.size()), cv::Point2f(-1, -1));
    std::vector<cv::Point2f> pred_r(static_cast<size_t>(prev.fr.size()), cv::Point2f(-1, -1));
    double radius = options_.matching.window_px;
    cv::Point2f shift(0, 0);
    if (!predict) {
      std::vector<cv::Point2f> probe(static_cast<size_t>(prev.fl.size()), cv::Point2f(-1, -1));
      const int step = std::max(1, prev.stereo_matches / 200);
      int n = 0;
      for (int i = 0; i < prev.fl.size(); ++i) {
        if (prev.stereo[static_cast<size_t>(i)] >= 0 && n++ % step == 0) {
          probe[static_cast<size_t>(i)] = prev.fl.keypoints[static_cast<size_t>(i)].pt;
        }
      }
      const std::vector<int> wide = MatchTemporal(
          prev.fl, cur->fl, probe, options_.matching.window_unpredicted_px, options_.matching);
      std::vector<float> dx, dy;
      for (size_t i = 0; i < wide.size(); ++i) {
        if (wide[i] < 0) continue;
        dx.push_back(cur->fl.keypoints[static_cast<size_t>(wide[i])].pt.x - probe[i].x);
        dy.push_back(cur->fl.keypoints[static_cast<size_t>(wide[i])].pt.y - probe[i].y);
      }
      if (dx.size() >= 8) {
        std::nth_element(dx.begin(), dx.begin() + static_cast<long>(dx.size() / 2), dx.end());
        std::nth_element(dy.begin(), dy.begin() + static_cast<long>(dy.size() / 2), dy.end());
        shift = cv::Point2f(dx[dx.size() / 2], dy[dy.size() / 2]);
        // Translation makes the flow non-uniform: allow for it around the global shift.
        radius =
            std::min(options_.matching.window_unpredicted_px, 3.0 * options_.matching.window_px);
      } else {
        radius = options_.matching.window_unpredicted_px;
      }
    }
    const Eigen::Isometry3d T_b_a = T_prev_velocity_.inverse();
    for (int i = 0; i < prev.fl.size(); ++i) {
      const int j = prev.stereo[static_cast<size_t>(i)];
      if (j < 0) continue;
      const cv::Point2f pl = prev.fl.keypoints[static_cast<size_t>(i)].pt;
      const cv::Point2f pr = prev.fr.keypoints[static_cast<size_t>(j)].pt;
      if (!predict) {
        pred_l[static_cast<size_t>(i)] = pl + shift;
        pred_r[static_cast<size_t>(j)] = pr + shift;
        continue;
      }
      Eigen::Vector3d uvu;
      if (!camera_.Project(T_b_a * camera_.Triangulate(pl.x, pl.y, pl.x - pr.x), &uvu)) continue;
      pred_l[static_cast<size_t>(i)] =
          cv::Point2f(static_cast<float>(uvu(0)), static_cast<float>(uvu(1)));
      pred_r[static_cast<size_t>(j)] =
          cv::Point2f(static_cast<float>(uvu(2)), static_cast<float>(uvu(1)));
    }
    const std::vector<int> tl = MatchTemporal(prev.fl, cur->fl, pred_l, radius, options_.matching);
    const std::vector<int> tr = MatchTemporal(prev.fr, cur->fr, pred_r, radius, options_.matching);
    quads = CloseQuadrilaterals(prev.fl, prev.fr, cur->fl, cur->fr, prev.stereo, cur->stereo, tl,
                                tr, options_.matching, &qstats);
    // Correspondences (left corners as detected, right x sub-pixel, see RefineStereo) and the
    // RANSAC motion; a failed attempt (e.g. consistent but wrong matches on repetitive
    // texture under a bad prediction) falls through to the global-shift search.
    corr.clear();
    corr_quad.clear();
    for (size_t k = 0; k < quads.size(); ++k) {
      const cv::Point2f la = prev.fl.keypoints[static_cast<size_t>(quads[k].left_a)].pt;
      const cv::Point2f lb = cur->fl.keypoints[static_cast<size_t>(quads[k].left_b)].pt;
      // Right x corrected by the disparity offset estimate (yaw of the right camera).
      const double ra_x =
          CorrectRightX(camera_, prev.right_x[static_cast<size_t>(quads[k].left_a)], offset_px_);
      const double rb_x =
          CorrectRightX(camera_, cur->right_x[static_cast<size_t>(quads[k].left_b)], offset_px_);
      const double da = la.x - ra_x, db = lb.x - rb_x;
      if (!(da > 0 && db > 0)) continue;
      StereoCorrespondence c;
      // Rectified pair: the left row is the point's row (the right one was aligned to it).
      c.obs_a = Eigen::Vector3d(la.x, la.y, ra_x);
      c.obs_b = Eigen::Vector3d(lb.x, lb.y, rb_x);
      c.p_a = camera_.Triangulate(la.x, la.y, da);
      c.p_b = camera_.Triangulate(lb.x, lb.y, db);
      corr.push_back(c);
      corr_quad.push_back(static_cast<int>(k));
    }
    if (static_cast<int>(corr.size()) < options_.min_quads) continue;
    RansacResult r = RansacMotion(camera_, corr, options_.ransac);
    // Keep the attempt with the most inliers; stop early when this one is clearly good.
    if (r.ok && (!ransac.ok || r.inliers.size() > ransac.inliers.size())) {
      ransac = std::move(r);
      best_quads = quads;
      best_corr = corr;
      best_corr_quad = corr_quad;
      best_stats = qstats;
    }
    if (ransac.ok && static_cast<int>(ransac.inliers.size()) >= 2 * options_.min_quads) break;
  }
  if (ransac.ok) {
    quads.swap(best_quads);
    corr.swap(best_corr);
    corr_quad.swap(best_corr_quad);
    qstats = best_stats;
  }
  result.stats.quads = qstats;
  result.stats.ms_matching += NowMs() - t0;
  if (static_cast<int>(corr.size()) < options_.min_quads) {
    return reject(TrackingState::kNotTracked,
                  "only " + std::to_string(corr.size()) + " closed quadrilaterals (need " +
                      std::to_string(options_.min_quads) + ") against the frame " +
                      std::to_string(dt_s) + " s earlier");
  }

  // ---- motion: RANSAC + SVD (above), then refinement ----
  t0 = NowMs();
  result.stats.ransac_iterations = ransac.iterations;
  result.stats.ransac_inliers = static_cast<int>(ransac.inliers.size());
  if (!ransac.ok) {
    result.stats.ms_motion = NowMs() - t0;
    return reject(TrackingState::kNotTracked,
                  "RANSAC found no consistent motion (" + std::to_string(ransac.inliers.size()) +
                      " inliers of " + std::to_string(corr.size()) + ")");
  }
  Eigen::Isometry3d T_a_b = ransac.T_a_b;
  std::vector<int> inliers = ransac.inliers;
  Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Identity() * 1e-2;
  // Disparity offset prior: the filter's prediction (random walk since its last update). The
  // prior's variance is halved because every frame's observations enter two frame pairs.
  constexpr double kReuse = 0.5;
  double offset_pred_var = offset_var_px2_;
  if (offset_utime_ >= 0) {
    offset_pred_var += options_.disparity_offset_drift_px * options_.disparity_offset_drift_px *
                       static_cast<double>(utime - offset_utime_) * 1e-6;
  }
  OffsetPrior offset_prior;
  offset_prior.variance_px2 = kReuse * offset_pred_var;
  offset_prior.sigma_px = pixel_sigma_px_;
  RefineResult offset_result;
  if (options_.use_refinement) {
    for (int round = 0; round < options_.refine_rounds; ++round) {
      const RefineResult refined =
          RefineMotion(camera_, corr, inliers, T_a_b, options_.refine, nullptr,
                       options_.estimate_disparity_offset ? &offset_prior : nullptr);
      offset_result = refined;
      if (!refined.ok) {
        result.stats.ms_motion = NowMs() - t0;
        return reject(TrackingState::kNotTracked, "motion refinement failed (degenerate geometry)");
      }
      T_a_b = refined.T_a_b;
      cov = refined.covariance;
      result.stats.reprojection_rms_px = refined.rms_px;
      if (round + 1 == options_.refine_rounds) break;
      // Re-select inliers with the refined motion, both directions.
      std::vector<int> next;
      const Eigen::Isometry3d T_b_a = T_a_b.inverse();
      Eigen::Vector3d fwd, bwd;
      for (int i = 0; i < static_cast<int>(corr.size()); ++i) {
        const StereoCorrespondence& c = corr[static_cast<size_t>(i)];
        if (!camera_.Project(T_b_a * c.p_a, &fwd) || !camera_.Project(T_a_b * c.p_b, &bwd)) {
          continue;
        }
        const double e =
            std::max((fwd - c.obs_b).cwiseAbs().maxCoeff(), (bwd - c.obs_a).cwiseAbs().maxCoeff());
        if (e <= options_.ransac.inlier_threshold_px) next.push_back(i);
      }
      if (static_cast<int>(next.size()) < options_.ransac.min_inliers) break;
      inliers.swap(next);
    }
  }
  result.stats.inliers = static_cast<int>(inliers.size());
  result.stats.ms_motion = NowMs() - t0;
  const double speed = T_a_b.translation().norm() / std::max(dt_s, 1e-6);
  if (speed > options_.max_speed_mps) {
    return reject(TrackingState::kNotTracked, "implausible motion " + std::to_string(speed) +
                                                  " m/s (max_speed_mps " +
                                                  std::to_string(options_.max_speed_mps) + ")");
  }

  // ---- accept: disparity offset filter, pose chain, tracks, keyframes ----
  if (offset_result.ok) {
    pixel_sigma_px_ = std::clamp(offset_result.sigma_px, 0.1, 2.0);
  }
  if (offset_result.ok && offset_result.offset_estimated) {
    // Kalman update with the data's information counted kReuse times (see above).
    offset_px_ += offset_result.offset_px;
    offset_var_px2_ =
        1.0 / (1.0 / offset_pred_var + kReuse * offset_result.offset_data_information);
    offset_utime_ = utime;
    if (std::abs(offset_px_) > options_.disparity_offset_max_px) {
      result.message = "disparity offset estimate " + std::to_string(offset_px_) +
                       " px exceeds disparity_offset_max_px " +
                       std::to_string(options_.disparity_offset_max_px) +
                       ": reset to the initial value; check the stereo calibration";
      offset_px_ = options_.disparity_offset_initial_px;
      offset_var_px2_ =
          options_.disparity_offset_initial_sd_px * options_.disparity_offset_initial_sd_px;
    }
  }
  T_world_camera_ = T_world_camera_ * T_a_b;
  T_prev_velocity_ = T_a_b;
  velocity_dt_s_ = dt_s;
  result.T_prev_camera = T_a_b;
  int tracked_from_keyframe = 0;
  for (int k : inliers) {
    const Quad& q = quads[static_cast<size_t>(corr_quad[static_cast<size_t>(k)])];
    const int64_t id = prev.track_id[static_cast<size_t>(q.left_a)];
    cur->track_id[static_cast<size_t>(q.left_b)] = id;
    if (id >= 0 && id <= keyframe_max_track_id_) ++tracked_from_keyframe;
  }
  assign_new_tracks(cur.get());
  cov_kf_camera_ = ComposeCovariance(cov_kf_camera_, T_a_b, cov);
  T_kf_camera_ = T_kf_camera_ * T_a_b;
  const double overlap =
      keyframe_tracks_ > 0 ? static_cast<double>(tracked_from_keyframe) / keyframe_tracks_ : 0.0;
  const double kf_rot_deg = fl::RotationAngle(T_kf_camera_.linear()) * 180.0 / M_PI;
  const bool new_keyframe =
      T_kf_camera_.translation().norm() >= options_.keyframe_translation_m ||
      kf_rot_deg >= options_.keyframe_rotation_deg || overlap < options_.keyframe_min_overlap ||
      static_cast<double>(utime - keyframe_utime_) * 1e-6 >= options_.keyframe_max_interval_s;
  if (new_keyframe) {
    KeyframeFactor f;
    f.utime_i = keyframe_utime_;
    f.utime_j = utime;
    f.keyframe_id_i = keyframe_id_;
    const Eigen::Isometry3d& T_bc = calibration_.T_base_camera;
    f.T_i_j = T_bc * T_kf_camera_ * T_bc.inverse();
    f.covariance = ChangeFrameCovariance(cov_kf_camera_, T_bc);
    f.covariance = 0.5 * (f.covariance + f.covariance.transpose());
    Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(f.covariance);
    f.information = ldlt.solve(Eigen::Matrix<double, 6, 6>::Identity());
    f.information = 0.5 * (f.information + f.information.transpose());
    make_keyframe(cur.get());
    f.keyframe_id_j = keyframe_id_;
    if (f.information.allFinite()) result.factor = f;
  }
  result.state = TrackingState::kTracked;
  std::ostringstream msg;
  msg << "tracked: " << result.stats.inliers << "/" << corr.size() << " inliers, rms "
      << result.stats.reprojection_rms_px << " px";
  if (!result.message.empty()) msg << "; " << result.message;
  result.message = msg.str();
  last_good_ = std::move(cur);
  fill_pose();
  return result;
}

}  // namespace fl::vo
