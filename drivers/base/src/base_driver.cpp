#include "fusionloc/base/base_driver.hpp"

#include <algorithm>
#include <cmath>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/number_format.hpp"

namespace fl::base {

fl::Status BaseDriverOptions::Validate() const {
  if (port.empty()) return fl::Status::Error("port is empty (e.g. /dev/kobuki)");
  if (baud <= 0) return fl::Status::Error("baud must be positive (the Kobuki uses 115200)");
  if (!(command_timeout_s > 0)) return fl::Status::Error("command_timeout_s must be > 0");
  if (!(command_rate_hz > 0) || command_rate_hz > 200) {
    return fl::Status::Error("command_rate_hz must be in (0, 200]");
  }
  if (!(feedback_timeout_s > 0)) return fl::Status::Error("feedback_timeout_s must be > 0");
  if (!(reconnect_interval_s > 0)) return fl::Status::Error("reconnect_interval_s must be > 0");
  if (!(max_gap_s > 0)) return fl::Status::Error("max_gap_s must be > 0");
  if (!(max_speed_m_s >= 0) || !(max_omega_rad_s >= 0)) {
    return fl::Status::Error("max_speed_m_s and max_omega_rad_s must be >= 0");
  }
  return fl::Status::Ok();
}

BaseDriver::BaseDriver(const BaseDriverOptions& options, const BaseGeometry& geometry)
    : options_(options),
      geometry_(geometry),
      odometry_(geometry, WheelOdometry::Options{options.max_gap_s}),
      watchdog_(options.command_timeout_s) {
  port_ = std::make_unique<fl::serial::SerialPort>(options_.port, options_.baud);
  stats_.connected = true;
  last_feedback_ = MonotonicUtime();
}

BaseDriver::~BaseDriver() {
  if (!port_) return;
  try {  // leave the wheels stopped
    const std::vector<uint8_t> stop = kobuki::EncodePacket(kobuki::EncodeBaseControl({}));
    port_->Write(stop.data(), stop.size());
  } catch (const std::exception&) {
  }
}

void BaseDriver::Command(Utime now, double v, double omega) {
  const double vc = std::clamp(v, -options_.max_speed_m_s, options_.max_speed_m_s);
  const double wc = std::clamp(omega, -options_.max_omega_rad_s, options_.max_omega_rad_s);
  watchdog_.Command(now, std::isfinite(vc) ? vc : 0.0, std::isfinite(wc) ? wc : 0.0);
}

void BaseDriver::Disconnected(const std::string& why, Utime now) {
  if (port_) FL_LOG(WARN) << why << "; reopening every " << options_.reconnect_interval_s << " s";
  port_.reset();
  stats_.connected = false;
  problem_ = why;
  last_reconnect_try_ = now;
  odometry_.Restart();
}

void BaseDriver::Spin(int timeout_ms, std::vector<OdometrySample>* out) {
  Utime now = MonotonicUtime();
  if (!port_) {
    if (now - last_reconnect_try_ >= SecondsToUtime(options_.reconnect_interval_s)) {
      last_reconnect_try_ = now;
      try {
        port_ = std::make_unique<fl::serial::SerialPort>(options_.port, options_.baud);
        stats_.connected = true;
        ++stats_.reconnects;
        last_feedback_ = now;
        FL_LOG(INFO) << "reconnected to " << options_.port;
        problem_.clear();
      } catch (const fl::serial::SerialError& e) {
        problem_ = e.what();
      }
    }
    if (!port_) {
      struct timespec ts {
        0, static_cast<long>(std::max(timeout_ms, 1)) * 1000000L
      };
      nanosleep(&ts, nullptr);
      return;
    }
  }
  uint8_t buf[512];
  try {
    const size_t n = port_->Read(buf, sizeof buf, timeout_ms);
    std::vector<std::vector<uint8_t>> payloads;
    if (n > 0) parser_.Feed(buf, n, &payloads);
    for (const auto& p : payloads) HandlePayload(p, out);
    now = MonotonicUtime();
    SendCommand(now);
  } catch (const fl::serial::SerialDisconnected& e) {
    Disconnected(e.what(), now);
  } catch (const fl::serial::SerialError& e) {
    Disconnected(e.what(), now);
  }
  stats_.bad_checksums = parser_.bad_checksums();
  stats_.skipped_bytes = parser_.skipped_bytes();
  stats_.malformed = malformed_ + parser_.malformed() + parser_.bad_lengths();
  stats_.watchdog_stops = watchdog_.timeouts();
  stats_.odometry_gaps = odometry_.gaps();
  stats_.feedback_stale = now - last_feedback_ > SecondsToUtime(options_.feedback_timeout_s);
  stats_.not_a_kobuki = stats_.packets == 0 &&
                        parser_.skipped_bytes() + static_cast<int64_t>(parser_.buffered()) >= 256;
}

void BaseDriver::HandlePayload(const std::vector<uint8_t>& payload,
                               std::vector<OdometrySample>* out) {
  const auto subs = kobuki::SplitPayload(payload);
  if (!subs) {
    ++malformed_;
    return;
  }
  for (const auto& s : *subs) {
    if (s.id != kobuki::kBasicSensorDataId) continue;  // other feedback: not used
    const auto d = kobuki::DecodeBasicSensorData(s.data);
    if (!d) {
      ++malformed_;
      continue;
    }
    ++stats_.packets;
    last_feedback_ = MonotonicUtime();
    OdometrySample sample;
    if (odometry_.Update(NowUtime(), *d, &sample)) out->push_back(sample);
  }
}

void BaseDriver::SendCommand(Utime now) {
  const CommandWatchdog::Velocity vel = watchdog_.Current(now);
  const kobuki::BaseControl c = kobuki::VelocityToBaseControl(vel.v, vel.omega, geometry_.track_m);
  const bool changed = c.speed_mm_s != last_sent_.speed_mm_s || c.radius_mm != last_sent_.radius_mm;
  const bool due = now - last_command_sent_ >= SecondsToUtime(1.0 / options_.command_rate_hz);
  if (!changed && !due) return;
  const std::vector<uint8_t> packet = kobuki::EncodePacket(kobuki::EncodeBaseControl(c));
  port_->Write(packet.data(), packet.size());
  ++stats_.commands_sent;
  last_sent_ = c;
  last_command_sent_ = now;
}

}  // namespace fl::base
