#include "fusionloc/stereo_vo/stereo_vo_stages.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "fusionloc/common/geometry.hpp"

namespace fl::vo::stages {
namespace {

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

size_t At(int i) { return static_cast<size_t>(i); }

}  // namespace

std::string CheckImages(const cv::Mat& left_in, const cv::Mat& right_in,
                        const StereoCalibration& calibration, cv::Mat* left, cv::Mat* right) {
  if (left_in.empty() || right_in.empty()) {
    return std::string(left_in.empty() ? "left" : "right") + " image is empty";
  }
  if (left_in.size() != right_in.size() || left_in.cols != calibration.width ||
      left_in.rows != calibration.height) {
    return "image sizes left " + SizeText(left_in) + ", right " + SizeText(right_in) +
           " do not match the calibration " + std::to_string(calibration.width) + "x" +
           std::to_string(calibration.height) +
           "; publish the rectified images the calibration was made for";
  }
  *left = ToGray(left_in);
  *right = ToGray(right_in);
  if (left->empty() || right->empty())
    return "unsupported pixel type (need 8-bit gray, BGR or BGRA)";
  return {};
}

std::string CheckTimeStamp(Utime utime, Utime last_utime) {
  if (last_utime >= 0 && utime <= last_utime) {
    return "time stamp " + std::to_string(utime) + " us is not after the previous " +
           std::to_string(last_utime) + " us (repeated or out of order)";
  }
  return {};
}

std::string CheckExposure(const cv::Mat& left, const cv::Mat& right,
                          const StereoVoOptions& options) {
  const double mean_l = cv::mean(left)[0], mean_r = cv::mean(right)[0];
  if (std::min(mean_l, mean_r) < options.min_mean_intensity) {
    return "black frame (mean gray " + std::to_string(static_cast<int>(std::min(mean_l, mean_r))) +
           ")";
  }
  if (std::max(mean_l, mean_r) > options.max_mean_intensity) {
    return "saturated frame (mean gray " +
           std::to_string(static_cast<int>(std::max(mean_l, mean_r))) + ")";
  }
  return {};
}

void DetectFeatures(FeatureExtractor* extractor, StereoFrame* frame) {
  extractor->Extract(frame->left, &frame->fl);
  extractor->Extract(frame->right, &frame->fr);
}

// The left corners stay as detected: aligning patches across time would be biased by the scale
// change of forward motion (features appear to move too far), which makes the motion too long.
int RefineStereo(const StereoVoOptions& options, StereoFrame* f) {
  f->right_x.assign(f->stereo.size(), -1.0f);
  const bool subpixel = options.subpixel_refinement;
  const int half = options.subpixel_window_px / 2;
  const float max_shift = static_cast<float>(options.subpixel_max_shift_px);
  int dropped = 0;
  for (size_t i = 0; i < f->stereo.size(); ++i) {
    const int j = f->stereo[i];
    if (j < 0) continue;
    const cv::Point2f pl = f->fl.keypoints[i].pt;
    const cv::Point2f pr = f->fr.keypoints[At(j)].pt;
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

int MatchStereoFrame(const StereoVoOptions& options, StereoFrame* frame) {
  frame->stereo = MatchStereo(frame->fl, frame->fr, options.matching);
  const int dropped = RefineStereo(options, frame);
  frame->track_id.assign(frame->stereo.size(), -1);
  frame->stereo_matches = 0;
  for (int j : frame->stereo) frame->stereo_matches += j >= 0 ? 1 : 0;
  return dropped;
}

TemporalPrediction PredictByVelocity(const StereoCamera& camera, const StereoFrame& prev,
                                     const Eigen::Isometry3d& T_prev_cur,
                                     const MatchOptions& options) {
  TemporalPrediction p;
  p.left.assign(At(prev.fl.size()), cv::Point2f(-1, -1));
  p.right.assign(At(prev.fr.size()), cv::Point2f(-1, -1));
  p.radius_px = options.window_px;
  const Eigen::Isometry3d T_b_a = T_prev_cur.inverse();
  for (int i = 0; i < prev.fl.size(); ++i) {
    const int j = prev.stereo[At(i)];
    if (j < 0) continue;
    const cv::Point2f pl = prev.fl.keypoints[At(i)].pt;
    const cv::Point2f pr = prev.fr.keypoints[At(j)].pt;
    Eigen::Vector3d uvu;
    if (!camera.Project(T_b_a * camera.Triangulate(pl.x, pl.y, pl.x - pr.x), &uvu)) continue;
    p.left[At(i)] = cv::Point2f(static_cast<float>(uvu(0)), static_cast<float>(uvu(1)));
    p.right[At(j)] = cv::Point2f(static_cast<float>(uvu(2)), static_cast<float>(uvu(1)));
  }
  return p;
}

GlobalShift EstimateGlobalShift(const StereoFrame& prev, const StereoFrame& cur,
                                const MatchOptions& options) {
  std::vector<cv::Point2f> probe(At(prev.fl.size()), cv::Point2f(-1, -1));
  const int step = std::max(1, prev.stereo_matches / 200);
  int n = 0;
  for (int i = 0; i < prev.fl.size(); ++i) {
    if (prev.stereo[At(i)] >= 0 && n++ % step == 0) probe[At(i)] = prev.fl.keypoints[At(i)].pt;
  }
  const std::vector<int> wide =
      MatchTemporal(prev.fl, cur.fl, probe, options.window_unpredicted_px, options);
  std::vector<float> dx, dy;
  for (size_t i = 0; i < wide.size(); ++i) {
    if (wide[i] < 0) continue;
    dx.push_back(cur.fl.keypoints[At(wide[i])].pt.x - probe[i].x);
    dy.push_back(cur.fl.keypoints[At(wide[i])].pt.y - probe[i].y);
  }
  GlobalShift g;
  if (dx.size() < 8) return g;
  std::nth_element(dx.begin(), dx.begin() + static_cast<long>(dx.size() / 2), dx.end());
  std::nth_element(dy.begin(), dy.begin() + static_cast<long>(dy.size() / 2), dy.end());
  g.found = true;
  g.shift = cv::Point2f(dx[dx.size() / 2], dy[dy.size() / 2]);
  return g;
}

TemporalPrediction PredictByShift(const StereoFrame& prev, const GlobalShift& shift,
                                  const MatchOptions& options) {
  TemporalPrediction p;
  p.left.assign(At(prev.fl.size()), cv::Point2f(-1, -1));
  p.right.assign(At(prev.fr.size()), cv::Point2f(-1, -1));
  // Translation makes the flow non-uniform: allow for it around the global shift.
  p.radius_px = shift.found ? std::min(options.window_unpredicted_px, 3.0 * options.window_px)
                            : options.window_unpredicted_px;
  for (int i = 0; i < prev.fl.size(); ++i) {
    const int j = prev.stereo[At(i)];
    if (j < 0) continue;
    p.left[At(i)] = prev.fl.keypoints[At(i)].pt + shift.shift;
    p.right[At(j)] = prev.fr.keypoints[At(j)].pt + shift.shift;
  }
  return p;
}

TemporalMatches MatchTemporalPair(const StereoFrame& prev, const StereoFrame& cur,
                                  const TemporalPrediction& prediction,
                                  const MatchOptions& options) {
  TemporalMatches m;
  m.left = MatchTemporal(prev.fl, cur.fl, prediction.left, prediction.radius_px, options);
  m.right = MatchTemporal(prev.fr, cur.fr, prediction.right, prediction.radius_px, options);
  return m;
}

QuadMatches CheckQuadrilaterals(const StereoFrame& prev, const StereoFrame& cur,
                                const TemporalMatches& temporal, const MatchOptions& options) {
  QuadMatches q;
  q.quads = CloseQuadrilaterals(prev.fl, prev.fr, cur.fl, cur.fr, prev.stereo, cur.stereo,
                                temporal.left, temporal.right, options, &q.stats);
  return q;
}

// Left corners as detected, right x sub-pixel (see RefineStereo) and corrected by the disparity
// offset estimate (yaw of the right camera).
Correspondences BuildCorrespondences(const StereoCamera& camera, const StereoFrame& prev,
                                     const StereoFrame& cur, const std::vector<Quad>& quads,
                                     double offset_px) {
  Correspondences out;
  for (size_t k = 0; k < quads.size(); ++k) {
    const cv::Point2f la = prev.fl.keypoints[At(quads[k].left_a)].pt;
    const cv::Point2f lb = cur.fl.keypoints[At(quads[k].left_b)].pt;
    const double ra_x = CorrectRightX(camera, prev.right_x[At(quads[k].left_a)], offset_px);
    const double rb_x = CorrectRightX(camera, cur.right_x[At(quads[k].left_b)], offset_px);
    const double da = la.x - ra_x, db = lb.x - rb_x;
    if (!(da > 0 && db > 0)) continue;
    StereoCorrespondence c;
    // Rectified pair: the left row is the point's row (the right one was aligned to it).
    c.obs_a = Eigen::Vector3d(la.x, la.y, ra_x);
    c.obs_b = Eigen::Vector3d(lb.x, lb.y, rb_x);
    c.p_a = camera.Triangulate(la.x, la.y, da);
    c.p_b = camera.Triangulate(lb.x, lb.y, db);
    out.corr.push_back(c);
    out.quad.push_back(static_cast<int>(k));
  }
  return out;
}

bool VelocityPredicts(double dt_s, double velocity_dt_s) {
  return velocity_dt_s > 0 && dt_s / velocity_dt_s > 0.75 && dt_s / velocity_dt_s < 1.33;
}

// A failed attempt (e.g. consistent but wrong matches on repetitive texture under a bad
// prediction) falls through to the global-shift search, which captures fast turns.
FrameMatch SearchMotion(const StereoCamera& camera, const StereoFrame& prev, const StereoFrame& cur,
                        bool predict_velocity, const Eigen::Isometry3d& T_prev_cur,
                        double offset_px, const StereoVoOptions& options) {
  const MatchOptions& mo = options.matching;
  FrameMatch best, last;
  for (int attempt = predict_velocity ? 0 : 1; attempt < 2; ++attempt) {
    const TemporalPrediction prediction =
        attempt == 0 ? PredictByVelocity(camera, prev, T_prev_cur, mo)
                     : PredictByShift(prev, EstimateGlobalShift(prev, cur, mo), mo);
    last = FrameMatch();
    last.attempt = attempt;
    last.quads = CheckQuadrilaterals(prev, cur, MatchTemporalPair(prev, cur, prediction, mo), mo);
    last.corr = BuildCorrespondences(camera, prev, cur, last.quads.quads, offset_px);
    if (static_cast<int>(last.corr.corr.size()) < options.min_quads) continue;
    RansacResult r = RansacMotion(camera, last.corr.corr, options.ransac);
    // Keep the attempt with the most inliers; stop early when this one is clearly good.
    if (r.ok && (!best.ransac.ok || r.inliers.size() > best.ransac.inliers.size())) {
      last.ransac = std::move(r);
      best = last;
    }
    if (best.ransac.ok && static_cast<int>(best.ransac.inliers.size()) >= 2 * options.min_quads) {
      break;
    }
  }
  return best.ransac.ok ? best : last;
}

std::vector<int> SelectInliers(const StereoCamera& camera,
                               const std::vector<StereoCorrespondence>& corr,
                               const Eigen::Isometry3d& T_a_b, double threshold_px) {
  std::vector<int> inliers;
  const Eigen::Isometry3d T_b_a = T_a_b.inverse();
  Eigen::Vector3d fwd, bwd;
  for (int i = 0; i < static_cast<int>(corr.size()); ++i) {
    const StereoCorrespondence& c = corr[At(i)];
    if (!camera.Project(T_b_a * c.p_a, &fwd) || !camera.Project(T_a_b * c.p_b, &bwd)) continue;
    const double e =
        std::max((fwd - c.obs_b).cwiseAbs().maxCoeff(), (bwd - c.obs_a).cwiseAbs().maxCoeff());
    if (e <= threshold_px) inliers.push_back(i);
  }
  return inliers;
}

Refinement RefineStage(const StereoCamera& camera, const std::vector<StereoCorrespondence>& corr,
                       const RansacResult& ransac, const OffsetPrior* offset_prior,
                       const StereoVoOptions& options, const PointMeasurements* measured) {
  Refinement out;
  out.ok = true;
  out.T_a_b = ransac.T_a_b;
  out.inliers = ransac.inliers;
  if (!options.use_refinement) return out;
  for (int round = 0; round < options.refine_rounds; ++round) {
    out.last = RefineMotion(camera, corr, out.inliers, out.T_a_b, options.refine, nullptr,
                            offset_prior, measured);
    if (!out.last.ok) {
      out.ok = false;
      return out;
    }
    out.T_a_b = out.last.T_a_b;
    out.covariance = out.last.covariance;
    out.rms_px = out.last.rms_px;
    if (round + 1 == options.refine_rounds) break;
    // Re-select inliers with the refined motion, both directions.
    std::vector<int> next =
        SelectInliers(camera, corr, out.T_a_b, options.ransac.inlier_threshold_px);
    if (static_cast<int>(next.size()) < options.ransac.min_inliers) break;
    out.inliers.swap(next);
  }
  return out;
}

LaserDepthVerdict LaserPoint(const StereoCamera& camera, const LaserDepthMap& map,
                             const Eigen::Vector3d& obs, double stereo_depth_m,
                             const LaserDepthOptions& options, Eigen::Vector3d* m,
                             Eigen::Matrix3d* W) {
  const FeatureDepth d =
      map.Associate(obs(0), obs(1), stereo_depth_m,
                    StereoDepthSigma(camera, stereo_depth_m, options.stereo_disparity_sigma_px));
  if (d.source != DepthSource::kLaser && d.source != DepthSource::kBoth) {
    return d.verdict == LaserDepthVerdict::kOk ? LaserDepthVerdict::kTooFew : d.verdict;
  }
  const Eigen::Vector3d ray((obs(0) - camera.cx) / camera.fx, (obs(1) - camera.cy) / camera.fy,
                            1.0);
  *m = d.depth_m * ray;
  *W = PointSqrtInformation(ray, d.sigma_m, options.point_lateral_sigma_px * d.depth_m / camera.fx);
  return LaserDepthVerdict::kOk;
}

LaserAssociation AssociateLaserDepth(const StereoCamera& camera, const StereoFrame& prev,
                                     const StereoFrame& cur,
                                     const std::vector<StereoCorrespondence>& corr,
                                     double pixel_sigma_px, const LaserDepthOptions& options) {
  LaserAssociation out;
  out.measured.pixel_sigma_px = pixel_sigma_px;
  out.measured.per_correspondence.resize(corr.size());
  const auto one = [&](const LaserDepthMap* map, const Eigen::Vector3d& obs,
                       const Eigen::Vector3d& p_stereo, bool* has, Eigen::Vector3d* m,
                       Eigen::Matrix3d* W) {
    if (map == nullptr) return;
    const LaserDepthVerdict verdict = LaserPoint(camera, *map, obs, p_stereo.z(), options, m, W);
    *has = verdict == LaserDepthVerdict::kOk;
    if (verdict == LaserDepthVerdict::kInconsistent) ++out.inconsistent;
    if (verdict == LaserDepthVerdict::kStereoDisagrees) ++out.disagrees;
  };
  for (size_t i = 0; i < corr.size(); ++i) {
    PointMeasurement& pm = out.measured.per_correspondence[i];
    one(prev.laser.get(), corr[i].obs_a, corr[i].p_a, &pm.has_a, &pm.m_a, &pm.W_a);
    one(cur.laser.get(), corr[i].obs_b, corr[i].p_b, &pm.has_b, &pm.m_b, &pm.W_b);
    out.prev += pm.has_a;
    out.cur += pm.has_b;
  }
  return out;
}

int PropagateTracks(const StereoFrame& prev, const FrameMatch& match,
                    const std::vector<int>& inliers, int64_t keyframe_max_track_id,
                    StereoFrame* cur) {
  int tracked_from_keyframe = 0;
  for (int k : inliers) {
    const Quad& q = match.quads.quads[At(match.corr.quad[At(k)])];
    const int64_t id = prev.track_id[At(q.left_a)];
    cur->track_id[At(q.left_b)] = id;
    if (id >= 0 && id <= keyframe_max_track_id) ++tracked_from_keyframe;
  }
  return tracked_from_keyframe;
}

void AssignNewTracks(StereoFrame* frame, int64_t* next_track_id) {
  for (size_t i = 0; i < frame->stereo.size(); ++i) {
    if (frame->stereo[i] >= 0 && frame->track_id[i] < 0) frame->track_id[i] = (*next_track_id)++;
  }
}

bool NeedsKeyframe(const Eigen::Isometry3d& T_kf_camera, int tracked_from_keyframe,
                   int keyframe_tracks, Utime since_keyframe_us, const StereoVoOptions& options) {
  const double overlap =
      keyframe_tracks > 0 ? static_cast<double>(tracked_from_keyframe) / keyframe_tracks : 0.0;
  const double kf_rot_deg = fl::RotationAngle(T_kf_camera.linear()) * 180.0 / M_PI;
  return T_kf_camera.translation().norm() >= options.keyframe_translation_m ||
         kf_rot_deg >= options.keyframe_rotation_deg || overlap < options.keyframe_min_overlap ||
         static_cast<double>(since_keyframe_us) * 1e-6 >= options.keyframe_max_interval_s;
}

KeyframeFactor MakeKeyframeFactor(const Eigen::Isometry3d& T_base_camera,
                                  const Eigen::Isometry3d& T_kf_camera,
                                  const Matrix6d& cov_kf_camera) {
  KeyframeFactor f;
  const Eigen::Isometry3d& T_bc = T_base_camera;
  f.T_i_j = T_bc * T_kf_camera * T_bc.inverse();
  f.covariance = ChangeFrameCovariance(cov_kf_camera, T_bc);
  f.covariance = 0.5 * (f.covariance + f.covariance.transpose());
  Eigen::LDLT<Matrix6d> ldlt(f.covariance);
  f.information = ldlt.solve(Matrix6d::Identity());
  f.information = 0.5 * (f.information + f.information.transpose());
  return f;
}

void KeyframePoints(const StereoCamera& camera, const StereoFrame& frame, double offset_px,
                    std::vector<Eigen::Vector3f>* points, std::vector<float>* intensities) {
  points->reserve(At(frame.stereo_matches));
  intensities->reserve(At(frame.stereo_matches));
  for (int i = 0; i < frame.fl.size(); ++i) {
    const int j = frame.stereo[At(i)];
    if (j < 0) continue;
    const cv::Point2f pl = frame.fl.keypoints[At(i)].pt;
    const double d = pl.x - CorrectRightX(camera, frame.right_x[At(i)], offset_px);
    if (!(d > 0)) continue;
    points->push_back(camera.Triangulate(pl.x, pl.y, d).cast<float>());
    intensities->push_back(frame.left.at<uint8_t>(cvRound(pl.y), cvRound(pl.x)) / 255.0f);
  }
}

std::vector<BaObservation> KeyframeObservations(const StereoCamera& camera,
                                                const StereoFrame& frame, double offset_px,
                                                const LaserDepthOptions* laser_options) {
  std::vector<BaObservation> out;
  out.reserve(At(frame.stereo_matches));
  for (int i = 0; i < frame.fl.size(); ++i) {
    if (frame.stereo[At(i)] < 0 || frame.track_id[At(i)] < 0) continue;
    const cv::Point2f pl = frame.fl.keypoints[At(i)].pt;
    BaObservation o;
    o.track_id = frame.track_id[At(i)];
    o.uvu = {pl.x, pl.y, CorrectRightX(camera, frame.right_x[At(i)], offset_px)};
    const double disparity = o.uvu(0) - o.uvu(2);
    if (laser_options != nullptr && frame.laser && disparity > 0) {
      const double z = camera.Triangulate(o.uvu(0), o.uvu(1), disparity).z();
      o.has_point = LaserPoint(camera, *frame.laser, o.uvu, z, *laser_options, &o.m_camera,
                               &o.W_camera) == LaserDepthVerdict::kOk;
    }
    out.push_back(o);
  }
  return out;
}

}  // namespace fl::vo::stages
