// fl-urg-driver: a Hokuyo URG laser over SCIP 2.0 (UrgDriverNode, urg_lcm.hpp) on the process
// edge (fusionloc/common/lcm_process.hpp).
#include <memory>

#include "fusionloc/urg/urg_lcm.hpp"

int main(int argc, char** argv) {
  using fl::urg::UrgDriverNode;
  fl::Program program(UrgDriverNode::kProgram,
                      "Hokuyo URG laser driver (SCIP 2.0 over USB-ACM or RS-232): publishes "
                      "scans in metres with host-time stamps from the sensor clock (TM sync + "
                      "drift filter); finds a USB Hokuyo itself and reconnects when it is back.");
  fl::urg::UrgDriverOptions options;
  program.AddOptions(&options, "config/urg_driver.yaml");
  std::string port;
  program.cli().AddFlag("port", &port, "serial device, overrides the config's port");
  fl::LcmProcess process(&program, UrgDriverNode::Inputs(), UrgDriverNode::Outputs());
  program.cli().AddEpilog(
      "\nExamples:\n"
      "  fl-urg-driver --config config/urg_driver.yaml            # USB Hokuyo, found by libusb\n"
      "  fl-urg-driver --port /dev/hokuyo                         # the udev rule's link\n"
      "  fl-urg-emulator --link /tmp/hokuyo & fl-urg-driver --port /tmp/hokuyo\n"
      "Ranges: 0 = no return (URG error codes below DMIN, or beyond DMAX). docs/HARDWARE.md has "
      "the udev rule and permissions.\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  if (!port.empty()) options.port = port;
  return program.Run([&] {
    return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
      return std::make_unique<UrgDriverNode>(options, lcm, channels);
    });
  });
}
