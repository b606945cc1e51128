// RBPF-SLAM node (fl-rbpf-slam): LASER, ODOMETRY and LASER_TO_BASE messages, decoded and
// handled by RbpfSlamNode as the process does (conversions, synchronisation, the SLAM).
#include "../fuzz_messages.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"

int Fuzz_rbpf_node(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  auto lcm = fl::MakeLcm("memq://");
  fl::rbpf::RbpfSlamOptions options;
  options.particles = 2; // small and fast; every code path of the node is the same
  fl::rbpf::RbpfSlamNodeOptions node_options;
  fl::rbpf::RbpfSlamNode node(options, node_options, lcm.get(), fl::ChannelMap());
  namespace ch = fl::channels;
  fl::fuzz::FeedMessages(&in, lcm.get(), {ch::kLaser, ch::kOdometry, ch::kLaserToBase}, &node);
  return 0;
}
