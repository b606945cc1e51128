#include "fusionloc/urg/urg_lcm.hpp"

#include <stdexcept>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/status_t.hpp"

namespace fl::urg {

bot_core::planar_lidar_t ScanToLcm(const LaserScan& scan) {
  bot_core::planar_lidar_t m;
  m.utime = scan.utime;
  m.nranges = static_cast<int32_t>(scan.ranges.size());
  m.ranges = scan.ranges;
  m.nintensities = 0;
  m.rad0 = scan.rad0;
  m.radstep = scan.radstep;
  return m;
}

std::vector<ChannelSpec> UrgDriverNode::Outputs() {
  return {{channels::kLaser, "bot_core.planar_lidar_t",
           "scans: ranges [m] (0 = no return), host-time stamps of the first beam"}};
}

UrgDriverNode::UrgDriverNode(const UrgDriverOptions& options, LcmInterface* lcm,
                             const ChannelMap& channels)
    : lcm_(lcm), ch_laser_(channels(channels::kLaser)), status_(lcm, kProgram), driver_(options) {
  if (Status s = driver_.Start(); !s.ok()) throw std::runtime_error(s.message());
  const DriverStats st = driver_.stats();
  status_.SetState(fusionloc::status_t::LEVEL_OK, st.sensor + " on " + st.device);
}

UrgDriverNode::~UrgDriverNode() { driver_.Stop(); }

void UrgDriverNode::Poll() {
  for (const LaserScan& scan : driver_.TakeScans()) {
    const bot_core::planar_lidar_t m = ScanToLcm(scan);
    lcm_->Publish(ch_laser_, m);
    status_.CountIn();
    status_.CountOut();
    ++published_;
  }
  const DriverStats st = driver_.stats();
  status_.Set("scans", static_cast<double>(st.scans));
  status_.Set("checksum_errors", static_cast<double>(st.checksum_errors));
  status_.Set("malformed", static_cast<double>(st.malformed));
  status_.Set("reconnects", static_cast<double>(st.reconnects));
  status_.Set("stalls", static_cast<double>(st.stalls));
  status_.Set("device_errors", static_cast<double>(st.device_errors));
  status_.Set("residual_ms", st.residual_ms);
  status_.Set("skew_ppm", st.skew_ppm);
  status_.Set("latency_ms", st.latency_ms);
  status_.Set("connected", st.connected ? 1.0 : 0.0);
  const std::string who = st.sensor + " on " + st.device;
  if (!st.connected) {
    status_.SetState(fusionloc::status_t::LEVEL_ERROR,
                     "disconnected from " + who + ": " + st.last_error + "; reconnecting");
  } else if (!st.last_error.empty() &&
             MonotonicUtime() - st.last_error_utime < 10 * kUtimePerSecond) {
    // A problem in the last 10 s (a dropped scan, a restarted stream): WARN, then OK again.
    status_.SetState(fusionloc::status_t::LEVEL_WARN, who + "; last problem: " + st.last_error);
  } else {
    status_.SetState(fusionloc::status_t::LEVEL_OK, who);
  }
}

void UrgDriverNode::Finish() {
  driver_.Stop();
  Poll();
}

std::string UrgDriverNode::Summary() const {
  const DriverStats st = driver_.stats();
  return "scans " + std::to_string(published_) + ", checksum errors " +
         std::to_string(st.checksum_errors) + ", reconnects " + std::to_string(st.reconnects) +
         ", stalls " + std::to_string(st.stalls);
}

}  // namespace fl::urg
