// The Kobuki packet codec and parser: round trips, the XOR checksum on a hand-made packet,
// resynchronisation after noise and false headers, bad checksums dropped and counted, the
// Base Control special radii and the 16-bit wrap.
#include "fusionloc/base/kobuki_protocol.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace fl::base::kobuki {
namespace {

BasicSensorData Sample() {
  BasicSensorData d;
  d.timestamp_ms = 0xFFF0;
  d.bumper = 0x02;
  d.wheel_drop = 0x01;
  d.cliff = 0x04;
  d.left_encoder = 0xFFFE;
  d.right_encoder = 0x0102;
  d.left_pwm = -20;
  d.right_pwm = 35;
  d.buttons = 0x04;
  d.charger = 6;
  d.battery = 161;
  d.over_current = 0x02;
  return d;
}

std::vector<std::vector<uint8_t>> FeedAll(PacketParser* parser, const std::vector<uint8_t>& b) {
  std::vector<std::vector<uint8_t>> out;
  parser->Feed(b.data(), b.size(), &out);
  return out;
}

TEST(KobukiProtocol, BaseControlPacketMatchesTheSpecificationByteForByte) {
  // speed 100 mm/s, radius 0: id 0x01, length 4, LSB first; checksum = XOR of length..data.
  const std::vector<uint8_t> p = EncodePacket(EncodeBaseControl({100, 0}));
  const std::vector<uint8_t> expected{0xAA, 0x55, 0x06, 0x01, 0x04, 0x64, 0x00, 0x00, 0x00, 0x67};
  EXPECT_EQ(p, expected);
  // Negative values are two's complement: -300 mm/s = 0xFED4, radius -1000 = 0xFC18.
  const std::vector<uint8_t> q = EncodePacket(EncodeBaseControl({-300, -1000}));
  EXPECT_EQ(q[5], 0xD4);
  EXPECT_EQ(q[6], 0xFE);
  EXPECT_EQ(q[7], 0x18);
  EXPECT_EQ(q[8], 0xFC);
  EXPECT_EQ(Xor(q.data() + 2, q.size() - 2), 0);
}

TEST(KobukiProtocol, BasicSensorDataRoundTrip) {
  const BasicSensorData d = Sample();
  const std::vector<uint8_t> sub = EncodeBasicSensorData(d);
  ASSERT_EQ(sub.size(), 17u);
  EXPECT_EQ(sub[0], 0x01);
  EXPECT_EQ(sub[1], 15);
  EXPECT_EQ(sub[2], 0xF0);  // timestamp LSB first
  EXPECT_EQ(sub[3], 0xFF);
  const auto subs = SplitPayload(sub);
  ASSERT_TRUE(subs.has_value());
  ASSERT_EQ(subs->size(), 1u);
  const auto back = DecodeBasicSensorData((*subs)[0].data);
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->timestamp_ms, d.timestamp_ms);
  EXPECT_EQ(back->bumper, d.bumper);
  EXPECT_EQ(back->wheel_drop, d.wheel_drop);
  EXPECT_EQ(back->cliff, d.cliff);
  EXPECT_EQ(back->left_encoder, d.left_encoder);
  EXPECT_EQ(back->right_encoder, d.right_encoder);
  EXPECT_EQ(back->left_pwm, d.left_pwm);
  EXPECT_EQ(back->right_pwm, d.right_pwm);
  EXPECT_EQ(back->buttons, d.buttons);
  EXPECT_EQ(back->charger, d.charger);
  EXPECT_EQ(back->battery, d.battery);
  EXPECT_EQ(back->over_current, d.over_current);
  // A wrong length is refused.
  std::vector<uint8_t> shorter((*subs)[0].data.begin(), (*subs)[0].data.end() - 1);
  EXPECT_FALSE(DecodeBasicSensorData(shorter).has_value());
}

TEST(KobukiProtocol, BaseControlRoundTripOverTheInt16Range) {
  for (int16_t speed :
       {int16_t{0}, int16_t{1}, int16_t{-1}, int16_t{700}, int16_t{-32768}, int16_t{32767}}) {
    for (int16_t radius : {int16_t{0}, int16_t{1}, int16_t{-250}, int16_t{32767}}) {
      const auto subs = SplitPayload(EncodeBaseControl({speed, radius}));
      ASSERT_TRUE(subs.has_value());
      const auto c = DecodeBaseControl((*subs)[0].data);
      ASSERT_TRUE(c.has_value());
      EXPECT_EQ(c->speed_mm_s, speed);
      EXPECT_EQ(c->radius_mm, radius);
    }
  }
}

