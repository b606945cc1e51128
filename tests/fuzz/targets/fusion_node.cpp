// Fusion node (fl-fusion): RBPF_POSE, RBPF_FACTORS, VO_FACTORS, ODOMETRY, VO_POINTS and
// CAMERA_TO_BASE messages, decoded and handled by FusionNode (solves inline, no map file).
#include "../fuzz_messages.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/fusion/fusion_lcm.hpp"

int Fuzz_fusion_node(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  auto lcm = fl::MakeLcm("memq://");
  fl::fusion::FusionProcessConfig config;
  fl::fusion::FusionNodeOptions node_options;
  node_options.map_out = "";
  node_options.sync_full_solve = true;
  fl::fusion::FusionNode node(config, node_options, lcm.get(), fl::ChannelMap());
  namespace ch = fl::channels;
  fl::fuzz::FeedMessages(&in, lcm.get(),
                         {ch::kRbpfPose, ch::kRbpfFactors, ch::kVoFactors, ch::kOdometry,
                          ch::kVoPoints, ch::kCameraToBase},
                         &node);
  return 0;
}
