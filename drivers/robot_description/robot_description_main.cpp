// fl-robot-description: publishes where the sensors sit on the robot (config/robot/*.yaml,
// docs/ROBOT.md) on LASER_TO_BASE and CAMERA_TO_BASE. Run it on the robot with the drivers.
#include <memory>

#include "fusionloc/robot_description/robot_description_node.hpp"

int main(int argc, char** argv) {
  using fl::RobotDescriptionNode;
  fl::Program program(RobotDescriptionNode::kProgram,
                      "Publishes a robot description's sensor mountings (T_base_laser, "
                      "T_base_camera) as bot_core.rigid_transform_t, at start and every "
                      "--period-s, for the estimators, the fusion and the logs.");
  std::string robot_path;
  fl::RobotDescriptionNodeOptions options;
  bool no_laser = false, no_camera = false;
  fl::CommandLine& cli = program.cli();
  cli.AddPositional("ROBOT", &robot_path, "robot description, e.g. config/robot/sim.yaml");
  cli.AddFlag("period-s", &options.period_s, "[s] repeat period");
  cli.AddFlag("no-laser", &no_laser, "do not publish LASER_TO_BASE (a robot without a laser)");
  cli.AddFlag("no-camera", &no_camera, "do not publish CAMERA_TO_BASE (a robot without a camera)");
  fl::LcmProcess process(&program, {}, RobotDescriptionNode::Outputs());
  fl::RobotDescription robot;
  cli.AddCheck([&]() -> std::string {
    options.laser = !no_laser;
    options.camera = !no_camera;
    if (const fl::Status s = options.Validate(); !s.ok()) return s.message();
    if (robot_path.empty()) return "";  // --print-config without ROBOT
    try {
      robot = fl::LoadRobotDescription(robot_path);
    } catch (const fl::ConfigError& e) {
      return e.what();
    }
    return "";
  });
  cli.AddEpilog(
      "\nExamples:\n"
      "  fl-robot-description config/robot/sim.yaml\n"
      "  fl-robot-description config/robot/turtlebot2.yaml --no-camera\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
      return std::make_unique<RobotDescriptionNode>(robot, options, lcm, channels);
    });
  });
}
