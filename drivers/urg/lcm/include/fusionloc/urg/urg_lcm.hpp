// fl-urg-driver's LCM adapter (target fl_urg_lcm; the core library fl_urg has no LCM):
// UrgDriverNode runs an UrgDriver and publishes its scans and health.
//   in:  nothing (the sensor)
//   out: LASER (bot_core.planar_lidar_t: ranges [m], 0 = no return; rad0/radstep from PP;
//        utime = host time of the first beam, from the sensor clock through TM + drift filter),
//        STATUS_FL_URG_DRIVER (status_t: model/serial from VV in the message; scans,
//        checksum_errors, malformed, reconnects, stalls, residual_ms, skew_ppm, latency_ms).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "bot_core/planar_lidar_t.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/urg/urg_driver.hpp"

namespace fl::urg {

bot_core::planar_lidar_t ScanToLcm(const LaserScan& scan);

class UrgDriverNode : public LcmNode {
 public:
  static constexpr const char* kProgram = "fl-urg-driver";
  static std::vector<ChannelSpec> Inputs() { return {}; }
  static std::vector<ChannelSpec> Outputs();

  // Connects to the sensor (throws std::runtime_error with the driver's message if the first
  // connection fails: exit code 1).
  UrgDriverNode(const UrgDriverOptions& options, LcmInterface* lcm, const ChannelMap& channels);
  ~UrgDriverNode() override;

  StatusReporter& status() override { return status_; }
  std::vector<std::string> RequiredInputs() const override { return {}; }
  void Poll() override;
  void Finish() override;
  std::string Summary() const override;

 private:
  LcmInterface* lcm_;
  std::string ch_laser_;
  StatusReporter status_;
  UrgDriver driver_;
  int64_t published_ = 0;
};

}  // namespace fl::urg
