#include "fusionloc/base/kobuki_protocol.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace fl::base::kobuki {
namespace {

void PutU16(std::vector<uint8_t>* out, uint16_t v) {
  out->push_back(static_cast<uint8_t>(v & 0xFF));
  out->push_back(static_cast<uint8_t>(v >> 8));
}
uint16_t GetU16(const uint8_t* p) {
  return static_cast<uint16_t>(p[0] | (static_cast<uint16_t>(p[1]) << 8));
}
int16_t SaturateInt16(double v) {
  const double r = std::round(v);
  return static_cast<int16_t>(std::clamp(r, -32768.0, 32767.0));
}

}  // namespace

uint8_t Xor(const uint8_t* data, size_t size) {
  uint8_t x = 0;
  for (size_t i = 0; i < size; ++i) x ^= data[i];
  return x;
}

std::vector<uint8_t> EncodePacket(const std::vector<uint8_t>& payload) {
  if (payload.empty() || payload.size() > 255) {
    throw std::invalid_argument("Kobuki packet payload of " + std::to_string(payload.size()) +
                                " bytes (must be 1..255)");
  }
  std::vector<uint8_t> p;
  p.reserve(payload.size() + 4);
  p.push_back(kHeader0);
  p.push_back(kHeader1);
  p.push_back(static_cast<uint8_t>(payload.size()));
  p.insert(p.end(), payload.begin(), payload.end());
  p.push_back(Xor(p.data() + 2, p.size() - 2));
  return p;
}

std::vector<uint8_t> EncodeBasicSensorData(const BasicSensorData& d) {
  std::vector<uint8_t> s{kBasicSensorDataId, kBasicSensorDataLength};
  PutU16(&s, d.timestamp_ms);
  s.push_back(d.bumper);
  s.push_back(d.wheel_drop);
  s.push_back(d.cliff);
  PutU16(&s, d.left_encoder);
  PutU16(&s, d.right_encoder);
  s.push_back(static_cast<uint8_t>(d.left_pwm));
  s.push_back(static_cast<uint8_t>(d.right_pwm));
  s.push_back(d.buttons);
  s.push_back(d.charger);
  s.push_back(d.battery);
  s.push_back(d.over_current);
  return s;
}

std::vector<uint8_t> EncodeBaseControl(const BaseControl& c) {
  std::vector<uint8_t> s{kBaseControlId, kBaseControlLength};
  PutU16(&s, static_cast<uint16_t>(c.speed_mm_s));
  PutU16(&s, static_cast<uint16_t>(c.radius_mm));
  return s;
}

std::optional<std::vector<SubPayload>> SplitPayload(const std::vector<uint8_t>& payload) {
  if (payload.empty()) return std::nullopt;
  std::vector<SubPayload> out;
  size_t i = 0;
  while (i < payload.size()) {
    if (i + 2 > payload.size()) return std::nullopt;
    const uint8_t id = payload[i];
    const size_t len = payload[i + 1];
    if (i + 2 + len > payload.size()) return std::nullopt;
    SubPayload s;
    s.id = id;
    s.data.assign(payload.begin() + static_cast<std::ptrdiff_t>(i + 2),
                  payload.begin() + static_cast<std::ptrdiff_t>(i + 2 + len));
    out.push_back(std::move(s));
    i += 2 + len;
  }
  return out;
}

std::optional<BasicSensorData> DecodeBasicSensorData(const std::vector<uint8_t>& data) {
  if (data.size() != kBasicSensorDataLength) return std::nullopt;
  const uint8_t* p = data.data();
  BasicSensorData d;
  d.timestamp_ms = GetU16(p);
  d.bumper = p[2];
  d.wheel_drop = p[3];
  d.cliff = p[4];
  d.left_encoder = GetU16(p + 5);
  d.right_encoder = GetU16(p + 7);
  d.left_pwm = static_cast<int8_t>(p[9]);
  d.right_pwm = static_cast<int8_t>(p[10]);
  d.buttons = p[11];
  d.charger = p[12];
  d.battery = p[13];
  d.over_current = p[14];
  return d;
}

std::optional<BaseControl> DecodeBaseControl(const std::vector<uint8_t>& data) {
  if (data.size() != kBaseControlLength) return std::nullopt;
  BaseControl c;
  c.speed_mm_s = static_cast<int16_t>(GetU16(data.data()));
  c.radius_mm = static_cast<int16_t>(GetU16(data.data() + 2));
  return c;
}

