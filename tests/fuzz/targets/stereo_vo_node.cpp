// Stereo VO node (fl-stereo-vo --laser-aided, use_odometry_prior, local_ba with laser points,
// a keyframe every 5 cm so that windows form): STEREO, STEREO_CALIBRATION,
// CAMERA_TO_BASE, LASER_3D, LASER_3D_TO_BASE and ODOMETRY messages, decoded and handled by
// StereoVoNode (image conversion, calibration checks, scans moved into the camera frame, the
// odometry prior, the VO). The laser-aided mode runs the plain path too (every frame without a
// usable scan), and without odometry around a frame the constant-velocity prediction.
#include "../fuzz_messages.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

int Fuzz_stereo_vo_node(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  auto lcm = fl::MakeLcm("memq://");
  fl::vo::StereoVoOptions options;
  options.laser_depth.enabled = true;
  options.use_odometry_prior = true;
  options.local_ba.enabled = true;
  options.local_ba.laser_points = true;
  options.keyframe_translation_m = 0.05;
  fl::vo::StereoVoNode node(options, lcm.get(), fl::ChannelMap());
  namespace ch = fl::channels;
  fl::fuzz::FeedMessages(
      &in, lcm.get(),
      {ch::kStereo, ch::kStereoCalibration, ch::kCameraToBase, ch::kLaser3d, ch::kLaser3dToBase,
       ch::kOdometry},
      &node);
  return 0;
}
