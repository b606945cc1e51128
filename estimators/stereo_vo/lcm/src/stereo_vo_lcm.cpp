#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <opencv2/imgproc.hpp>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/status_t.hpp"

namespace fl::vo {

fl::Status ImageToGray(const bot_core::image_t& image, cv::Mat* gray) {
  const int kGray = bot_core::image_t::PIXEL_FORMAT_GRAY;
  const int kRgb = bot_core::image_t::PIXEL_FORMAT_RGB;
  const int kBgr = bot_core::image_t::PIXEL_FORMAT_BGR;
  const int fmt = image.pixelformat;
  int channels = 0;
  if (fmt == kGray) channels = 1;
  if (fmt == kRgb || fmt == kBgr) channels = 3;
  if (channels == 0) {
    return fl::Status::Error("unsupported pixel format " + std::to_string(fmt) +
                             "; send 8-bit GRAY, RGB or BGR (decompress MJPEG/PNG first)");
  }
  if (image.width <= 0 || image.height <= 0) {
    return fl::Status::Error("image size " + std::to_string(image.width) + "x" +
                             std::to_string(image.height) + " is empty");
  }
  const int64_t min_stride = static_cast<int64_t>(image.width) * channels;
  if (image.row_stride < min_stride) {
    return fl::Status::Error("row_stride " + std::to_string(image.row_stride) +
                             " is shorter than width x channels = " + std::to_string(min_stride));
  }
  const int64_t needed = static_cast<int64_t>(image.row_stride) * (image.height - 1) + min_stride;
  if (image.size != static_cast<int32_t>(image.data.size()) || image.size < needed) {
    return fl::Status::Error("image data has " + std::to_string(image.data.size()) +
                             " bytes, need " + std::to_string(needed) + " for " +
                             std::to_string(image.width) + "x" + std::to_string(image.height));
  }
  const cv::Mat view(image.height, image.width, channels == 1 ? CV_8UC1 : CV_8UC3,
                     const_cast<uint8_t*>(image.data.data()),
                     static_cast<size_t>(image.row_stride));
  if (channels == 1) {
    view.copyTo(*gray);
  } else {
    cv::cvtColor(view, *gray, fmt == kRgb ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
  }
  return fl::Status::Ok();
}

fl::Status StereoImagesToGray(const bot_core::images_t& images, cv::Mat* left, cv::Mat* right) {
  const int16_t kLeft = bot_core::images_t::LEFT;
  const int16_t kRight = bot_core::images_t::RIGHT;
  int il = -1, ir = -1;
  const int n = std::min<int>(
      images.n_images, static_cast<int>(std::min(images.images.size(), images.image_types.size())));
  for (int i = 0; i < n; ++i) {
    if (images.image_types[static_cast<size_t>(i)] == kLeft && il < 0) il = i;
    if (images.image_types[static_cast<size_t>(i)] == kRight && ir < 0) ir = i;
  }
  if (il < 0 || ir < 0) {
    return fl::Status::Error("stereo message has no " + std::string(il < 0 ? "LEFT" : "RIGHT") +
                             " image (image_types must hold LEFT=0 and RIGHT=1)");
  }
  if (auto s = ImageToGray(images.images[static_cast<size_t>(il)], left); !s.ok()) {
    return fl::Status::Error("left image: " + s.message());
  }
  if (auto s = ImageToGray(images.images[static_cast<size_t>(ir)], right); !s.ok()) {
    return fl::Status::Error("right image: " + s.message());
  }
  return fl::Status::Ok();
}

StereoCalibration CalibrationFromLcm(const fusionloc::stereo_calibration_t& msg,
                                     const bot_core::rigid_transform_t& camera_to_base) {
  StereoCalibration c;
  c.fx = msg.fx;
  c.fy = msg.fy;
  c.cx = msg.cx;
  c.cy = msg.cy;
  c.baseline = msg.baseline;
  c.width = msg.width;
  c.height = msg.height;
  c.rectified = msg.rectified;
  c.T_base_camera = fl::TransformFromLcm(camera_to_base);
  return c;
}

bot_core::pose_t PoseToLcm(Utime utime, const Eigen::Isometry3d& T_world_base) {
  bot_core::pose_t p{};
  p.utime = utime;
  fl::IsometryToArrays(T_world_base, p.pos, p.orientation);
  return p;
}

fusionloc::relative_pose_factor_t FactorToLcm(const KeyframeFactor& f) {
  fusionloc::relative_pose_factor_t m{};
  m.utime_i = f.utime_i;
  m.utime_j = f.utime_j;
  fl::IsometryToArrays(f.T_i_j, m.trans, m.quat);
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) m.information[r * 6 + c] = f.information(r, c);
  }
  m.source = fusionloc::relative_pose_factor_t::SOURCE_VISION;
  m.is_loop_closure = false;
  m.keyframe_id_i = f.keyframe_id_i;
  m.keyframe_id_j = f.keyframe_id_j;
  return m;
}

