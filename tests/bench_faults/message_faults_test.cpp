#include "fusionloc/bench_faults/message_faults.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::bench_faults {
namespace {

template <class Msg>
std::vector<uint8_t> Encode(const Msg& m) {
  std::vector<uint8_t> b(static_cast<size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

template <class Msg>
Msg Decode(const std::vector<uint8_t>& b) {
  Msg m;
  EXPECT_EQ(m.decode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
  return m;
}

bot_core::planar_lidar_t Scan() {
  bot_core::planar_lidar_t s;
  s.utime = 1000000;
  s.nranges = 5;
  s.ranges = {1, 2, 3, 4, 5};
  s.nintensities = 0;
  s.rad0 = -1.0f;
  s.radstep = 0.5f;
  return s;
}

bool Bad(double v) { return !std::isfinite(v) || std::abs(v) >= 1e29; }

TEST(MessageFaults, RecognisesTypesByFingerprint) {
  EXPECT_EQ(MessageType(Encode(Scan())), "bot_core.planar_lidar_t");
  EXPECT_EQ(MessageType(Encode(fusionloc::wheel_odometry_t())), "fusionloc.wheel_odometry_t");
  EXPECT_EQ(MessageType(Encode(fusionloc::status_t())), "");  // not an input type
  EXPECT_EQ(MessageType({1, 2, 3}), "");
  EXPECT_FALSE(CorruptibleFields("bot_core.planar_lidar_t").empty());
  EXPECT_TRUE(CorruptibleFields("nope").empty());
}

TEST(MessageFaults, ShiftsEveryStampOfAFactor) {
  fusionloc::relative_pose_factor_t f{};
  f.utime_i = 10;
  f.utime_j = 20;
  f.quat[0] = 1;
  std::vector<uint8_t> b = Encode(f);
  int64_t t = 0;
  ASSERT_TRUE(MessageUtime(b, &t));
  EXPECT_EQ(t, 20);
  ASSERT_TRUE(ShiftMessageTime(&b, 60000000));
  const auto g = Decode<fusionloc::relative_pose_factor_t>(b);
  EXPECT_EQ(g.utime_i, 60000010);
  EXPECT_EQ(g.utime_j, 60000020);
  EXPECT_EQ(g.quat[0], 1.0);
}

TEST(MessageFaults, UnknownOrTruncatedBytesAreLeftAlone) {
  std::vector<uint8_t> b = Encode(Scan());
  b.resize(b.size() - 3);
  const std::vector<uint8_t> before = b;
  std::mt19937_64 rng(1);
  std::string what;
  int64_t t = 0;
  EXPECT_FALSE(MessageUtime(b, &t));
  EXPECT_FALSE(ShiftMessageTime(&b, 5));
  EXPECT_FALSE(CorruptMessageField(&b, &rng, &what));
  EXPECT_EQ(b, before);
}

// Every corruption changes exactly one field to a bad value, and over many draws every field
// of the type is hit.
TEST(MessageFaults, CorruptsOneFieldAtATimeAndReachesThemAll) {
  std::mt19937_64 rng(7);
  const bot_core::planar_lidar_t ok = Scan();
  std::set<std::string> hit;
  for (int i = 0; i < 400; ++i) {
    std::vector<uint8_t> b = Encode(ok);
    std::string what;
    ASSERT_TRUE(CorruptMessageField(&b, &rng, &what));
    const auto m = Decode<bot_core::planar_lidar_t>(b);
    int changed = 0;
    if (m.utime != ok.utime) {
      ++changed;
      EXPECT_TRUE(m.utime < 0 || m.utime > 1000000000000000LL) << what;
      hit.insert("utime");
    }
    for (size_t k = 0; k < ok.ranges.size(); ++k) {
      if (!(m.ranges[k] == ok.ranges[k])) {
        ++changed;
        EXPECT_TRUE(Bad(m.ranges[k])) << what;
        hit.insert("ranges");
      }
    }
    if (!(m.rad0 == ok.rad0)) {
      ++changed;
      EXPECT_TRUE(Bad(m.rad0)) << what;
      hit.insert("rad0");
    }
    if (!(m.radstep == ok.radstep)) {
      ++changed;
      EXPECT_TRUE(Bad(m.radstep)) << what;
      hit.insert("radstep");
    }
    EXPECT_EQ(changed, 1) << what;
    EXPECT_EQ(what.rfind("bot_core.planar_lidar_t.", 0), 0u) << what;
  }
  // intensities is empty in this scan, so it is never chosen.
  EXPECT_EQ(hit, (std::set<std::string>{"utime", "ranges", "rad0", "radstep"}));
}

TEST(MessageFaults, NamesTheArrayElement) {
  bot_core::pose_t p{};
  p.orientation[0] = 1;
  std::mt19937_64 rng(3);
  bool saw_element = false;
  for (int i = 0; i < 100 && !saw_element; ++i) {
    std::vector<uint8_t> b = Encode(p);
    std::string what;
    ASSERT_TRUE(CorruptMessageField(&b, &rng, &what));
    saw_element = what.find("pos[") != std::string::npos && what.find("[]") == std::string::npos;
  }
  EXPECT_TRUE(saw_element);
}

}  // namespace
}  // namespace fl::bench_faults
