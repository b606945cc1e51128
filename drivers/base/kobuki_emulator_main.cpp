// fl-base-emulator: an emulated Kobuki on a pseudo-terminal (KobukiEmulator), for running
// fl-base-driver without the robot.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "fusionloc/base/kobuki_emulator.hpp"
#include "fusionloc/base/odometry.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"

int main(int argc, char** argv) {
  fl::Program program("fl-base-emulator",
                      "Emulated Kobuki base on a pseudo-terminal: moves on the Base Control "
                      "commands it receives and streams Basic Sensor Data at 50 Hz (wrapping "
                      "encoders), with optional checksum errors, noise and dropouts.");
  fl::base::KobukiEmulatorOptions options;
  program.AddOptions(&options, "config/base_emulator.yaml");
  std::string link, robot;
  double duration_s = 0.0;
  program.cli().AddFlag("link", &link,
                        "also make this symlink to the pseudo-terminal (e.g. /tmp/kobuki)");
  program.cli().AddFlag("robot", &robot,
                        "take the wheel radius, track and ticks per revolution from this robot "
                        "description's `base:` (e.g. config/robot/turtlebot2.yaml)");
  program.cli().AddFlag("duration", &duration_s, "[s] stop after this long (0: until Ctrl-C)");
  program.cli().AddEpilog(
      "\nPrints the device to stdout (\"/dev/pts/N\"), then runs until SIGINT/SIGTERM.\n"
      "  fl-base-emulator --link /tmp/kobuki --config faults.yaml  # checksum_error_rate: 0.01\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (!robot.empty()) {
      const fl::BaseGeometry g = fl::base::LoadBaseGeometry(robot);
      options.wheel_radius_m = g.wheel_radius_m;
      options.track_m = g.track_m;
      options.ticks_per_revolution = g.ticks_per_revolution;
    }
    fl::InstallShutdownHandlers();
    fl::base::KobukiEmulator emulator(options);
    if (!link.empty()) {
      std::error_code ec;
      std::filesystem::remove(link, ec);
      std::filesystem::create_symlink(emulator.device(), link, ec);
      if (ec) {
        throw std::runtime_error("cannot make the symlink '" + link + "': " + ec.message());
      }
    }
    std::printf("%s\n", emulator.device().c_str());
    std::fflush(stdout);
    const auto start = std::chrono::steady_clock::now();
    while (!fl::ShutdownRequested()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      if (duration_s > 0 &&
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >=
              duration_s) {
        break;
      }
    }
    const fl::Pose2 p = emulator.pose();
    FL_LOG(INFO) << "pose x " << p.x << " y " << p.y << " theta " << p.theta << "; commands "
                 << emulator.commands() << ", packets " << emulator.packets_sent() << " (corrupted "
                 << emulator.corrupted() << ")";
    if (!link.empty()) {
      std::error_code ec;
      std::filesystem::remove(link, ec);
    }
    return 0;
  });
}
