// An emulated Kobuki: a differential base that moves on the Base Control commands it receives
// and streams Basic Sensor Data every 20 ms with wrapping 16-bit encoders and clock, with
// injected faults (bad checksums, noise between packets, dropouts).
//
// SimulatedKobuki is the device itself, stepped by the caller (deterministic, for tests);
// KobukiEmulator runs one on a pseudo-terminal in real time (fl-base-emulator, the driver
// tests).
#pragma once

#include <atomic>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

#include "fusionloc/base/kobuki_protocol.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/robot_description.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/serial/pty.hpp"

namespace fl::base {

struct KobukiEmulatorOptions {
  double wheel_radius_m = 0.035;          // [m] the Kobuki's (overridden by --robot)
  double track_m = 0.230;                 // [m]
  double ticks_per_revolution = 2578.33;  // [ticks] 52 ticks x 6545/132 gearing
  double period_s = 0.02;                 // [s] feedback period (the Kobuki's 50 Hz)
  // Start values near the wrap, so that every run crosses it.
  int initial_left_encoder = 65000;  // [ticks] 0..65535
  int initial_right_encoder = 300;   // [ticks] 0..65535
  int initial_timestamp_ms = 64000;  // [ms] 0..65535
  double checksum_error_rate = 0.0;  // [-] fraction of packets sent with a wrong checksum
  double noise_rate = 0.0;           // [-] fraction of packets followed by noise bytes
  double dropout_every_s = 0.0;      // [s] a feedback dropout starts this often (0: never)
  double dropout_length_s = 0.0;     // [s] length of each dropout (motion goes on)
  int seed = 1;                      // random seed of the fault injection

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("wheel_radius_m", &wheel_radius_m);
    a->Visit("track_m", &track_m);
    a->Visit("ticks_per_revolution", &ticks_per_revolution);
    a->Visit("period_s", &period_s);
    a->Visit("initial_left_encoder", &initial_left_encoder);
    a->Visit("initial_right_encoder", &initial_right_encoder);
    a->Visit("initial_timestamp_ms", &initial_timestamp_ms);
    a->Visit("checksum_error_rate", &checksum_error_rate);
    a->Visit("noise_rate", &noise_rate);
    a->Visit("dropout_every_s", &dropout_every_s);
    a->Visit("dropout_length_s", &dropout_length_s);
    a->Visit("seed", &seed);
  }
  fl::Status Validate() const;
};

class SimulatedKobuki {
 public:
  explicit SimulatedKobuki(const KobukiEmulatorOptions& options);

  // Bytes from the driver (Base Control commands; other commands are ignored).
  void Receive(const uint8_t* data, size_t size);
  // Advances the motion by `dt_s` with the current wheel speeds; returns the feedback bytes
  // for this instant (empty during a dropout).
  std::vector<uint8_t> Step(double dt_s);

  const Pose2& pose() const { return pose_; }  // true pose in the start frame
  kobuki::WheelSpeeds wheels() const { return wheels_; }
  kobuki::BaseControl last_command() const { return command_; }
  double time_s() const { return time_s_; }
  int64_t commands() const { return commands_; }
  int64_t packets_sent() const { return packets_sent_; }
  int64_t corrupted() const { return corrupted_; }
  int64_t dropped() const { return dropped_; }
  // [s] time_s() when a command last stopped moving wheels (0 if never).
  double last_stop_time_s() const { return last_stop_time_s_; }

 private:
  KobukiEmulatorOptions options_;
  kobuki::PacketParser parser_;
  Pose2 pose_;
  kobuki::WheelSpeeds wheels_;
  kobuki::BaseControl command_;
  double time_s_ = 0.0;
  double left_ticks_, right_ticks_;  // [ticks] continuous counts
  double timestamp_ms_;
  std::mt19937 rng_;
  int64_t commands_ = 0, packets_sent_ = 0, corrupted_ = 0, dropped_ = 0;
  double last_stop_time_s_ = 0.0;
};

// A SimulatedKobuki on a pseudo-terminal, in real time on its own thread.
class KobukiEmulator {
 public:
  explicit KobukiEmulator(const KobukiEmulatorOptions& options);  // starts streaming
  ~KobukiEmulator();
  const std::string& device() const { return pty_.slave_path(); }

  // Thread-safe snapshots.
  Pose2 pose() const;
  kobuki::WheelSpeeds wheels() const;
  double time_s() const;
  int64_t commands() const;
  int64_t packets_sent() const;
  int64_t corrupted() const;
  double last_stop_time_s() const;

 private:
  void Loop();
  fl::serial::Pty pty_;
  mutable std::mutex mutex_;
  SimulatedKobuki kobuki_;
  double period_s_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace fl::base
