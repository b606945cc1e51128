#include "fusionloc/base/kobuki_emulator.hpp"

#include <chrono>
#include <cmath>

#include "fusionloc/base/odometry.hpp"

namespace fl::base {

fl::Status KobukiEmulatorOptions::Validate() const {
  BaseGeometry g{wheel_radius_m, track_m, ticks_per_revolution};
  if (auto s = CheckOdometryGeometry(g); !s.ok()) return s;
  if (!(period_s > 0) || period_s > 1) return fl::Status::Error("period_s must be in (0, 1]");
  for (int v : {initial_left_encoder, initial_right_encoder, initial_timestamp_ms}) {
    if (v < 0 || v > 65535) {
      return fl::Status::Error("initial encoder and timestamp values must be in 0..65535");
    }
  }
  if (!(checksum_error_rate >= 0 && checksum_error_rate <= 1) ||
      !(noise_rate >= 0 && noise_rate <= 1)) {
    return fl::Status::Error("checksum_error_rate and noise_rate must be in [0, 1]");
  }
  if (!(dropout_every_s >= 0) || !(dropout_length_s >= 0) ||
      (dropout_every_s > 0 && dropout_length_s >= dropout_every_s)) {
    return fl::Status::Error("dropouts need 0 <= dropout_length_s < dropout_every_s");
  }
  return fl::Status::Ok();
}

SimulatedKobuki::SimulatedKobuki(const KobukiEmulatorOptions& options)
    : options_(options),
      left_ticks_(options.initial_left_encoder),
      right_ticks_(options.initial_right_encoder),
      timestamp_ms_(options.initial_timestamp_ms),
      rng_(static_cast<uint32_t>(options.seed)) {}

void SimulatedKobuki::Receive(const uint8_t* data, size_t size) {
  std::vector<std::vector<uint8_t>> payloads;
  parser_.Feed(data, size, &payloads);
  for (const auto& p : payloads) {
    const auto subs = kobuki::SplitPayload(p);
    if (!subs) continue;
    for (const auto& s : *subs) {
      if (s.id != kobuki::kBaseControlId) continue;
      const auto c = kobuki::DecodeBaseControl(s.data);
      if (!c) continue;
      ++commands_;
      const bool moving = wheels_.left != 0.0 || wheels_.right != 0.0;
      command_ = *c;
      wheels_ = kobuki::BaseControlToWheelSpeeds(*c, options_.track_m);
      if (moving && wheels_.left == 0.0 && wheels_.right == 0.0) last_stop_time_s_ = time_s_;
    }
  }
}

std::vector<uint8_t> SimulatedKobuki::Step(double dt_s) {
  // Constant wheel speeds over the step: an exact arc.
  const double dl = wheels_.left * dt_s, dr = wheels_.right * dt_s;
  const double ds = 0.5 * (dl + dr), dth = (dr - dl) / options_.track_m;
  const double half = 0.5 * dth;
  const double sinc = std::abs(half) < 1e-9 ? 1.0 : std::sin(half) / half;
  pose_ = Pose2(pose_.x + ds * sinc * std::cos(pose_.theta + half),
                pose_.y + ds * sinc * std::sin(pose_.theta + half), WrapAngle(pose_.theta + dth));
  const double ticks_per_m = options_.ticks_per_revolution / (2.0 * M_PI * options_.wheel_radius_m);
  left_ticks_ += dl * ticks_per_m;
  right_ticks_ += dr * ticks_per_m;
  timestamp_ms_ += dt_s * 1000.0;
  time_s_ += dt_s;

  if (options_.dropout_every_s > 0 && time_s_ > options_.dropout_every_s &&
      std::fmod(time_s_, options_.dropout_every_s) < options_.dropout_length_s) {
    ++dropped_;
    return {};
  }
  auto wrap16 = [](double v) {
    const double f = std::floor(v);
    return static_cast<uint16_t>(static_cast<int64_t>(f) & 0xFFFF);
  };
  kobuki::BasicSensorData d;
  d.timestamp_ms = wrap16(timestamp_ms_);
  d.left_encoder = wrap16(left_ticks_);
  d.right_encoder = wrap16(right_ticks_);
  d.battery = 165;  // 16.5 V
  std::vector<uint8_t> payload = kobuki::EncodeBasicSensorData(d);
  // An inertial sub-payload too (the driver skips it), as the real feedback packet holds
  // several: angle [0.01 deg], angle rate [0.01 deg/s], 3 unused bytes.
  const int16_t angle = static_cast<int16_t>(std::lround(pose_.theta * 18000.0 / M_PI));
  payload.insert(payload.end(),
                 {kobuki::kInertialSensorDataId, 7, static_cast<uint8_t>(angle & 0xFF),
                  static_cast<uint8_t>((angle >> 8) & 0xFF), 0, 0, 0, 0, 0});
  std::vector<uint8_t> bytes = kobuki::EncodePacket(payload);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  if (options_.checksum_error_rate > 0 && u(rng_) < options_.checksum_error_rate) {
    bytes.back() ^= static_cast<uint8_t>(1 + rng_() % 255);
    ++corrupted_;
  }
  if (options_.noise_rate > 0 && u(rng_) < options_.noise_rate) {
    // Noise, with a false header in it now and then.
    const int n = 1 + static_cast<int>(rng_() % 24);
    for (int i = 0; i < n; ++i) bytes.push_back(static_cast<uint8_t>(rng_() & 0xFF));
    if (rng_() % 2) bytes.insert(bytes.end(), {kobuki::kHeader0, kobuki::kHeader1});
  }
  ++packets_sent_;
  return bytes;
}

KobukiEmulator::KobukiEmulator(const KobukiEmulatorOptions& options)
    : kobuki_(options), period_s_(options.period_s) {
  thread_ = std::thread([this] { Loop(); });
}

KobukiEmulator::~KobukiEmulator() {
  stop_ = true;
  thread_.join();
}

void KobukiEmulator::Loop() {
  using Clock = std::chrono::steady_clock;
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_s_));
  auto next = Clock::now() + period;
  uint8_t buf[256];
  while (!stop_) {
    // Read commands until the next feedback instant.
    while (!stop_) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(next - Clock::now());
      if (left.count() <= 0) break;
      const size_t n = pty_.Read(buf, sizeof buf, static_cast<int>(left.count()));
      if (n > 0) {
        std::lock_guard<std::mutex> lock(mutex_);
        kobuki_.Receive(buf, n);
      }
    }
    std::vector<uint8_t> out;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      out = kobuki_.Step(period_s_);
    }
    if (!out.empty()) pty_.Write(out.data(), out.size());
    next += period;
  }
}

Pose2 KobukiEmulator::pose() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kobuki_.pose();
}
kobuki::WheelSpeeds KobukiEmulator::wheels() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kobuki_.wheels();
}
double KobukiEmulator::time_s() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kobuki_.time_s();
}
int64_t KobukiEmulator::commands() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kobuki_.commands();
}
int64_t KobukiEmulator::packets_sent() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kobuki_.packets_sent();
}
int64_t KobukiEmulator::corrupted() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kobuki_.corrupted();
}

double KobukiEmulator::last_stop_time_s() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kobuki_.last_stop_time_s();
}

}  // namespace fl::base
