// Conversions between the stereo VO library and LCM messages, shared by the fl-stereo-vo
// process and the stereo benchmark (target fl_stereo_vo_lcm; the core library has no LCM).
#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "bot_core/images_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/stereo_vo/stereo_vo.hpp"

namespace fl::vo {

// An 8-bit gray cv::Mat from an image_t (GRAY copied; RGB/BGR converted). Errors name the
// problem (unsupported pixel format, data shorter than row_stride * height, ...).
fl::Status ImageToGray(const bot_core::image_t& image, cv::Mat* gray);

// The LEFT and RIGHT images of a stereo images_t as gray.
fl::Status StereoImagesToGray(const bot_core::images_t& images, cv::Mat* left, cv::Mat* right);

// Library calibration from the message (no validation: StereoCalibration::Validate does it).
StereoCalibration CalibrationFromLcm(const fusionloc::stereo_calibration_t& msg);

bot_core::pose_t PoseToLcm(Utime utime, const Eigen::Isometry3d& T_world_base);
fusionloc::relative_pose_factor_t FactorToLcm(const KeyframeFactor& factor);
fusionloc::point_cloud_t KeyframePointsToLcm(const StereoVoResult& result);

}  // namespace fl::vo
