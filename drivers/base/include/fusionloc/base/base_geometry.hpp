// The base's geometry from the robot description (config/robot/<robot>.yaml, key `base:`).
//
// TEMPORARY: the same fields as fl::BaseGeometry in fusionloc/common/robot_description.hpp,
// which is landing on main; when it does, this header goes and the driver takes
// fl::LoadRobotDescription(path).base.
#pragma once

#include <string>

#include "fusionloc/common/status.hpp"

namespace fl::base {

struct BaseGeometry {
  double wheel_radius_m = 0.0;        // [m] wheel radius
  double track_m = 0.0;               // [m] distance between the wheels' contact points
  double ticks_per_revolution = 0.0;  // [ticks] encoder ticks per wheel turn; 0 = not described

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("wheel_radius_m", &wheel_radius_m);
    a->Visit("track_m", &track_m);
    a->Visit("ticks_per_revolution", &ticks_per_revolution);
  }
  // All three positive (a base without encoders cannot give odometry).
  fl::Status Validate() const;
  double metres_per_tick() const;
};

// The `base:` section of a robot description file. Throws fl::ConfigError naming the file.
BaseGeometry LoadBaseGeometry(const std::string& robot_path);

}  // namespace fl::base