fusionloc::point_cloud_t KeyframePointsToLcm(const StereoVoResult& result) {
  fusionloc::point_cloud_t m;
  m.utime = result.utime;
  m.frame = "camera";
  m.num_points = static_cast<int32_t>(result.keyframe_points.size());
  m.points.resize(result.keyframe_points.size());
  for (size_t i = 0; i < result.keyframe_points.size(); ++i) {
    m.points[i] = {result.keyframe_points[i].x(), result.keyframe_points[i].y(),
                   result.keyframe_points[i].z()};
  }
  m.num_intensities = static_cast<int32_t>(result.keyframe_intensities.size());
  m.intensities = result.keyframe_intensities;
  return m;
}

LaserCloud LaserCloudFromScan(const fusionloc::laser_scan_3d_t& scan,
                              const Eigen::Isometry3d& T_camera_laser, int64_t* non_finite) {
  LaserCloud cloud;
  cloud.utime = scan.utime;
  cloud.T_camera_laser = T_camera_laser;
  const size_t n = std::min({static_cast<size_t>(std::max(scan.num_points, 0)), scan.x.size(),
                             scan.y.size(), scan.z.size()});
  cloud.points.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f p(scan.x[i], scan.y[i], scan.z[i]);
    if (!p.allFinite()) {
      if (non_finite) ++*non_finite;
      continue;
    }
    cloud.points.push_back(p);
  }
  return cloud;
}

bool SameCalibration(const StereoCalibration& a, const StereoCalibration& b) {
  auto close = [](double x, double y) { return std::abs(x - y) <= 1e-9 * (1 + std::abs(x)); };
  return a.width == b.width && a.height == b.height && close(a.fx, b.fx) && close(a.fy, b.fy) &&
         close(a.cx, b.cx) && close(a.cy, b.cy) && close(a.baseline, b.baseline) &&
         a.rectified == b.rectified && a.T_base_camera.isApprox(b.T_base_camera, 1e-9);
}

std::vector<ChannelSpec> StereoVoNode::Inputs() {
  return {{channels::kStereo, "bot_core.images_t",
           "rectified LEFT/RIGHT pair, 8-bit GRAY, RGB or BGR (required)"},
          {channels::kStereoCalibration, "fusionloc.stereo_calibration_t",
           "intrinsics and baseline (required before the first frame)"},
          {channels::kCameraToBase, "bot_core.rigid_transform_t",
           "T_base_camera, the robot description's mounting (required before the first frame)"},
          {channels::kLaser3d, "fusionloc.laser_scan_3d_t",
           "laser-aided mode (laser_depth.enabled, --laser-aided): multi-line scans; the one "
           "nearest each frame in time, received before it, gives features their depth"},
          {channels::kLaser3dToBase, "bot_core.rigid_transform_t",
           "laser-aided mode: T_base_laser3d, the scanner's mounting (without it: plain stereo)"},
          {channels::kOdometry, "fusionloc.wheel_odometry_t",
           "use_odometry_prior: the motion prior of temporal matching and across gaps "
           "(optional; without it, constant velocity)"}};
}

std::vector<ChannelSpec> StereoVoNode::Outputs() {
  return {{channels::kVoPose, "bot_core.pose_t", "T_world_base of every tracked frame"},
          {channels::kVoFactors, "fusionloc.relative_pose_factor_t",
           "keyframe-to-keyframe motion in the base frame, 6x6 information"},
          {channels::kVoPoints, "fusionloc.point_cloud_t", "keyframe 3D points (camera frame)"}};
}