TEST(KobukiProtocol, SplitPayloadRejectsASubPayloadRunningPastTheEnd) {
  std::vector<uint8_t> p = EncodeBasicSensorData(Sample());
  p[1] = 16;  // claims one byte more than there is
  EXPECT_FALSE(SplitPayload(p).has_value());
  EXPECT_FALSE(SplitPayload({}).has_value());
  EXPECT_FALSE(SplitPayload({0x01}).has_value());
  // Two sub-payloads side by side.
  std::vector<uint8_t> two = EncodeBasicSensorData(Sample());
  two.insert(two.end(), {0x04, 0x07, 1, 2, 3, 4, 5, 6, 7});
  const auto subs = SplitPayload(two);
  ASSERT_TRUE(subs.has_value());
  ASSERT_EQ(subs->size(), 2u);
  EXPECT_EQ((*subs)[1].id, 0x04);
  EXPECT_EQ((*subs)[1].data.size(), 7u);
}

TEST(KobukiProtocol, ParserFindsPacketsInNoiseAndCountsBadChecksums) {
  const std::vector<uint8_t> good = EncodePacket(EncodeBasicSensorData(Sample()));
  std::vector<uint8_t> bad = good;
  bad.back() ^= 0x5A;
  std::vector<uint8_t> stream{0x00, 0x13, 0xAA, 0x12, 0x55};  // noise, a lone 0xAA
  stream.insert(stream.end(), good.begin(), good.end());
  stream.insert(stream.end(), bad.begin(), bad.end());
  // A false header with a long length, then a real packet inside its "payload".
  stream.insert(stream.end(), {0xAA, 0x55, 40, 0x01});
  stream.insert(stream.end(), good.begin(), good.end());
  stream.insert(stream.end(), 40, 0x00);
  stream.insert(stream.end(), good.begin(), good.end());
  PacketParser parser;
  const auto payloads = FeedAll(&parser, stream);
  ASSERT_EQ(payloads.size(), 3u);
  for (const auto& p : payloads) {
    EXPECT_EQ(p, std::vector<uint8_t>(good.begin() + 3, good.end() - 1));
  }
  EXPECT_EQ(parser.packets(), 3);
  EXPECT_EQ(parser.bad_checksums(), 2);  // the corrupted packet and the false header
  EXPECT_GT(parser.skipped_bytes(), 0);
}

TEST(KobukiProtocol, ParserHandlesPacketsSplitAcrossReadsByteByByte) {
  std::vector<uint8_t> stream;
  for (int i = 0; i < 5; ++i) {
    BasicSensorData d = Sample();
    d.timestamp_ms = static_cast<uint16_t>(20 * i);
    const auto p = EncodePacket(EncodeBasicSensorData(d));
    stream.insert(stream.end(), p.begin(), p.end());
  }
  PacketParser parser;
  std::vector<std::vector<uint8_t>> out;
  for (uint8_t b : stream) parser.Feed(&b, 1, &out);
  ASSERT_EQ(out.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    const auto subs = SplitPayload(out[static_cast<size_t>(i)]);
    ASSERT_TRUE(subs.has_value());
    EXPECT_EQ(DecodeBasicSensorData((*subs)[0].data)->timestamp_ms, 20 * i);
  }
  EXPECT_EQ(parser.bad_checksums(), 0);
  EXPECT_EQ(parser.skipped_bytes(), 0);
  EXPECT_EQ(parser.buffered(), 0u);
}

TEST(KobukiProtocol, ParserRecoversEveryGoodPacketFromARandomlyCorruptedStream) {
  std::mt19937 rng(7);
  std::vector<uint8_t> stream;
  int good = 0, corrupted = 0;
  for (int i = 0; i < 500; ++i) {
    BasicSensorData d = Sample();
    d.timestamp_ms = static_cast<uint16_t>(i);
    auto p = EncodePacket(EncodeBasicSensorData(d));
    if (rng() % 10 == 0) {
      p[3 + rng() % 15] ^= static_cast<uint8_t>(1 + rng() % 255);  // corrupt a data byte
      ++corrupted;
    } else {
      ++good;
    }
    stream.insert(stream.end(), p.begin(), p.end());
    if (rng() % 8 == 0) {  // noise, sometimes with a false header
      for (int k = 0; k < 5; ++k) stream.push_back(static_cast<uint8_t>(rng()));
      if (rng() % 2) stream.insert(stream.end(), {0xAA, 0x55});
    }
  }
  PacketParser parser;
  std::vector<std::vector<uint8_t>> out;
  for (size_t i = 0; i < stream.size(); i += 37) {
    parser.Feed(stream.data() + i, std::min<size_t>(37, stream.size() - i), &out);
  }
  // Every good packet comes out in order (a corrupted one could pass a 1-byte XOR only by a
  // compensating error, which single-byte corruption cannot make).
  std::vector<uint16_t> stamps;
  for (const auto& p : out) {
    const auto subs = SplitPayload(p);
    if (!subs || (*subs)[0].id != kBasicSensorDataId) continue;
    const auto d = DecodeBasicSensorData((*subs)[0].data);
    if (d && d->battery == Sample().battery && d->bumper == Sample().bumper) {
      stamps.push_back(d->timestamp_ms);
    }
  }
  EXPECT_EQ(static_cast<int>(stamps.size()), good);
  EXPECT_GE(parser.bad_checksums() + parser.malformed(), corrupted);
  for (size_t i = 1; i < stamps.size(); ++i) EXPECT_LT(stamps[i - 1], stamps[i]);
}

