#include "fusionloc/base/base_driver_lcm.hpp"

#include <cmath>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/status_t.hpp"

namespace fl::base {

fusionloc::wheel_odometry_t OdometryToLcm(const OdometrySample& s) {
  fusionloc::wheel_odometry_t m{};
  m.utime = s.utime;
  m.x = s.x;
  m.y = s.y;
  m.theta = s.theta;
  m.v = s.v;
  m.omega = s.omega;
  m.left_ticks = s.left_ticks;
  m.right_ticks = s.right_ticks;
  return m;
}

std::vector<ChannelSpec> BaseDriverNode::Inputs() {
  return {{channels::kBaseCommand, "fusionloc.base_command_t",
           "velocity command v [m/s], omega [rad/s]; none for command_timeout_s stops the "
           "wheels (optional)"}};
}

std::vector<ChannelSpec> BaseDriverNode::Outputs() {
  return {{channels::kOdometry, "fusionloc.wheel_odometry_t",
           "encoder odometry, 50 Hz (the base's feedback rate)"}};
}

BaseDriverNode::BaseDriverNode(const BaseDriverOptions& options, const BaseGeometry& geometry,
                               LcmInterface* lcm, const ChannelMap& channels)
    : lcm_(lcm),
      ch_command_(channels(channels::kBaseCommand)),
      ch_odometry_(channels(channels::kOdometry)),
      driver_(options, geometry),
      status_(lcm, kProgram) {
  status_.SetState(fusionloc::status_t::LEVEL_STARTING, "waiting for feedback on " + options.port);
  lcm_->Subscribe<fusionloc::base_command_t>(
      ch_command_,
      [this](const fusionloc::base_command_t& m, const std::string&) { OnCommand(m); });
  FL_LOG(INFO) << "Kobuki on " << options.port << ": wheel radius " << geometry.wheel_radius_m
               << " m, track " << geometry.track_m << " m, " << geometry.ticks_per_revolution
               << " ticks/rev; watchdog " << options.command_timeout_s << " s";
}

void BaseDriverNode::OnCommand(const fusionloc::base_command_t& msg) {
  status_.CountIn();
  if (!std::isfinite(msg.v) || !std::isfinite(msg.omega)) {
    status_.CountDropped(ch_command_ + ": non-finite v or omega (command ignored)");
    return;
  }
  ++commands_;
  driver_.Command(MonotonicUtime(), msg.v, msg.omega);
}

void BaseDriverNode::Step(int timeout_ms) {
  std::vector<OdometrySample> samples;
  driver_.Spin(timeout_ms, &samples);
  for (const auto& s : samples) {
    lcm_->Publish(ch_odometry_, OdometryToLcm(s), s.utime);
    ++published_;
    status_.CountOut();
  }
  while (lcm_->HandleSubscriptions(0) > 0) {
  }
  UpdateStatus();
  status_.Tick();
}

void BaseDriverNode::UpdateStatus() {
  const BaseDriverStats& st = driver_.stats();
  status_.Set("connected", st.connected ? 1 : 0);
  status_.Set("packets", static_cast<double>(st.packets));
  status_.Set("bad_checksums", static_cast<double>(st.bad_checksums));
  status_.Set("malformed", static_cast<double>(st.malformed));
  status_.Set("skipped_bytes", static_cast<double>(st.skipped_bytes));
  status_.Set("commands_sent", static_cast<double>(st.commands_sent));
  status_.Set("watchdog_stops", static_cast<double>(st.watchdog_stops));
  status_.Set("reconnects", static_cast<double>(st.reconnects));
  status_.Set("odometry_gaps", static_cast<double>(st.odometry_gaps));
  if (!st.connected) {
    status_.SetState(fusionloc::status_t::LEVEL_ERROR, driver_.problem());
  } else if (st.not_a_kobuki) {
    const std::string m = "bytes arrive on " + driver_.options().port +
                          " but none is a Kobuki packet: another device on this port (check "
                          "`ls -l /dev/serial/by-id/`) or a wrong baud rate (the Kobuki's is "
                          "115200)";
    if (status_.message() != m) FL_LOG(ERROR) << m;
    status_.SetState(fusionloc::status_t::LEVEL_ERROR, m);
  } else if (st.feedback_stale) {
    status_.SetState(fusionloc::status_t::LEVEL_WARN,
                     "no feedback from " + driver_.options().port +
                         ": is the Kobuki switched on? (power switch on its side)");
  } else if (st.packets > 0) {
    status_.SetState(fusionloc::status_t::LEVEL_OK, "streaming");
  }
}

int BaseDriverNode::Run() {
  while (!ShutdownRequested()) Step(5);
  status_.Tick(true);
  FL_LOG(INFO) << "odometry " << published_ << ", commands " << commands_ << ", bad checksums "
               << driver_.stats().bad_checksums << ", reconnects " << driver_.stats().reconnects;
  return 0;
}

}  // namespace fl::base