StereoVoNode::StereoVoNode(const StereoVoOptions& options, LcmInterface* lcm,
                           const ChannelMap& channels)
    : options_(options),
      lcm_(lcm),
      ch_stereo_(channels(channels::kStereo)),
      ch_calib_(channels(channels::kStereoCalibration)),
      ch_camera_to_base_(channels(channels::kCameraToBase)),
      ch_pose_(channels(channels::kVoPose)),
      ch_factors_(channels(channels::kVoFactors)),
      ch_points_(channels(channels::kVoPoints)),
      ch_laser_(channels(channels::kLaser3d)),
      ch_laser_to_base_(channels(channels::kLaser3dToBase)),
      ch_odometry_(channels(channels::kOdometry)),
      status_(lcm, kProgram) {
  status_.SetState(fusionloc::status_t::LEVEL_STARTING, "waiting for " + ch_calib_);
  lcm_->Subscribe<fusionloc::stereo_calibration_t>(
      ch_calib_,
      [this](const fusionloc::stereo_calibration_t& m, const std::string&) { OnCalibration(m); });
  lcm_->Subscribe<bot_core::rigid_transform_t>(
      ch_camera_to_base_,
      [this](const bot_core::rigid_transform_t& m, const std::string&) { OnCameraToBase(m); });
  lcm_->Subscribe<bot_core::images_t>(
      ch_stereo_, [this](const bot_core::images_t& m, const std::string&) { OnStereo(m); },
      LcmInterface::Duplicates::kDrop);
  if (options_.use_odometry_prior) {
    lcm_->Subscribe<fusionloc::wheel_odometry_t>(
        ch_odometry_,
        [this](const fusionloc::wheel_odometry_t& m, const std::string&) { OnOdometry(m); },
        LcmInterface::Duplicates::kDrop);
  }
  if (options_.laser_depth.enabled) {
    lcm_->Subscribe<fusionloc::laser_scan_3d_t>(
        ch_laser_,
        [this](const fusionloc::laser_scan_3d_t& m, const std::string&) { OnLaserScan(m); },
        LcmInterface::Duplicates::kDrop);
    lcm_->Subscribe<bot_core::rigid_transform_t>(
        ch_laser_to_base_,
        [this](const bot_core::rigid_transform_t& m, const std::string&) { OnLaserToBase(m); });
  }
}

void StereoVoNode::OnOdometry(const fusionloc::wheel_odometry_t& msg) {
  status_.CountIn(ch_odometry_, msg.utime);
  if (!vo_) return;  // a prior only: nothing to predict before the VO runs
  if (const Status s = vo_->AddOdometry(msg.utime, Pose2(msg.x, msg.y, msg.theta)); !s.ok()) {
    status_.CountDropped(ch_odometry_ + ": " + s.message());
  }
}

void StereoVoNode::OnLaserScan(const fusionloc::laser_scan_3d_t& msg) {
  status_.CountIn(ch_laser_, msg.utime);
  if (msg.utime <= 0) {
    status_.CountDropped(ch_laser_ + ": utime " + std::to_string(msg.utime) +
                         " is not a time stamp (microseconds since 1970)");
    return;
  }
  if (!laser_scans_.empty() && msg.utime <= laser_scans_.front().utime) {
    status_.CountDropped(ch_laser_ + ": scan at " + std::to_string(msg.utime) +
                         " not after the previous one (" +
                         std::to_string(laser_scans_.front().utime) + "); dropped");
    return;
  }
  ++laser_scans_in_;
  laser_scans_.push_front(msg);
  if (laser_scans_.size() > kLaserScansKept) laser_scans_.pop_back();
}

void StereoVoNode::OnLaserToBase(const bot_core::rigid_transform_t& msg) {
  status_.CountIn();
  const Eigen::Isometry3d T = fl::TransformFromLcm(msg);
  const double qn = std::sqrt(msg.quat[0] * msg.quat[0] + msg.quat[1] * msg.quat[1] +
                              msg.quat[2] * msg.quat[2] + msg.quat[3] * msg.quat[3]);
  constexpr double kMaxMountOffsetM = 10.0;
  if (!T.matrix().allFinite() || !(std::abs(qn - 1.0) < 1e-3) ||
      !(T.translation().norm() <= kMaxMountOffsetM)) {
    status_.CountDropped(ch_laser_to_base_ +
                         ": T_base_laser3d is not a rigid transform (quaternion norm " +
                         std::to_string(qn) + ") or more than 10 m away; ignored");
    return;
  }
  if (T_base_laser_ && !T_base_laser_->isApprox(T, 1e-9)) {
    FL_LOG(WARN) << ch_laser_to_base_ << " changed: the new mounting is used from now on";
  }
  T_base_laser_ = T;
}

