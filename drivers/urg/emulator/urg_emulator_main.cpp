// fl-urg-emulator: an emulated Hokuyo URG-04LX on a pseudo-terminal (UrgEmulator), for running
// and testing fl-urg-driver without the sensor.
#include <chrono>
#include <iostream>
#include <thread>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/urg/urg_emulator.hpp"

int main(int argc, char** argv) {
  fl::Program program("fl-urg-emulator",
                      "Emulated Hokuyo URG-04LX (SCIP 2.0) on a pseudo-terminal: prints the "
                      "device path, streams ray-cast scans of a simulator world with Gaussian "
                      "noise, and injects faults (checksum errors, split lines, stalls, the "
                      "device vanishing and coming back). Runs until SIGINT/SIGTERM.");
  fl::urg::UrgEmulatorOptions options;
  program.AddOptions(&options, "config/urg_emulator.yaml");
  std::string link;
  program.cli().AddFlag("link", &link,
                        "symlink to the pty, e.g. /tmp/hokuyo (overrides the config)");
  double duration_s = 0.0;
  program.cli().AddFlag("duration-s", &duration_s, "stop after this long [s] (0: never)");
  program.cli().AddEpilog(
      "\nExample:\n"
      "  fl-urg-emulator --link /tmp/hokuyo &   fl-urg-driver --port /tmp/hokuyo\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  if (!link.empty()) options.link = link;
  return program.Run([&] {
    fl::urg::UrgEmulator emulator(options);
    if (fl::Status s = emulator.Start(); !s.ok()) throw std::runtime_error(s.message());
    std::cout << emulator.device_path() << std::endl;
    FL_LOG(INFO) << "emulated URG-04LX on " << emulator.slave_path()
                 << (options.link.empty() ? "" : " (link " + options.link + ")");
    fl::InstallShutdownHandlers();
    const auto start = std::chrono::steady_clock::now();
    while (!fl::ShutdownRequested()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      if (duration_s > 0 &&
          std::chrono::steady_clock::now() - start > std::chrono::duration<double>(duration_s))
        break;
    }
    emulator.Stop();
    return fl::kExitOk;
  });
}