TEST(KobukiProtocol, ParserDropsATooShortLength) {
  PacketParser parser;
  const auto good = EncodePacket(EncodeBaseControl({1, 0}));
  std::vector<uint8_t> stream{0xAA, 0x55, 0x01, 0x01, 0x01};  // length 1 < 3
  stream.insert(stream.end(), good.begin(), good.end());
  EXPECT_EQ(FeedAll(&parser, stream).size(), 1u);
  EXPECT_EQ(parser.bad_lengths(), 1);
}

TEST(KobukiProtocol, EncodePacketRejectsEmptyAndOversizedPayloads) {
  EXPECT_THROW(EncodePacket({}), std::invalid_argument);
  EXPECT_THROW(EncodePacket(std::vector<uint8_t>(256, 0)), std::invalid_argument);
  EXPECT_NO_THROW(EncodePacket(std::vector<uint8_t>(255, 0)));
}

TEST(KobukiProtocol, WrapDelta16FollowsBothDirections) {
  EXPECT_EQ(WrapDelta16(65530, 4), 10);   // forward across the wrap
  EXPECT_EQ(WrapDelta16(4, 65530), -10);  // backward across the wrap
  EXPECT_EQ(WrapDelta16(100, 130), 30);
  EXPECT_EQ(WrapDelta16(130, 100), -30);
  EXPECT_EQ(WrapDelta16(0, 32767), 32767);
  EXPECT_EQ(WrapDelta16(0, 32768), -32768);
}

TEST(KobukiProtocol, VelocityCommandsUseTheSpecialRadii) {
  const double b = 0.230;
  BaseControl c = VelocityToBaseControl(0.3, 0.0, b);  // straight
  EXPECT_EQ(c.radius_mm, kRadiusStraight);
  EXPECT_EQ(c.speed_mm_s, 300);
  c = VelocityToBaseControl(-0.25, 0.0, b);
  EXPECT_EQ(c.radius_mm, 0);
  EXPECT_EQ(c.speed_mm_s, -250);
  c = VelocityToBaseControl(0.0, 1.0, b);  // rotation in place: speed = omega * b / 2
  EXPECT_EQ(c.radius_mm, kRadiusRotate);
  EXPECT_EQ(c.speed_mm_s, 115);
  c = VelocityToBaseControl(0.0, -2.0, b);
  EXPECT_EQ(c.radius_mm, 1);
  EXPECT_EQ(c.speed_mm_s, -230);
  c = VelocityToBaseControl(0.2, 0.4, b);  // arc R = 500 mm: outer (right) wheel speed
  EXPECT_EQ(c.radius_mm, 500);
  EXPECT_EQ(c.speed_mm_s, 246);             // (500 + 115) * 0.4
  c = VelocityToBaseControl(0.2, -0.4, b);  // R = -500: outer (left) wheel
  EXPECT_EQ(c.radius_mm, -500);
  EXPECT_EQ(c.speed_mm_s, 246);  // (-500 - 115) * -0.4
  c = VelocityToBaseControl(100.0, 0.0, b);
  EXPECT_EQ(c.speed_mm_s, 32767);  // saturates
}

TEST(KobukiProtocol, WheelSpeedsInvertTheVelocityCommand) {
  const double b = 0.230;
  for (double v : {-0.5, -0.1, 0.0, 0.05, 0.3, 0.7}) {
    for (double w : {-3.0, -1.0, -0.2, 0.0, 0.1, 0.4, 2.5}) {
      const WheelSpeeds ws = BaseControlToWheelSpeeds(VelocityToBaseControl(v, w, b), b);
      const double v_out = 0.5 * (ws.left + ws.right), w_out = (ws.right - ws.left) / b;
      // Quantisation: 1 mm/s in speed, 1 mm in radius.
      EXPECT_NEAR(ws.left, v - 0.5 * b * w, 2e-3 + 0.01 * std::abs(v)) << v << " " << w;
      EXPECT_NEAR(ws.right, v + 0.5 * b * w, 2e-3 + 0.01 * std::abs(v)) << v << " " << w;
      EXPECT_NEAR(v_out, v, 2e-3) << v << " " << w;
      EXPECT_NEAR(w_out, w, 1e-2 + 0.01 * std::abs(w)) << v << " " << w;
    }
  }
}

}  // namespace
}  // namespace fl::base::kobuki