const LaserCloud* StereoVoNode::LaserFor(Utime utime, std::string* why) {
  if (laser_scans_.empty()) {
    *why = "no " + ch_laser_ + " scan received yet";
    return nullptr;
  }
  if (!T_base_laser_) {
    *why = ch_laser_ + " without its mounting " + ch_laser_to_base_ +
           " (the robot description's T_base_laser3d)";
    return nullptr;
  }
  const fusionloc::laser_scan_3d_t* best = &laser_scans_.front();
  for (const auto& s : laser_scans_) {
    if (std::llabs(s.utime - utime) < std::llabs(best->utime - utime)) best = &s;
  }
  const Eigen::Isometry3d T_camera_laser =
      active_calibration_.T_base_camera.inverse() * *T_base_laser_;
  laser_cloud_ = LaserCloudFromScan(*best, T_camera_laser, &laser_points_non_finite_);
  return &laser_cloud_;
}

StereoVoNode::~StereoVoNode() = default;

void StereoVoNode::OnCalibration(const fusionloc::stereo_calibration_t& msg) {
  status_.CountIn();
  intrinsics_ = msg;
  StartOrRestart();
}

void StereoVoNode::OnCameraToBase(const bot_core::rigid_transform_t& msg) {
  status_.CountIn();
  camera_to_base_ = msg;
  StartOrRestart();
}

void StereoVoNode::StartOrRestart() {
  if (!intrinsics_ || !camera_to_base_) {
    status_.SetState(fusionloc::status_t::LEVEL_STARTING,
                     "waiting for " + (intrinsics_ ? ch_camera_to_base_ : ch_calib_));
    return;
  }
  const StereoCalibration calib = CalibrationFromLcm(*intrinsics_, *camera_to_base_);
  if (vo_ && SameCalibration(calib, active_calibration_)) return;  // periodic repeat
  if (auto s = calib.Validate(); !s.ok()) {
    status_.CountDropped(ch_calib_ + ": " + s.message());
    status_.SetState(fusionloc::status_t::LEVEL_ERROR, ch_calib_ + ": " + s.message());
    FL_LOG(ERROR) << ch_calib_ << ": " << s.message();
    return;  // keep the previous valid calibration, if any
  }
  if (vo_) FL_LOG(WARN) << "calibration changed: restarting VO (new segment)";
  vo_ = std::make_unique<StereoVo>(options_, calib);
  active_calibration_ = calib;
  status_.SetState(fusionloc::status_t::LEVEL_STARTING,
                   "calibration received; waiting for " + ch_stereo_);
  FL_LOG(INFO) << "calibration " << calib.width << "x" << calib.height << " fx " << calib.fx
               << " baseline " << calib.baseline << " m";
}

