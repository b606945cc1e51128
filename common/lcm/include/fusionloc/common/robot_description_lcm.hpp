// The robot description on LCM: a mounting T_base_sensor as bot_core.rigid_transform_t
// (trans = t, quat = R as w, x, y, z), on LASER_TO_BASE / CAMERA_TO_BASE (channels.hpp).
#pragma once

#include <Eigen/Geometry>

#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/time.hpp"

namespace fl {

inline bot_core::rigid_transform_t TransformToLcm(const Eigen::Isometry3d& T_base_sensor,
                                                  Utime utime) {
  bot_core::rigid_transform_t m{};
  m.utime = utime;
  IsometryToArrays(T_base_sensor, m.trans, m.quat);
  return m;
}

inline Eigen::Isometry3d TransformFromLcm(const bot_core::rigid_transform_t& m) {
  return IsometryFromArrays(m.trans, m.quat);
}

}  // namespace fl
