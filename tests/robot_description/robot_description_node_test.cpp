#include "fusionloc/robot_description/robot_description_node.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>
#include <vector>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "test_paths.hpp"

namespace fl {
namespace {

TEST(RobotDescriptionNode, PublishesTheMountingsAtStartAndEveryPeriod) {
  auto lcm = MakeLcm("memq://");
  std::vector<bot_core::rigid_transform_t> laser, camera;
  lcm->Subscribe<bot_core::rigid_transform_t>(
      "LASER_TO_BASE",
      [&](const bot_core::rigid_transform_t& m, const std::string&) { laser.push_back(m); });
  lcm->Subscribe<bot_core::rigid_transform_t>(
      "CAM_MOUNT",
      [&](const bot_core::rigid_transform_t& m, const std::string&) { camera.push_back(m); });
  const RobotDescription robot = LoadRobotDescription(test::SourceDir() + "/config/robot/sim.yaml");
  RobotDescriptionNodeOptions options;
  options.period_s = 0.05;
  ChannelMap channels;
  ASSERT_EQ(channels.Add("CAMERA_TO_BASE=CAM_MOUNT"), "");
  RobotDescriptionNode node(robot, options, lcm.get(), channels);
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  ASSERT_EQ(laser.size(), 1u);
  ASSERT_EQ(camera.size(), 1u);  // renamed channel
  EXPECT_EQ(TransformFromLcm(laser[0]).translation(), Eigen::Vector3d(0.15, 0, 0.3));
  const Eigen::Isometry3d T_base_camera = TransformFromLcm(camera[0]);
  EXPECT_TRUE(T_base_camera.isApprox(robot.camera.T_base_sensor(), 1e-15));
  // Repeats: a subscriber started later gets it within a period.
  for (int i = 0; i < 50 && laser.size() < 3; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    node.Poll();
    while (lcm->HandleSubscriptions(0) > 0) {
    }
  }
  EXPECT_GE(laser.size(), 3u);
  EXPECT_EQ(laser.size(), camera.size());
}

TEST(RobotDescriptionNode, OptionsAreChecked) {
  RobotDescriptionNodeOptions o;
  o.period_s = 0;
  EXPECT_FALSE(o.Validate().ok());
  o = RobotDescriptionNodeOptions();
  o.laser = o.camera = false;
  EXPECT_NE(o.Validate().message().find("nothing to publish"), std::string::npos);
}

}  // namespace
}  // namespace fl
