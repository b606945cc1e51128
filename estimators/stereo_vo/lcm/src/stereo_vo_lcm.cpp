#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

#include <opencv2/imgproc.hpp>

#include "fusionloc/common/geometry.hpp"

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

StereoCalibration CalibrationFromLcm(const fusionloc::stereo_calibration_t& msg) {
  StereoCalibration c;
  c.fx = msg.fx;
  c.fy = msg.fy;
  c.cx = msg.cx;
  c.cy = msg.cy;
  c.baseline = msg.baseline;
  c.width = msg.width;
  c.height = msg.height;
  c.rectified = msg.rectified;
  c.T_base_camera = fl::IsometryFromArrays(msg.T_base_camera.trans, msg.T_base_camera.quat);
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

}  // namespace fl::vo
