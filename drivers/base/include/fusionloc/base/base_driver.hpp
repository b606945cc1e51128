// The Kobuki base driver without LCM: the serial link (with reconnects), the packet parser,
// the odometry and the command watchdog. The LCM adapter (fusionloc/base/base_driver_lcm.hpp)
// calls Spin() in its loop and publishes what it returns.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "fusionloc/base/kobuki_protocol.hpp"
#include "fusionloc/base/odometry.hpp"
#include "fusionloc/common/robot_description.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/serial/serial_port.hpp"

namespace fl::base {

struct BaseDriverOptions {
  std::string port = "/dev/kobuki";   // serial device (config/udev/ names the Kobuki /dev/kobuki)
  int baud = 115200;                  // [baud] the Kobuki's rate
  double command_timeout_s = 0.5;     // [s] watchdog: no BASE_COMMAND for this long -> stop
  double command_rate_hz = 20.0;      // [Hz] Base Control resend rate while driving or stopping
  double feedback_timeout_s = 0.5;    // [s] no feedback for this long: a warning in the status
  double reconnect_interval_s = 1.0;  // [s] between attempts to reopen a vanished port
  double max_gap_s = 1.0;             // [s] odometry reference reset after a longer silence
  double max_speed_m_s = 0.7;         // [m/s] commands are clamped to this (Kobuki: 0.7)
  double max_omega_rad_s = 3.14;      // [rad/s] commands are clamped to this (Kobuki: pi)

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("port", &port);
    a->Visit("baud", &baud);
    a->Visit("command_timeout_s", &command_timeout_s);
    a->Visit("command_rate_hz", &command_rate_hz);
    a->Visit("feedback_timeout_s", &feedback_timeout_s);
    a->Visit("reconnect_interval_s", &reconnect_interval_s);
    a->Visit("max_gap_s", &max_gap_s);
    a->Visit("max_speed_m_s", &max_speed_m_s);
    a->Visit("max_omega_rad_s", &max_omega_rad_s);
  }
  fl::Status Validate() const;
};

// Counters for the status message.
struct BaseDriverStats {
  int64_t packets = 0;         // good feedback packets
  int64_t bad_checksums = 0;   // dropped: checksum mismatch
  int64_t malformed = 0;       // dropped: bad length or sub-payloads that do not add up
  int64_t skipped_bytes = 0;   // noise between packets
  int64_t commands_sent = 0;   // Base Control packets written
  int64_t watchdog_stops = 0;  // times the watchdog stopped the wheels
  int64_t reconnects = 0;      // times the port was reopened after vanishing
  int64_t odometry_gaps = 0;   // odometry reference resets after a silence
  bool connected = false;
  bool feedback_stale = false;  // no feedback for feedback_timeout_s
  // Bytes arrive but not one good Kobuki packet among the first 256: another device on this
  // port (or a wrong baud rate).
  bool not_a_kobuki = false;
};

class BaseDriver {
 public:
  // Opens the port: throws fl::serial::SerialError naming the device and the fix.
  BaseDriver(const BaseDriverOptions& options, const BaseGeometry& geometry);
  ~BaseDriver();

  // A velocity command (clamped to the limits) at monotonic time `now`.
  void Command(Utime now, double v, double omega);
  // Reads for up to `timeout_ms`, appends new odometry samples (stamped with wall time) to
  // `out`, and sends the Base Control command when due. `now` is monotonic time. A vanished
  // port is reopened every reconnect_interval_s (counted); it never throws for that.
  void Spin(int timeout_ms, std::vector<OdometrySample>* out);

  const BaseDriverStats& stats() const { return stats_; }
  // The last disconnect/reconnect problem ("" if none).
  const std::string& problem() const { return problem_; }
  const BaseDriverOptions& options() const { return options_; }

 private:
  void HandlePayload(const std::vector<uint8_t>& payload, std::vector<OdometrySample>* out);
  void SendCommand(Utime now);
  void Disconnected(const std::string& why, Utime now);

  BaseDriverOptions options_;
  BaseGeometry geometry_;
  std::unique_ptr<fl::serial::SerialPort> port_;
  kobuki::PacketParser parser_;
  WheelOdometry odometry_;
  CommandWatchdog watchdog_;
  BaseDriverStats stats_;
  std::string problem_;
  int64_t malformed_ = 0;  // Basic Sensor Data of a wrong length
  Utime last_command_sent_ = 0;
  kobuki::BaseControl last_sent_;
  Utime last_feedback_ = 0;
  Utime last_reconnect_try_ = 0;
};

}  // namespace fl::base
