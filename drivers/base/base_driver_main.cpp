// fl-base-driver: the Kobuki (TurtleBot 2) base over its serial protocol: encoder odometry on
// ODOMETRY, velocity commands from BASE_COMMAND with a watchdog (BaseDriverNode).
#include "fusionloc/base/base_driver_lcm.hpp"
#include "fusionloc/common/program.hpp"

int main(int argc, char** argv) {
  using fl::base::BaseDriverNode;
  fl::Program program(BaseDriverNode::kProgram,
                      "Kobuki base driver: reads Basic Sensor Data (50 Hz) from the serial "
                      "port, publishes wheel odometry from the encoders, and drives the wheels "
                      "from velocity commands, stopping them when commands stop.");
  fl::base::BaseDriverOptions options;
  program.AddOptions(&options, "config/base_driver.yaml");
  std::string robot, port;
  program.cli().AddFlag("robot", &robot,
                        "robot description whose `base:` gives wheel radius, track and ticks "
                        "per revolution (e.g. config/robot/turtlebot2.yaml); required");
  program.cli().AddFlag("port", &port, "serial device, overrides the options' port");
  fl::LcmProcess process(&program, BaseDriverNode::Inputs(), BaseDriverNode::Outputs());
  program.cli().AddEpilog(
      "\nExamples:\n"
      "  fl-base-driver --robot config/robot/turtlebot2.yaml            # /dev/kobuki\n"
      "  fl-base-emulator --link /tmp/kobuki &\n"
      "  fl-base-driver --robot config/robot/turtlebot2.yaml --port /tmp/kobuki\n"
      "Odometry frame: the base frame at the first encoder reading. Permissions and the udev "
      "rule: docs/HARDWARE.md.\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (robot.empty()) {
      throw fl::UsageError("give the robot description: --robot config/robot/turtlebot2.yaml");
    }
    const fl::BaseGeometry geometry = fl::base::LoadBaseGeometry(robot);
    if (!port.empty()) options.port = port;
    auto lcm = process.Open();
    BaseDriverNode node(options, geometry, lcm.get(), process.channels());
    return node.Run();
  });
}
