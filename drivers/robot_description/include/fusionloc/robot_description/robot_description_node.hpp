// RobotDescriptionNode: publishes the mountings of a robot description (config/robot/*.yaml)
// as bot_core.rigid_transform_t on LASER_TO_BASE and CAMERA_TO_BASE, at start and every
// period_s, so that an estimator started later, lcm-logger and lcm-spy all get them (LCM has no
// latched topics: libbot2's and ROS 1's answer for static transforms is the same repeat).
#pragma once

#include <string>
#include <vector>

#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/robot_description.hpp"

namespace fl {

struct RobotDescriptionNodeOptions {
  double period_s = 1.0;  // [s] repeat period
  bool laser = true;      // publish LASER_TO_BASE
  bool camera = true;     // publish CAMERA_TO_BASE
  Status Validate() const;
};

class RobotDescriptionNode : public LcmNode {
 public:
  static constexpr const char* kProgram = "fl-robot-description";
  static std::vector<ChannelSpec> Outputs();

  RobotDescriptionNode(const RobotDescription& robot, const RobotDescriptionNodeOptions& options,
                       LcmInterface* lcm, const ChannelMap& channels);
  StatusReporter& status() override { return status_; }
  std::vector<std::string> RequiredInputs() const override { return {}; }
  void Poll() override;
  std::string Summary() const override;

 private:
  void Publish();

  RobotDescription robot_;
  RobotDescriptionNodeOptions options_;
  LcmInterface* lcm_;
  std::string ch_laser_, ch_camera_;
  StatusReporter status_;
  Utime last_ = 0;
  int64_t published_ = 0;
};

}  // namespace fl
