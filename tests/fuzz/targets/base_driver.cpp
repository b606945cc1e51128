// The wheel-base driver (fl-base-driver) end to end: BASE_COMMAND messages over memq and the
// Kobuki's byte stream on a pty, in any interleaving. Records [selector][length u16 LE][bytes]:
// an even selector publishes the bytes on BASE_COMMAND (an LCM message), an odd one writes
// them to the serial line; the node steps after each (commands, feedback decode, odometry,
// status), and what it published stays decodable with finite odometry.
#include <cmath>

#include "../fuzz_entry.hpp"
#include "fusionloc/base/base_driver_lcm.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/serial/pty.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

int Fuzz_base_driver(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  fl::serial::Pty pty;
  fl::base::BaseDriverOptions options;
  options.port = pty.slave_path();
  fl::BaseGeometry geometry;
  geometry.wheel_radius_m = 0.035;
  geometry.track_m = 0.23;
  geometry.ticks_per_revolution = 2578.33;
  auto lcm = fl::MakeLcm("memq://");
  int64_t odometry = 0;
  lcm->Subscribe<fusionloc::wheel_odometry_t>(
      fl::channels::kOdometry, [&](const fusionloc::wheel_odometry_t& m, const std::string&) {
        FL_FUZZ_CHECK(std::isfinite(m.x) && std::isfinite(m.y) && std::isfinite(m.theta));
        ++odometry;
      });
  fl::base::BaseDriverNode node(options, geometry, lcm.get(), fl::ChannelMap());
  uint8_t sink[4096];
  fl::Utime utime = 1000000;
  while (!in.empty()) {
    const bool serial = in.Byte() & 1;
    const std::string_view bytes = in.Bytes(in.U16());
    if (serial) {
      pty.Write(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
    } else {
      lcm->PublishRaw(fl::channels::kBaseCommand, bytes.data(), static_cast<int>(bytes.size()),
                      utime += 20000);
    }
    node.Step(0);
    while (pty.Read(sink, sizeof(sink), 0) > 0) {  // what the driver sent the base
    }
  }
  node.Step(0);
  FL_FUZZ_CHECK(odometry <= node.published());
  return 0;
}