BaseControl VelocityToBaseControl(double v, double omega, double track_m) {
  constexpr double kEpsilon = 1e-4;
  const double half_track_mm = 500.0 * track_m;
  BaseControl c;
  if (std::abs(omega) < kEpsilon) {
    c.radius_mm = kRadiusStraight;
    c.speed_mm_s = SaturateInt16(1000.0 * v);
    return c;
  }
  const double radius_mm = 1000.0 * v / omega;
  if (std::abs(v) < kEpsilon || std::abs(radius_mm) <= 1.0) {
    c.radius_mm = kRadiusRotate;
    c.speed_mm_s = SaturateInt16(half_track_mm * omega);
    return c;
  }
  // An arc: the outer wheel's speed. A radius beyond the int16 range is as good as straight.
  if (std::abs(radius_mm) > 32767.0) {
    c.radius_mm = kRadiusStraight;
    c.speed_mm_s = SaturateInt16(1000.0 * v);
    return c;
  }
  const int16_t r = SaturateInt16(radius_mm);
  // A radius that rounds to 0 or 1 would change meaning: those are |radius| <= 1.5 mm, which
  // the rotation case above already took (|radius| <= 1) or which round to 2 / -1.
  c.radius_mm = (r == kRadiusStraight || r == kRadiusRotate) ? static_cast<int16_t>(2) : r;
  const double rr = c.radius_mm;
  c.speed_mm_s = SaturateInt16((rr > 0 ? rr + half_track_mm : rr - half_track_mm) * omega);
  return c;
}

WheelSpeeds BaseControlToWheelSpeeds(const BaseControl& c, double track_m) {
  const double s = c.speed_mm_s * 1e-3;  // [m/s]
  const double b2 = 0.5 * track_m;
  WheelSpeeds w;
  if (c.radius_mm == kRadiusStraight) {
    w.left = w.right = s;
  } else if (c.radius_mm == kRadiusRotate) {
    w.left = -s;
    w.right = s;
  } else {
    const double r = c.radius_mm * 1e-3;
    const double omega = s / (r > 0 ? r + b2 : r - b2);
    w.left = omega * (r - b2);
    w.right = omega * (r + b2);
  }
  return w;
}

int32_t WrapDelta16(uint16_t previous, uint16_t current) {
  return static_cast<int16_t>(static_cast<uint16_t>(current - previous));
}

void PacketParser::Feed(const uint8_t* data, size_t size,
                        std::vector<std::vector<uint8_t>>* payloads) {
  buffer_.insert(buffer_.end(), data, data + size);
  size_t i = 0;
  while (true) {
    // Find the two header bytes.
    size_t start = i;
    while (start + 1 < buffer_.size() &&
           !(buffer_[start] == kHeader0 && buffer_[start + 1] == kHeader1)) {
      ++start;
    }
    if (start + 1 >= buffer_.size()) {
      // Keep a trailing 0xAA: it may be the start of the next header.
      const size_t keep = (buffer_.size() > i && buffer_.back() == kHeader0) ? 1 : 0;
      skipped_bytes_ += static_cast<int64_t>(buffer_.size() - i - keep);
      i = buffer_.size() - keep;
      break;
    }
    skipped_bytes_ += static_cast<int64_t>(start - i);
    i = start;
    if (i + 3 > buffer_.size()) break;  // need the length byte
    const size_t len = buffer_[i + 2];
    if (len < 3) {  // the specification's minimum payload
      ++bad_lengths_;
      i += 1;
      continue;
    }
    if (i + 3 + len + 1 > buffer_.size()) break;  // wait for the rest
    if (Xor(buffer_.data() + i + 2, len + 2) != 0) {
      ++bad_checksums_;
      i += 1;  // resume right after this (false or corrupted) header
      continue;
    }
    std::vector<uint8_t> payload(buffer_.begin() + static_cast<std::ptrdiff_t>(i + 3),
                                 buffer_.begin() + static_cast<std::ptrdiff_t>(i + 3 + len));
    if (!SplitPayload(payload)) {  // a checksum that passed by chance (1 in 256)
      ++malformed_;
      i += 1;
      continue;
    }
    payloads->push_back(std::move(payload));
    ++packets_;
    i += 3 + len + 1;
  }
  buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(i));
}

}  // namespace fl::base::kobuki
