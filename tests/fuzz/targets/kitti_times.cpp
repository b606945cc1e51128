// KITTI time parsers (fl-kitti2lcm): times.txt (first byte even) or a raw drive's
// timestamps.txt (odd). Parses or throws std::runtime_error.
#include <stdexcept>

#include "../fuzz_entry.hpp"
#include "fusionloc/importers/kitti.hpp"

int Fuzz_kitti_times(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  const bool odometry = (in.Byte() & 1) == 0;
  const std::string text(in.Rest());
  try {
    const std::vector<fl::Utime> t = odometry
                                         ? fl::importers::ParseKittiTimes(text, "times.txt")
                                         : fl::importers::ParseKittiTimestamps(text, "timestamps.txt");
    FL_FUZZ_CHECK(t.size() <= text.size());
    if (odometry) {
      for (fl::Utime u : t) FL_FUZZ_CHECK(u >= fl::importers::kKittiOdometryEpochUtime);
    }
  } catch (const std::runtime_error&) {
  }
  return 0;
}
