// KITTI calibration parser (fl-kitti2lcm): calib_cam_to_cam.txt (first byte even) or
// calib.txt (odd; gray or colour pair by the next bit). Parses or throws
// std::runtime_error; a calibration that parses is a usable rectified pair.
#include <cmath>
#include <stdexcept>

#include "../fuzz_entry.hpp"
#include "fusionloc/importers/kitti.hpp"

int Fuzz_kitti_calib(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  const uint8_t mode = in.Byte();
  const bool raw = (mode & 1) == 0;
  try {
    const fl::importers::KittiCalibration c =
        fl::importers::ParseKittiCalibration(std::string(in.Rest()), "calib.txt", raw, mode & 2);
    FL_FUZZ_CHECK(c.fx > 0 && c.fy > 0 && c.baseline > 0.01);
    FL_FUZZ_CHECK(std::isfinite(c.cx) && std::isfinite(c.cy));
    if (raw) FL_FUZZ_CHECK(c.width > 0 && c.height > 0);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
