// Localization node (fl-rbpf-slam --localize): LASER, ODOMETRY, LASER_TO_BASE and INITIAL_POSE
// messages, decoded and handled by LocalizerNode as the process does (conversions,
// synchronisation, initial poses, the Monte Carlo localizer with its global search) on a fixed
// small map: a 4 m x 3 m room with a box.
#include "../fuzz_messages.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/rbpf_slam/localizer_lcm.hpp"

namespace {
fl::rbpf::OccupancyMap Room() {
  fl::rbpf::OccupancyMap m;
  m.resolution = 0.1;
  m.origin_x = -2.0;
  m.origin_y = -1.5;
  m.width = 40;
  m.height = 30;
  m.cells.assign(static_cast<size_t>(m.width * m.height), 0);
  for (int y = 0; y < m.height; ++y) {
    for (int x = 0; x < m.width; ++x) {
      const bool wall = x == 0 || y == 0 || x == m.width - 1 || y == m.height - 1;
      const bool box = x >= 25 && x < 29 && y >= 8 && y < 12;
      if (wall || box) m.cells[static_cast<size_t>(y * m.width + x)] = 100;
    }
  }
  return m;
}
}  // namespace

int Fuzz_localizer_node(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  static const fl::rbpf::OccupancyMap map = Room();
  fl::fuzz::Input in(data, size);
  auto lcm = fl::MakeLcm("memq://");
  fl::rbpf::LocalizerOptions options;  // small and fast; every code path of the node is the same
  options.min_particles = 2;
  options.max_particles = 20;
  options.global_step_m = 0.5;
  options.global_step_rad = 0.5;
  options.global_beams = 8;
  options.global_hypotheses = 10;
  options.lost_updates = 2;
  fl::rbpf::RbpfSlamNodeOptions node_options;
  fl::rbpf::LocalizerNode node(options, node_options, map, "fuzz-room", lcm.get(),
                               fl::ChannelMap());
  namespace ch = fl::channels;
  fl::fuzz::FeedMessages(&in, lcm.get(),
                         {ch::kLaser, ch::kOdometry, ch::kLaserToBase, ch::kInitialPose}, &node);
  return 0;
}
