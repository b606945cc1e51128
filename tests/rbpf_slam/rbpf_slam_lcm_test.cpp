// The RBPF-SLAM's LCM adapter: the scan/odometry synchronisation and the conversions.
#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::rbpf {
namespace {

LaserScan Scan(Utime t) {
  LaserScan s;
  s.utime = t;
  s.ranges = {1.0f, 2.0f};
  s.radstep = 0.1;
  return s;
}

struct Handed {
  Utime utime;
  bool has_odom;
  Pose2 odom;
  std::string reason;  // why there is no odometry ("" when there is)
};

std::vector<Handed> Drain(ScanOdometrySync* sync, bool flush, std::vector<std::string>* warnings) {
  std::vector<Handed> out;
  sync->Process(
      flush,
      [&](const LaserScan& s, const Pose2* o, const Status& lookup) {
        out.push_back({s.utime, o != nullptr, o ? *o : Pose2(), lookup.message()});
      },
      [&](const std::string& w) { warnings->push_back(w); });
  return out;
}

TEST(ScanOdometrySync, AScanWaitsForOdometryAfterItAndGetsItInterpolated) {
  ScanOdometrySync sync(0.3, true);
  std::vector<std::string> warnings;
  ASSERT_TRUE(sync.PushOdometry(0, Pose2(0, 0, 0)).ok());
  ASSERT_TRUE(sync.PushScan(Scan(50000)).ok());
  EXPECT_TRUE(Drain(&sync, false, &warnings).empty());  // no odometry after 0.05 s yet
  ASSERT_TRUE(sync.PushOdometry(100000, Pose2(1.0, 0, 0.2)).ok());
  ASSERT_TRUE(sync.PushOdometry(200000, Pose2(2.0, 0, 0.4)).ok());
  // The merger hands odometry at 0.1 s on once the laser stream has passed it.
  ASSERT_TRUE(sync.PushScan(Scan(150000)).ok());
  const auto h = Drain(&sync, false, &warnings);
  ASSERT_EQ(h.size(), 1u);
  EXPECT_EQ(h[0].utime, 50000);
  ASSERT_TRUE(h[0].has_odom);
  EXPECT_NEAR(h[0].odom.x, 0.5, 1e-12);
  EXPECT_NEAR(h[0].odom.theta, 0.1, 1e-12);
  EXPECT_TRUE(warnings.empty());
}

TEST(ScanOdometrySync, AScanWithoutOdometryIsHandedOnAfterTheLatencyWithTheReason) {
  ScanOdometrySync sync(0.3, true);
  std::vector<std::string> warnings;
  ASSERT_TRUE(sync.PushOdometry(0, Pose2()).ok());
  ASSERT_TRUE(sync.PushOdometry(100000, Pose2(1, 0, 0)).ok());
  ASSERT_TRUE(sync.PushScan(Scan(500000)).ok());  // odometry stops before it
  ASSERT_TRUE(sync.PushScan(Scan(600000)).ok());
  ASSERT_TRUE(sync.PushScan(Scan(900000)).ok());
  EXPECT_TRUE(Drain(&sync, false, &warnings).empty());  // still within the merge latency
  ASSERT_TRUE(sync.PushScan(Scan(1200000)).ok());
  ASSERT_TRUE(sync.PushScan(Scan(1500000)).ok());  // data has moved on > 0.3 s past the first
  auto h = Drain(&sync, false, &warnings);
  ASSERT_EQ(h.size(), 2u);
  EXPECT_EQ(h[0].utime, 500000);
  EXPECT_FALSE(h[0].has_odom);
  EXPECT_NE(h[0].reason.find("no odometry around utime 500000"), std::string::npos)
      << h[0].reason;
  EXPECT_EQ(h[1].utime, 600000);
  h = Drain(&sync, true, &warnings);  // the end: everything still waiting goes
  ASSERT_EQ(h.size(), 3u);
  EXPECT_EQ(h.back().utime, 1500000);
}

TEST(ScanOdometrySync, TimeGoingBackwardsIsRefusedAndWithoutOdometryScansGoAtOnce) {
  ScanOdometrySync sync(0.3, false);
  std::vector<std::string> warnings;
  ASSERT_TRUE(sync.PushScan(Scan(100000)).ok());
  const Status back = sync.PushScan(Scan(50000));
  EXPECT_FALSE(back.ok());
  EXPECT_NE(back.message().find("time went backwards"), std::string::npos) << back.message();
  EXPECT_TRUE(sync.PushOdometry(0, Pose2()).ok());  // ignored without odometry
  const auto h = Drain(&sync, false, &warnings);    // no flush: nothing to wait for
  ASSERT_EQ(h.size(), 1u);
  EXPECT_EQ(h[0].utime, 100000);
  EXPECT_FALSE(h[0].has_odom);
  EXPECT_EQ(h[0].reason, "");
  EXPECT_EQ(sync.waiting(), 0u);
}

TEST(RbpfSlamLcm, FactorAndGridConversions) {
  KeyframeFactor f;
  f.keyframe_i = 3;
  f.keyframe_j = 4;
  f.utime_i = 10;
  f.utime_j = 20;
  f.T_i_j = Pose2(1.0, -0.5, 0.25);
  f.information << 100, 1, 2, 1, 200, 3, 2, 3, 300;
  const auto m = FactorToLcm(f);
  EXPECT_EQ(m.information[0], 100);
  EXPECT_EQ(m.information[1 * 6 + 1], 200);
  EXPECT_EQ(m.information[5 * 6 + 5], 300);
  EXPECT_EQ(m.information[0 * 6 + 5], 2);
  EXPECT_EQ(m.information[2 * 6 + 2], 0);  // z stays unknown
  EXPECT_NEAR(m.trans[0], 1.0, 1e-12);
  EXPECT_NEAR(2 * std::atan2(m.quat[3], m.quat[0]), 0.25, 1e-12);
  EXPECT_EQ(m.keyframe_id_j, 4);

  TiledGrid grid{GridOptions{}};
  const auto empty = GridToLcm(5, grid);
  EXPECT_EQ(empty.num_cells, 0);
}

// Found by fuzzing (tests/fuzz/regressions/rbpf_node/): odometry 4e8 m (or 1e169 m) from its
// origin put the robot where the grid has no cell (out-of-range int casts in the map and the
// scan matcher). The node drops such odometry, and a laser mounting 1e9 m away, and counts them.
TEST(RbpfSlamNodeInput, AbsurdOdometryAndMountingAreDroppedAndCounted) {
  auto lcm = MakeLcm("memq://");
  RbpfSlamNode node(RbpfSlamOptions{}, RbpfSlamNodeOptions{}, lcm.get(), ChannelMap());
  bot_core::rigid_transform_t mount{};
  mount.trans[0] = 1e9;
  mount.quat[0] = 1.0;
  lcm->Publish(channels::kLaserToBase, mount, 0);
  fusionloc::wheel_odometry_t odo{};
  odo.utime = 1000000;
  for (const double x : {4.3e8, -2.3e169, std::nan(""), 1.0}) {
    odo.x = x;
    odo.utime += 100000;
    lcm->Publish(channels::kOdometry, odo, 0);
  }
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  EXPECT_EQ(node.status().dropped(), 4);
}

}  // namespace
}  // namespace fl::rbpf
