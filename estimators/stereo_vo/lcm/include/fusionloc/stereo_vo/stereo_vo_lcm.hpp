// The stereo VO's LCM adapter (target fl_stereo_vo_lcm; the core library has no LCM):
// conversions between the library and LCM messages, shared with the benchmarks, and
// StereoVoNode, which fl-stereo-vo and fl-replay run.
//   in:  STEREO (bot_core.images_t LEFT/RIGHT, GRAY/RGB/BGR), STEREO_CALIBRATION,
//        CAMERA_TO_BASE; laser-aided mode (laser_depth.enabled): LASER_3D and its mounting
//        LASER_3D_TO_BASE
//   out: VO_POSE (bot_core.pose_t, T_world_base), VO_FACTORS (relative_pose_factor_t between
//        keyframes, base frame, SOURCE_VISION), VO_POINTS (point_cloud_t per keyframe, frame
//        "camera"), STATUS_FL_STEREO_VO (status_t).
#pragma once

#include <deque>
#include <memory>
#include <optional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "bot_core/images_t.hpp"
#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/laser_scan_3d_t.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/stereo_vo/stereo_vo.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::vo {

// An 8-bit gray cv::Mat from an image_t (GRAY copied; RGB/BGR converted). Errors name the
// problem (unsupported pixel format, data shorter than row_stride * height, ...).
fl::Status ImageToGray(const bot_core::image_t& image, cv::Mat* gray);

// The LEFT and RIGHT images of a stereo images_t as gray.
fl::Status StereoImagesToGray(const bot_core::images_t& images, cv::Mat* left, cv::Mat* right);

// Library calibration from the camera's own calibration and its mounting (CAMERA_TO_BASE, the
// robot description's T_base_camera); no validation: StereoCalibration::Validate does it.
StereoCalibration CalibrationFromLcm(const fusionloc::stereo_calibration_t& msg,
                                     const bot_core::rigid_transform_t& camera_to_base);

bot_core::pose_t PoseToLcm(Utime utime, const Eigen::Isometry3d& T_world_base);
fusionloc::relative_pose_factor_t FactorToLcm(const KeyframeFactor& factor);
fusionloc::point_cloud_t KeyframePointsToLcm(const StereoVoResult& result);

// A LASER_3D scan for the laser-aided mode: its finite points (laser frame) and the extrinsic
// T_camera_laser the VO maps them into the left camera frame with; `non_finite` counts the
// points left out.
LaserCloud LaserCloudFromScan(const fusionloc::laser_scan_3d_t& scan,
                              const Eigen::Isometry3d& T_camera_laser, int64_t* non_finite);

// Same image size, intrinsics, baseline, rectification and mounting (to 1e-9): the periodic
// repeats of STEREO_CALIBRATION do not restart the VO.
bool SameCalibration(const StereoCalibration& a, const StereoCalibration& b);

class StereoVoNode : public LcmNode {
 public:
  static constexpr const char* kProgram = "fl-stereo-vo";
  static std::vector<ChannelSpec> Inputs();
  static std::vector<ChannelSpec> Outputs();

  StereoVoNode(const StereoVoOptions& options, LcmInterface* lcm, const ChannelMap& channels);
  ~StereoVoNode() override;

  StatusReporter& status() override { return status_; }
  std::vector<std::string> RequiredInputs() const override {
    return {ch_stereo_, ch_calib_, ch_camera_to_base_};
  }
  std::string Summary() const override;

 private:
  void OnCalibration(const fusionloc::stereo_calibration_t& msg);
  void OnCameraToBase(const bot_core::rigid_transform_t& msg);
  // Starts the VO once both the intrinsics and the mounting are known; restarts it when either
  // changes (the periodic repeats do not).
  void StartOrRestart();
  void OnStereo(const bot_core::images_t& msg);
  // use_odometry_prior: hands the wheel odometry to the VO as its motion prior.
  void OnOdometry(const fusionloc::wheel_odometry_t& msg);
  // Laser-aided mode: keeps the latest scans (kLaserScansKept) and the scanner's mounting.
  void OnLaserScan(const fusionloc::laser_scan_3d_t& msg);
  void OnLaserToBase(const bot_core::rigid_transform_t& msg);
  // The kept scan nearest in time to `utime`, in the left camera frame; nullptr (and why in
  // *why) when there is none or the mounting is unknown.
  const LaserCloud* LaserFor(Utime utime, std::string* why);

  StereoVoOptions options_;
  LcmInterface* lcm_;
  std::string ch_stereo_, ch_calib_, ch_camera_to_base_, ch_pose_, ch_factors_, ch_points_;
  std::string ch_laser_, ch_laser_to_base_, ch_odometry_;
  std::optional<fusionloc::stereo_calibration_t> intrinsics_;
  std::optional<bot_core::rigid_transform_t> camera_to_base_;
  StatusReporter status_;
  RateLimitedWarning rejected_warning_;  // frames the VO refused (a late frame, a bad image)
  std::unique_ptr<StereoVo> vo_;
  StereoCalibration active_calibration_;
  int64_t frames_ = 0, tracked_ = 0, not_tracked_ = 0, keyframes_ = 0;
  int64_t odometry_prior_frames_ = 0;  // tracked with the wheel odometry's prediction
  int64_t ba_windows_ = 0, ba_skipped_ = 0;  // keyframes adjusted / not adjusted by the local BA
  // Laser-aided mode.
  static constexpr size_t kLaserScansKept = 3;
  std::deque<fusionloc::laser_scan_3d_t> laser_scans_;  // latest first
  std::optional<Eigen::Isometry3d> T_base_laser_;
  LaserCloud laser_cloud_;  // the scan handed to the VO for the current frame
  int64_t laser_scans_in_ = 0, laser_frames_ = 0, laser_fallback_frames_ = 0;
  int64_t laser_points_non_finite_ = 0;
};

}  // namespace fl::vo
