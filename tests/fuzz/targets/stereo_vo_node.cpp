// Stereo VO node (fl-stereo-vo): STEREO, STEREO_CALIBRATION and CAMERA_TO_BASE messages,
// decoded and handled by StereoVoNode (image conversion, calibration checks, the VO).
#include "../fuzz_messages.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

int Fuzz_stereo_vo_node(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  auto lcm = fl::MakeLcm("memq://");
  fl::vo::StereoVoOptions options;
  fl::vo::StereoVoNode node(options, lcm.get(), fl::ChannelMap());
  namespace ch = fl::channels;
  fl::fuzz::FeedMessages(&in, lcm.get(), {ch::kStereo, ch::kStereoCalibration, ch::kCameraToBase},
                         &node);
  return 0;
}
