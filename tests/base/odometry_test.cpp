// Wheel odometry from wrapping encoders (forward and backward across 65535/0), the exact arc
// integration against an analytic circle driven through the emulated Kobuki, and the command
// watchdog.
#include "fusionloc/base/odometry.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "fusionloc/base/kobuki_emulator.hpp"

namespace fl::base {
namespace {

const BaseGeometry kKobuki{0.035, 0.230, 2578.33};

kobuki::BasicSensorData Reading(uint16_t t_ms, uint16_t left, uint16_t right) {
  kobuki::BasicSensorData d;
  d.timestamp_ms = t_ms;
  d.left_encoder = left;
  d.right_encoder = right;
  return d;
}

TEST(WheelOdometry, StraightForwardAcrossTheWrap) {
  WheelOdometry odo(kKobuki, {});
  OdometrySample s;
  EXPECT_FALSE(odo.Update(0, Reading(65500, 65000, 65000), &s));  // the reference
  // 1000 ticks forward on both wheels, across 65535 -> 0, robot clock wrapping too.
  ASSERT_TRUE(odo.Update(20000, Reading(65500 + 20 - 65536, 464, 464), &s));
  const double d = 1000 * MetresPerTick(kKobuki);
  EXPECT_NEAR(s.x, d, 1e-12);
  EXPECT_NEAR(s.y, 0.0, 1e-12);
  EXPECT_NEAR(s.theta, 0.0, 1e-12);
  EXPECT_NEAR(s.v, d / 0.020, 1e-9);
  EXPECT_EQ(s.left_ticks, 1000);
  EXPECT_EQ(s.right_ticks, 1000);
}

TEST(WheelOdometry, StraightBackwardAcrossTheWrap) {
  WheelOdometry odo(kKobuki, {});
  OdometrySample s;
  odo.Update(0, Reading(100, 300, 300), &s);
  ASSERT_TRUE(odo.Update(20000, Reading(120, 65536 - 700, 65536 - 700), &s));  // -1000 ticks
  EXPECT_NEAR(s.x, -1000 * MetresPerTick(kKobuki), 1e-12);
  EXPECT_LT(s.v, 0);
  EXPECT_EQ(s.left_ticks, -1000);
}

TEST(WheelOdometry, RotationInPlaceGivesTheTrackAngle) {
  WheelOdometry odo(kKobuki, {});
  OdometrySample s;
  odo.Update(0, Reading(0, 10, 65530), &s);
  // Left back 500 ticks (across 0 -> 65535), right forward 500 (across 65535 -> 0).
  ASSERT_TRUE(odo.Update(20000,
                         Reading(20, static_cast<uint16_t>(10 - 500 + 65536),
                                 static_cast<uint16_t>(65530 + 500 - 65536)),
                         &s));
  const double arc = 500 * MetresPerTick(kKobuki);
  EXPECT_NEAR(s.theta, 2 * arc / kKobuki.track_m, 1e-12);
  EXPECT_NEAR(s.x, 0.0, 1e-12);
  EXPECT_NEAR(s.y, 0.0, 1e-12);
  EXPECT_NEAR(s.omega, 2 * arc / kKobuki.track_m / 0.020, 1e-9);
}

TEST(WheelOdometry, OneArcStepIsExact) {
  // One reading interval on an arc of radius R: chord geometry, not a straight-line guess.
  WheelOdometry odo(kKobuki, {});
  OdometrySample s;
  odo.Update(0, Reading(0, 0, 0), &s);
  const double m = MetresPerTick(kKobuki);
  const int dl = 2000, dr = 3000;
  ASSERT_TRUE(odo.Update(20000, Reading(20, dl, dr), &s));
  const double th = (dr - dl) * m / kKobuki.track_m;
  const double R = 0.5 * (dl + dr) * m / th;
  EXPECT_NEAR(s.x, R * std::sin(th), 1e-12);
  EXPECT_NEAR(s.y, R * (1 - std::cos(th)), 1e-12);
  EXPECT_NEAR(s.theta, th, 1e-12);
}

TEST(WheelOdometry, AGapResetsTheReference) {
  WheelOdometry odo(kKobuki, {1.0});
  OdometrySample s;
  odo.Update(0, Reading(0, 0, 0), &s);
  ASSERT_TRUE(odo.Update(20000, Reading(20, 100, 100), &s));
  // 1.5 s of silence: the tick step cannot be trusted; the pose is kept, the step is not used.
  EXPECT_FALSE(odo.Update(1520000, Reading(1520, 40000, 40000), &s));
  EXPECT_EQ(odo.gaps(), 1);
  ASSERT_TRUE(odo.Update(1540000, Reading(1540, 40100, 40100), &s));
  EXPECT_NEAR(s.x, 200 * MetresPerTick(kKobuki), 1e-12);
}

TEST(WheelOdometry, InvalidGeometryIsRefused) {
  EXPECT_THROW(WheelOdometry(BaseGeometry{0.035, 0.23, 0.0}, {}), std::invalid_argument);
  EXPECT_FALSE(CheckOdometryGeometry(BaseGeometry{0.0, 0.23, 2578.33}).ok());
  // Not described (all zero) is a valid robot description, but no odometry.
  EXPECT_NE(CheckOdometryGeometry(BaseGeometry{}).message().find("turtlebot2.yaml"),
            std::string::npos);
}

// Drives the emulated Kobuki (stepped, deterministic) on a commanded circle and integrates
// its feedback packets; compares with the analytic circle and with the emulator's truth.
TEST(WheelOdometry, FollowsAnEmulatedCircle) {
  KobukiEmulatorOptions eo;  // encoders and clock start near the wrap
  SimulatedKobuki kobuki(eo);
  const double v = 0.2, w = 0.4;  // R = 0.5 m; Base Control radius 500, speed 246 exactly
  const auto cmd = kobuki::EncodePacket(
      kobuki::EncodeBaseControl(kobuki::VelocityToBaseControl(v, w, kKobuki.track_m)));
  kobuki.Receive(cmd.data(), cmd.size());
  WheelOdometry odo(kKobuki, {});
  kobuki::PacketParser parser;
  OdometrySample s;
  const int steps = static_cast<int>(std::round(2 * M_PI / w / 0.02));  // one full turn
  int wraps_left = 0;
  uint16_t last_left = 0;
  for (int k = 0; k <= steps; ++k) {
    const auto bytes = kobuki.Step(0.02);
    std::vector<std::vector<uint8_t>> payloads;
    parser.Feed(bytes.data(), bytes.size(), &payloads);
    ASSERT_EQ(payloads.size(), 1u);
    const auto d = kobuki::DecodeBasicSensorData((*kobuki::SplitPayload(payloads[0]))[0].data);
    if (k > 0 && d->left_encoder < last_left) ++wraps_left;
    last_left = d->left_encoder;
    odo.Update(SecondsToUtime(0.02 * k), *d, &s);
  }
  EXPECT_GE(wraps_left, 1);  // the counters wrapped during the run
  // Analytic circle from the first reading (t = 0.02 s) to the last.
  const double T = 0.02 * steps;
  const double R = v / w;
  const double th = w * T;
  EXPECT_NEAR(s.theta, WrapAngle(th), 1e-3);
  EXPECT_NEAR(s.x, R * std::sin(th), 1e-3);
  EXPECT_NEAR(s.y, R * (1 - std::cos(th)), 1e-3);
  // Velocities over one 20 ms interval: one tick is 4.3 mm/s of v and 37 mrad/s of omega.
  EXPECT_NEAR(s.v, v, 5e-3);
  EXPECT_NEAR(s.omega, w, 0.08);
  // The emulator's truth is in its start frame, one step before the first reading: compose.
  const Pose2 first(R * std::sin(w * 0.02), R * (1 - std::cos(w * 0.02)), w * 0.02);
  const Pose2 truth = first.inverse() * kobuki.pose();
  EXPECT_NEAR(s.x, truth.x, 2e-4);  // 1 tick = 0.085 mm
  EXPECT_NEAR(s.y, truth.y, 2e-4);
  EXPECT_NEAR(s.theta, truth.theta, 1e-3);
}

// Feedback dropouts (0.3 s every second) lose packets, not motion: the encoders are cumulative,
// so the first packet after a dropout carries the whole step.
TEST(WheelOdometry, DropoutsLosePacketsNotMotion) {
  KobukiEmulatorOptions eo;
  eo.dropout_every_s = 1.0;
  eo.dropout_length_s = 0.3;
  SimulatedKobuki kobuki(eo);
  const auto cmd = kobuki::EncodePacket(
      kobuki::EncodeBaseControl(kobuki::VelocityToBaseControl(0.3, -0.5, kKobuki.track_m)));
  kobuki.Receive(cmd.data(), cmd.size());
  WheelOdometry odo(kKobuki, {});
  kobuki::PacketParser parser;
  OdometrySample s;
  int packets = 0;
  Pose2 first, at_last_packet;
  for (int k = 1; k <= 190; ++k) {  // 3.8 s
    const auto bytes = kobuki.Step(0.02);
    std::vector<std::vector<uint8_t>> payloads;
    parser.Feed(bytes.data(), bytes.size(), &payloads);
    for (const auto& p : payloads) {
      const auto d = kobuki::DecodeBasicSensorData((*kobuki::SplitPayload(p))[0].data);
      if (packets++ == 0) first = kobuki.pose();
      at_last_packet = kobuki.pose();
      odo.Update(SecondsToUtime(0.02 * k), *d, &s);
    }
  }
  EXPECT_GE(kobuki.dropped(), 44);  // 3 dropouts of 15 packets (give or take the boundaries)
  EXPECT_EQ(packets, 190 - kobuki.dropped());
  const Pose2 truth = first.inverse() * at_last_packet;
  EXPECT_NEAR(s.x, truth.x, 2e-4);
  EXPECT_NEAR(s.y, truth.y, 2e-4);
  EXPECT_NEAR(s.theta, truth.theta, 1e-3);
  EXPECT_EQ(odo.gaps(), 0);  // 0.3 s is below max_gap_s
}

TEST(CommandWatchdog, StopsAfterTheTimeoutAndCountsOnce) {
  CommandWatchdog wd(0.5);
  EXPECT_EQ(wd.Current(0).v, 0.0);
  EXPECT_EQ(wd.timeouts(), 0);  // nothing commanded yet: nothing to time out
  wd.Command(1000000, 0.3, 0.1);
  EXPECT_EQ(wd.Current(1400000).v, 0.3);
  EXPECT_EQ(wd.Current(1500000).omega, 0.1);
  EXPECT_EQ(wd.Current(1500001).v, 0.0);
  EXPECT_EQ(wd.Current(1600000).omega, 0.0);
  EXPECT_EQ(wd.timeouts(), 1);
  wd.Command(2000000, -0.1, 0.0);
  EXPECT_EQ(wd.Current(2100000).v, -0.1);
  EXPECT_EQ(wd.Current(3000000).v, 0.0);
  EXPECT_EQ(wd.timeouts(), 2);
}

}  // namespace
}  // namespace fl::base
