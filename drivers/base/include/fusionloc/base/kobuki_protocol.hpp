// The Kobuki (TurtleBot 2) serial protocol, after Yujin Robot's "Appendix: Protocol
// Specification" (kobuki_driver documentation). Pure functions and a byte-stream parser; no
// I/O, no LCM.
//
// Packet:  0xAA 0x55 | length (payload bytes, 1 byte) | payload | checksum
//   checksum = XOR of the length byte and every payload byte (the headers are left out), so
//   XOR over length..checksum is 0 for a good packet.
// Payload: sub-payloads  id (1 byte) | length (1 byte) | data (length bytes)
// Numbers are little-endian (least significant byte first).
//
// Feedback (robot -> host, streamed every 20 ms, i.e. 50 Hz):
//   Basic Sensor Data, id 0x01, length 15:
//     timestamp uint16 [ms] (wraps at 65536), bumper u8, wheel drop u8, cliff u8,
//     left encoder uint16 [ticks], right encoder uint16 [ticks] (both wrap at 65536; count up
//     when the wheel turns forward), left PWM s8, right PWM s8, buttons u8, charger u8,
//     battery u8 [0.1 V], over-current flags u8.
//   Other feedback sub-payloads (inertial 0x04, cliff 0x05, current 0x06, ...) are skipped.
// Commands (host -> robot):
//   Base Control, id 0x01, length 4: speed int16 [mm/s], radius int16 [mm].
//     radius 0: pure translation at `speed`;
//     radius 1: pure rotation, `speed` = omega * track / 2 [mm/s] (positive: counter-clockwise);
//     otherwise: an arc of `radius` (positive: centre on the left), `speed` is the speed of
//     the outer wheel: (radius + track/2) * omega for radius > 1, (radius - track/2) * omega
//     for radius < -1.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace fl::base::kobuki {

constexpr uint8_t kHeader0 = 0xAA;
constexpr uint8_t kHeader1 = 0x55;
constexpr int kBaudRate = 115200;          // [baud] 8N1, no flow control
constexpr double kFeedbackPeriodS = 0.02;  // [s] the robot streams feedback at 50 Hz

// Feedback sub-payload ids.
constexpr uint8_t kBasicSensorDataId = 0x01;
constexpr uint8_t kBasicSensorDataLength = 15;
constexpr uint8_t kInertialSensorDataId = 0x04;
// Command sub-payload ids.
constexpr uint8_t kBaseControlId = 0x01;
constexpr uint8_t kBaseControlLength = 4;
constexpr int16_t kRadiusStraight = 0;  // radius meaning "pure translation"
constexpr int16_t kRadiusRotate = 1;    // radius meaning "pure rotation"

struct BasicSensorData {
  uint16_t timestamp_ms = 0;   // [ms] robot clock, wraps at 65536
  uint8_t bumper = 0;          // [-] 0x01 right, 0x02 centre, 0x04 left
  uint8_t wheel_drop = 0;      // [-] 0x01 right, 0x02 left
  uint8_t cliff = 0;           // [-] 0x01 right, 0x02 centre, 0x04 left
  uint16_t left_encoder = 0;   // [ticks] wraps at 65536
  uint16_t right_encoder = 0;  // [ticks] wraps at 65536
  int8_t left_pwm = 0;         // [%] signed
  int8_t right_pwm = 0;        // [%] signed
  uint8_t buttons = 0;         // [-] 0x01 B0, 0x02 B1, 0x04 B2
  uint8_t charger = 0;         // [-] charging state flags
  uint8_t battery = 0;         // [0.1 V] battery voltage
  uint8_t over_current = 0;    // [-] 0x01 left wheel, 0x02 right wheel
};

struct BaseControl {
  int16_t speed_mm_s = 0;  // [mm/s] see the file comment
  int16_t radius_mm = 0;   // [mm] 0 straight, 1 rotate in place, else the arc radius
};

// XOR of `size` bytes.
uint8_t Xor(const uint8_t* data, size_t size);

// A whole packet (headers, length, payload, checksum) around `payload` (at most 255 bytes;
// throws std::invalid_argument if longer or empty).
std::vector<uint8_t> EncodePacket(const std::vector<uint8_t>& payload);

// Sub-payloads (id, length, data).
std::vector<uint8_t> EncodeBasicSensorData(const BasicSensorData& d);
std::vector<uint8_t> EncodeBaseControl(const BaseControl& c);

// One sub-payload found in a payload.
struct SubPayload {
  uint8_t id = 0;
  std::vector<uint8_t> data;
};
// Splits a payload into sub-payloads; std::nullopt if a sub-payload runs past the end (or the
// payload is empty), which the parser counts as malformed.
std::optional<std::vector<SubPayload>> SplitPayload(const std::vector<uint8_t>& payload);

// Decodes Basic Sensor Data / Base Control data (std::nullopt for a wrong length).
std::optional<BasicSensorData> DecodeBasicSensorData(const std::vector<uint8_t>& data);
std::optional<BaseControl> DecodeBaseControl(const std::vector<uint8_t>& data);

// Velocity (v [m/s] forward, omega [rad/s] counter-clockwise) to a Base Control command for a
// base of `track_m` (the Kobuki's is 0.230 m); speeds saturate at the int16 range. A |omega|
// below 1e-4 rad/s is straight; |v| below 1e-4 m/s or an arc of |radius| <= 1 mm is a
// rotation in place.
BaseControl VelocityToBaseControl(double v, double omega, double track_m);

// What the robot does with a Base Control command: wheel speeds [m/s] (the inverse of
// VelocityToBaseControl, used by the emulator).
struct WheelSpeeds {
  double left = 0.0;   // [m/s]
  double right = 0.0;  // [m/s]
};
WheelSpeeds BaseControlToWheelSpeeds(const BaseControl& c, double track_m);

// Forward difference of two wrapping 16-bit counters (encoder ticks or the ms timestamp):
// the signed step in (-32768, 32767] from `previous` to `current`.
int32_t WrapDelta16(uint16_t previous, uint16_t current);

// Turns a byte stream into packets: finds 0xAA 0x55, checks the length and the checksum,
// checks that the sub-payloads add up to the length (a 1-byte XOR passes noise 1 time in
// 256), and resynchronises after noise. A packet that fails is dropped and counted, and the
// search resumes one byte after its header (so a real packet hidden behind a false header is
// not lost).
class PacketParser {
 public:
  // Appends the payloads of the complete good packets in `data` to `payloads`.
  void Feed(const uint8_t* data, size_t size, std::vector<std::vector<uint8_t>>* payloads);

  int64_t packets() const { return packets_; }              // good packets
  int64_t bad_checksums() const { return bad_checksums_; }  // dropped: checksum mismatch
  int64_t bad_lengths() const { return bad_lengths_; }      // dropped: length < 3
  // Dropped: the checksum passed but the sub-payloads do not add up to the length.
  int64_t malformed() const { return malformed_; }
  int64_t skipped_bytes() const { return skipped_bytes_; }  // noise before a header
  size_t buffered() const { return buffer_.size(); }

 private:
  std::vector<uint8_t> buffer_;
  int64_t packets_ = 0, bad_checksums_ = 0, bad_lengths_ = 0, malformed_ = 0, skipped_bytes_ = 0;
};

}  // namespace fl::base::kobuki
