// KITTI pose parser (fl-kitti2lcm's ground truth, fl-eval's KITTI poses): parses or throws
// std::runtime_error; every pose read has a rotation.
#include <cmath>
#include <stdexcept>

#include "../fuzz_entry.hpp"
#include "fusionloc/importers/kitti.hpp"

int Fuzz_kitti_poses(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  try {
    const auto poses = fl::importers::ParseKittiPoses(
        std::string(reinterpret_cast<const char*>(data), size), "poses.txt");
    for (const auto& T : poses) {
      FL_FUZZ_CHECK(std::abs(T.linear().determinant() - 1.0) < 1e-6);
      FL_FUZZ_CHECK(T.matrix().allFinite());
    }
  } catch (const std::runtime_error&) {
  }
  return 0;
}
