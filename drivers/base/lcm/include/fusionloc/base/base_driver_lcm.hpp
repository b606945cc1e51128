// fl-base-driver's LCM adapter (target fl_base_lcm; the core library fl_base has no LCM).
//   in:  BASE_COMMAND (fusionloc.base_command_t: v [m/s], omega [rad/s])
//   out: ODOMETRY (fusionloc.wheel_odometry_t, 50 Hz), STATUS_FL_BASE_DRIVER (status_t)
#pragma once

#include <string>
#include <vector>

#include "fusionloc/base/base_driver.hpp"
#include "fusionloc/base_command_t.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::base {

fusionloc::wheel_odometry_t OdometryToLcm(const OdometrySample& s);

class BaseDriverNode {
 public:
  static constexpr const char* kProgram = "fl-base-driver";
  static std::vector<ChannelSpec> Inputs();
  static std::vector<ChannelSpec> Outputs();

  // Opens the port (throws fl::serial::SerialError naming the device and the fix).
  BaseDriverNode(const BaseDriverOptions& options, const BaseGeometry& geometry, LcmInterface* lcm,
                 const ChannelMap& channels);

  // One turn of the loop: reads the serial port for up to `timeout_ms`, publishes odometry,
  // handles LCM, updates and ticks the status.
  void Step(int timeout_ms);
  // Steps until shutdown is requested (SIGINT/SIGTERM); returns the exit code (0).
  int Run();

  const BaseDriver& driver() const { return driver_; }
  StatusReporter& status() { return status_; }
  int64_t published() const { return published_; }

 private:
  void OnCommand(const fusionloc::base_command_t& msg);
  void UpdateStatus();

  LcmInterface* lcm_;
  std::string ch_command_, ch_odometry_;
  BaseDriver driver_;
  StatusReporter status_;
  int64_t published_ = 0, commands_ = 0;
};

}  // namespace fl::base