void StereoVoNode::OnStereo(const bot_core::images_t& msg) {
  status_.CountIn(ch_stereo_, msg.utime);
  if (!vo_) {
    status_.CountDropped("stereo frame before a valid " + ch_calib_ + " and " + ch_camera_to_base_ +
                         " (waiting for the calibration and the mounting)");
    return;
  }
  cv::Mat left, right;
  if (auto s = StereoImagesToGray(msg, &left, &right); !s.ok()) {
    status_.CountDropped(ch_stereo_ + ": " + s.message());
    return;
  }
  const LaserCloud* laser = nullptr;
  std::string laser_why;
  if (options_.laser_depth.enabled) laser = LaserFor(msg.utime, &laser_why);
  const StereoVoResult r = vo_->AddStereoFrame(msg.utime, left, right, laser);
  ++frames_;
  if (options_.laser_depth.enabled) {
    const bool used = r.laser_message.empty() && r.stats.laser_points_in_view > 0;
    ++(used ? laser_frames_ : laser_fallback_frames_);
    if (!used && (r.state == TrackingState::kInitialized || r.state == TrackingState::kTracked)) {
      // Not an error of the frame: the VO ran it on plain stereo; say why once in a while.
      const std::string why = laser_why.empty() ? r.laser_message : laser_why;
      if (laser_fallback_frames_ == 1 || laser_fallback_frames_ % 100 == 0) {
        FL_LOG(WARN) << "frame " << msg.utime << ": laser-aided mode: " << why << " (plain stereo; "
                     << laser_fallback_frames_ << " such frames)";
      }
    }
  }
  status_.AddItemTime(r.stats.ms_total);
  const Utime stamp = lcm_->last_message_utime();
  switch (r.state) {
    case TrackingState::kRejected:
      status_.CountDropped(r.message);
      rejected_warning_.Warn(ch_stereo_ + " frame " + std::to_string(msg.utime) + " " +
                             r.message + "; dropped");
      return;
    case TrackingState::kNotTracked:
      ++not_tracked_;
      status_.SetState(fusionloc::status_t::LEVEL_WARN, r.message);
      FL_LOG(WARN) << "frame " << msg.utime << ": " << r.message;
      break;
    case TrackingState::kInitialized:
    case TrackingState::kTracked:
      ++tracked_;
      if (r.stats.odometry_prior) ++odometry_prior_frames_;
      status_.SetState(fusionloc::status_t::LEVEL_OK, r.message);
      if (r.new_segment) FL_LOG(WARN) << r.message;
      lcm_->Publish(ch_pose_, PoseToLcm(r.utime, r.T_world_base), stamp);
      status_.CountOut();
      if (r.factor) {
        lcm_->Publish(ch_factors_, FactorToLcm(*r.factor), stamp);
        status_.CountOut();
      }
      if (r.is_keyframe) {
        ++keyframes_;
        if (options_.local_ba.enabled && r.factor) {
          ++(r.stats.local_ba ? ba_windows_ : ba_skipped_);
        }
        lcm_->Publish(ch_points_, KeyframePointsToLcm(r), stamp);
        status_.CountOut();
      }
      break;
  }
  status_.Set("frames", static_cast<double>(frames_));
  status_.Set("tracked", static_cast<double>(tracked_));
  status_.Set("not_tracked", static_cast<double>(not_tracked_));
  status_.Set("keyframes", static_cast<double>(keyframes_));
  if (options_.use_odometry_prior) {
    status_.Set("odometry_prior_frames", static_cast<double>(odometry_prior_frames_));
  }
  if (options_.local_ba.enabled) {
    status_.Set("local_ba_windows", static_cast<double>(ba_windows_));
    status_.Set("local_ba_skipped", static_cast<double>(ba_skipped_));
    if (r.stats.local_ba) {
      status_.Set("local_ba_points", r.stats.ba_points);
      status_.Set("local_ba_rms_px", r.stats.ba_rms_px);
      status_.Set("local_ba_ms", r.stats.ms_ba);
    }
  }
  status_.Set("inliers", r.stats.inliers);
  status_.Set("features_left", r.stats.features_left);
  status_.Set("segment", r.segment);
  // Online rectification check (docs/STEREO_VO.md): a large or drifting value means the
  // stereo calibration is off.
  status_.Set("disparity_offset_px", r.stats.disparity_offset_px);
  status_.Set("disparity_offset_sd_px", r.stats.disparity_offset_sd_px);
  if (options_.laser_depth.enabled) {
    status_.Set("laser_scans", static_cast<double>(laser_scans_in_));
    status_.Set("laser_frames", static_cast<double>(laser_frames_));
    status_.Set("laser_fallback_frames", static_cast<double>(laser_fallback_frames_));
    status_.Set("laser_points_non_finite", static_cast<double>(laser_points_non_finite_));
    status_.Set("laser_depth_features", r.stats.laser_depth_cur);
  }
}

std::string StereoVoNode::Summary() const {
  return "frames " + std::to_string(frames_) + ", tracked " + std::to_string(tracked_) +
         ", not tracked " + std::to_string(not_tracked_) + ", keyframes " +
         std::to_string(keyframes_) + ", dropped " + std::to_string(status_.dropped()) +
         (options_.use_odometry_prior
              ? ", predicted by odometry " + std::to_string(odometry_prior_frames_)
              : "") +
         (options_.laser_depth.enabled
              ? ", laser-aided " + std::to_string(laser_frames_) + " (plain stereo " +
                    std::to_string(laser_fallback_frames_) + ")"
              : "");
}

}  // namespace fl::vo
