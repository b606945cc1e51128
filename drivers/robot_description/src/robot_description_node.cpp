#include "fusionloc/robot_description/robot_description_node.hpp"

#include <cmath>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/status_t.hpp"

namespace fl {

Status RobotDescriptionNodeOptions::Validate() const {
  if (!(period_s > 0.0 && period_s <= 3600.0)) {
    return Status::Error("--period-s must be in (0, 3600]");
  }
  if (!laser && !camera)
    return Status::Error("nothing to publish: both --no-laser and --no-camera");
  return Status::Ok();
}

std::vector<ChannelSpec> RobotDescriptionNode::Outputs() {
  return {{channels::kLaserToBase, "bot_core.rigid_transform_t", "T_base_laser, every --period-s"},
          {channels::kCameraToBase, "bot_core.rigid_transform_t",
           "T_base_camera (left camera, optical frame), every --period-s"}};
}

RobotDescriptionNode::RobotDescriptionNode(const RobotDescription& robot,
                                           const RobotDescriptionNodeOptions& options,
                                           LcmInterface* lcm, const ChannelMap& channels)
    : robot_(robot),
      options_(options),
      lcm_(lcm),
      ch_laser_(channels(channels::kLaserToBase)),
      ch_camera_(channels(channels::kCameraToBase)),
      status_(lcm, kProgram) {
  status_.SetState(fusionloc::status_t::LEVEL_OK, "publishing robot '" + robot_.name + "'");
  Publish();
}

void RobotDescriptionNode::Publish() {
  const Utime now = lcm_->Now();
  if (options_.laser) {
    lcm_->Publish(ch_laser_, TransformToLcm(robot_.laser.T_base_sensor(), now), now);
    status_.CountOut();
  }
  if (options_.camera) {
    lcm_->Publish(ch_camera_, TransformToLcm(robot_.camera.T_base_sensor(), now), now);
    status_.CountOut();
  }
  last_ = now;
  ++published_;
}

void RobotDescriptionNode::Poll() {
  const Utime now = lcm_->Now();
  if (now < last_ || UtimeToSeconds(now - last_) >= options_.period_s) Publish();
}

std::string RobotDescriptionNode::Summary() const {
  return "robot '" + robot_.name + "': published " + std::to_string(published_) + " times";
}

}  // namespace fl
