#include "fusionloc/bench_faults/fault_injector.hpp"

#include <gtest/gtest.h>

#include <set>
#include <stdexcept>

#include "bot_core/planar_lidar_t.hpp"
#include "fusionloc/bench_faults/message_faults.hpp"

namespace fl::bench_faults {
namespace {

std::vector<uint8_t> ScanAt(int64_t utime) {
  bot_core::planar_lidar_t s;
  s.utime = utime;
  s.nranges = 3;
  s.ranges = {1, 2, 3};
  s.nintensities = 0;
  s.rad0 = 0;
  s.radstep = 0.1f;
  std::vector<uint8_t> b(static_cast<size_t>(s.getEncodedSize()));
  s.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

int64_t StampOf(const FaultEvent& e) {
  int64_t t = -1;
  EXPECT_TRUE(MessageUtime(e.data, &t));
  return t;
}

// Pushes n scans 0.1 s apart (stamps and arrival), pops as it goes; returns what came out.
std::vector<FaultEvent> Stream(FaultInjector* f, int n, const std::string& channel = "LASER") {
  std::vector<FaultEvent> out;
  FaultEvent e;
  for (int i = 0; i < n; ++i) {
    const double now = 0.1 * i;
    f->Push(channel, ScanAt(100000 * i), now);
    while (f->Pop(now, &e)) out.push_back(e);
  }
  f->Flush();
  while (f->Pop(1e9, &e)) out.push_back(e);
  return out;
}

TEST(FaultInjector, WithoutFaultsEverythingPassesInOrder) {
  FaultInjector f(FaultOptions{});
  const auto out = Stream(&f, 50);
  ASSERT_EQ(out.size(), 50u);
  for (int i = 0; i < 50; ++i) EXPECT_EQ(StampOf(out[i]), 100000 * i);
  EXPECT_EQ(f.counts().in, 50);
  EXPECT_EQ(f.counts().out, 50);
}

TEST(FaultInjector, DropsAboutTheFractionAndCountsIt) {
  FaultOptions o;
  o.drop_fraction = 0.1;
  FaultInjector f(o);
  const auto out = Stream(&f, 2000);
  EXPECT_EQ(static_cast<int64_t>(out.size()) + f.counts().dropped, 2000);
  EXPECT_NEAR(f.counts().dropped, 200, 50);
  EXPECT_EQ(f.counts().dropped_per_channel.at("LASER"), f.counts().dropped);
}

TEST(FaultInjector, OnlyMatchingChannelsAreTouched) {
  FaultOptions o;
  o.channels = "ODOMETRY";
  o.drop_fraction = 1.0;
  FaultInjector f(o);
  EXPECT_EQ(Stream(&f, 20, "LASER").size(), 20u);
  EXPECT_EQ(Stream(&f, 20, "ODOMETRY").size(), 0u);
}

TEST(FaultInjector, DuplicatesFollowTheirOriginal) {
  FaultOptions o;
  o.duplicate_fraction = 0.5;
  FaultInjector f(o);
  const auto out = Stream(&f, 200);
  EXPECT_EQ(static_cast<int64_t>(out.size()), 200 + f.counts().duplicated);
  EXPECT_GT(f.counts().duplicated, 50);
  for (size_t i = 1; i < out.size(); ++i) EXPECT_LE(StampOf(out[i - 1]), StampOf(out[i]));
}

TEST(FaultInjector, DelayedMessagesAreOvertakenButNotLost) {
  FaultOptions o;
  o.delay_fraction = 0.2;
  o.max_delay_s = 1.0;
  FaultInjector f(o);
  const auto out = Stream(&f, 300);
  ASSERT_EQ(out.size(), 300u);
  int inversions = 0;
  std::set<int64_t> stamps;
  for (size_t i = 0; i < out.size(); ++i) {
    stamps.insert(StampOf(out[i]));
    if (i > 0 && StampOf(out[i]) < StampOf(out[i - 1])) ++inversions;
  }
  EXPECT_EQ(stamps.size(), 300u);
  EXPECT_GT(inversions, 10);
  EXPECT_GT(f.counts().delayed, 30);
}

TEST(FaultInjector, ClockJumpShiftsOnlyTheWindow) {
  FaultOptions o;
  o.jump_offset_s = 60.0;
  o.jump_start_s = 1.0;
  o.jump_duration_s = 0.5;
  FaultInjector f(o);
  const auto out = Stream(&f, 30);
  ASSERT_EQ(out.size(), 30u);
  for (int i = 0; i < 30; ++i) {
    const bool in_window = i >= 10 && i < 15;
    EXPECT_EQ(StampOf(out[i]), 100000 * i + (in_window ? 60000000 : 0)) << i;
  }
  EXPECT_EQ(f.counts().shifted, 5);
}

TEST(FaultInjector, OutageRemovesTheWindowOnly) {
  FaultOptions o;
  o.outage_start_s = 1.0;
  o.outage_duration_s = 0.5;
  FaultInjector f(o);
  const auto out = Stream(&f, 30);
  ASSERT_EQ(out.size(), 25u);
  for (size_t i = 0; i < out.size(); ++i) {
    const int64_t k = static_cast<int64_t>(i < 10 ? i : i + 5);  // 10..14 removed
    EXPECT_EQ(StampOf(out[i]), 100000 * k) << i;
  }
  EXPECT_EQ(f.counts().silenced, 5);
  EXPECT_EQ(f.counts().dropped, 5);
  EXPECT_EQ(f.counts().dropped_per_channel.at("LASER"), 5);
}

TEST(FaultInjector, CorruptsAndRemembersWhat) {
  FaultOptions o;
  o.corrupt_fraction = 1.0;
  FaultInjector f(o);
  const auto out = Stream(&f, 10);
  EXPECT_EQ(f.counts().corrupted, 10);
  ASSERT_FALSE(f.counts().corruptions.empty());
  EXPECT_NE(f.counts().corruptions[0].find("LASER: bot_core.planar_lidar_t."), std::string::npos);
  int differ = 0;
  for (int i = 0; i < 10; ++i) differ += out[i].data != ScanAt(100000 * i);
  EXPECT_EQ(differ, 10);
}

TEST(FaultInjector, SameSeedSameFaults) {
  FaultOptions o;
  o.drop_fraction = 0.3;
  o.corrupt_fraction = 0.3;
  FaultInjector a(o), b(o);
  const auto x = Stream(&a, 100), y = Stream(&b, 100);
  ASSERT_EQ(x.size(), y.size());
  for (size_t i = 0; i < x.size(); ++i) EXPECT_EQ(x[i].data, y[i].data);
}

TEST(FaultInjector, RejectsInvalidOptions) {
  FaultOptions o;
  o.drop_fraction = 1.5;
  EXPECT_THROW(FaultInjector{o}, std::invalid_argument);
  o = FaultOptions{};
  o.delay_fraction = 0.1;  // without max_delay_s
  EXPECT_THROW(FaultInjector{o}, std::invalid_argument);
  o = FaultOptions{};
  o.outage_duration_s = -1.0;
  EXPECT_THROW(FaultInjector{o}, std::invalid_argument);
  o = FaultOptions{};
  o.channels = "(";
  EXPECT_THROW(FaultInjector{o}, std::invalid_argument);
}

}  // namespace
}  // namespace fl::bench_faults
