// The RBPF-SLAM's LCM adapter: the scan/odometry synchronisation and the conversions.
#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "laser_fixtures.hpp"

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
  EXPECT_TRUE(sync.PushOdometry(0, Pose2()).ok());  // ignored without odometry
  const auto h = Drain(&sync, false, &warnings);    // no flush: nothing to wait for
  ASSERT_EQ(h.size(), 1u);
  EXPECT_EQ(h[0].utime, 100000);
  EXPECT_FALSE(h[0].has_odom);
  EXPECT_EQ(h[0].reason, "");
  EXPECT_EQ(sync.waiting(), 0u);
  // Older than the scan already handed on: refused.
  const Status back = sync.PushScan(Scan(50000));
  EXPECT_FALSE(back.ok());
  EXPECT_NE(back.message().find("was processed"), std::string::npos) << back.message();
}

TEST(ScanOdometrySync, ReorderedOdometryWithinTheMergeLatencyIsPlacedByItsStamp) {
  ScanOdometrySync sync(0.3, true);
  std::vector<std::string> warnings;
  ASSERT_TRUE(sync.PushOdometry(0, Pose2(0, 0, 0)).ok());
  ASSERT_TRUE(sync.PushOdometry(200000, Pose2(2, 0, 0)).ok());
  ASSERT_TRUE(sync.PushOdometry(100000, Pose2(1, 0, 0)).ok());  // arrived late, still in time
  ASSERT_TRUE(sync.PushScan(Scan(150000)).ok());
  ASSERT_TRUE(sync.PushOdometry(300000, Pose2(3, 0, 0)).ok());
  const auto h = Drain(&sync, true, &warnings);
  ASSERT_EQ(h.size(), 1u);
  EXPECT_TRUE(h[0].has_odom);
  EXPECT_NEAR(h[0].odom.x, 1.5, 1e-9);  // between the samples at 0.1 s and 0.2 s
}

TEST(MountingWait, HoldsTheFirstScansForTheWaitThenHandsThemOnInOrder) {
  MountingWait wait(1.0);
  std::vector<Utime> run;
  const auto on_scan = [&](const LaserScan& s, const Pose2* o, const Status&) {
    run.push_back(s.utime);
    EXPECT_NE(o, nullptr);
  };
  const Pose2 odom(1, 0, 0);
  EXPECT_EQ(wait.Offer(true, Scan(1'000'000), &odom, Status::Ok(), on_scan),
            MountingWait::Outcome::kHeldFirst);
  EXPECT_EQ(wait.Offer(true, Scan(1'500'000), &odom, Status::Ok(), on_scan),
            MountingWait::Outcome::kHeld);
  EXPECT_TRUE(run.empty());
  EXPECT_EQ(wait.held(), 2u);
  // 1 s after the first held scan: the wait is over, everything runs in order.
  EXPECT_EQ(wait.Offer(true, Scan(2'000'000), &odom, Status::Ok(), on_scan),
            MountingWait::Outcome::kRun);
  EXPECT_EQ(run, (std::vector<Utime>{1'000'000, 1'500'000, 2'000'000}));
  EXPECT_EQ(wait.held(), 0u);
}

TEST(MountingWait, ReleaseRunsTheHeldScansAndNotWaitingOrNoWaitNeverHolds) {
  std::vector<Utime> run;
  const auto on_scan = [&](const LaserScan& s, const Pose2*, const Status&) {
    run.push_back(s.utime);
  };
  MountingWait wait(2.0);
  EXPECT_EQ(wait.Offer(true, Scan(10), nullptr, Status::Error("no odometry"), on_scan),
            MountingWait::Outcome::kHeldFirst);
  wait.Release(on_scan);  // the mounting arrived
  EXPECT_EQ(run, (std::vector<Utime>{10}));
  EXPECT_EQ(wait.Offer(false, Scan(20), nullptr, Status::Ok(), on_scan),
            MountingWait::Outcome::kRun);
  MountingWait none(0.0);
  EXPECT_EQ(none.Offer(true, Scan(30), nullptr, Status::Ok(), on_scan),
            MountingWait::Outcome::kRun);
  EXPECT_EQ(run, (std::vector<Utime>{10, 20, 30}));
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

// A live RbpfSlamNode (memq://) fed `steps` scans at 10 Hz of a robot driving along a room's
// wall, with LASER_TO_BASE published after `mounting_after` scans (-1: never). Returns the
// number of RBPF_POSE after each scan and, through `log`, what the node logged; through
// `trajectory_sizes` the size of each RBPF_TRAJECTORY.
// With `late_every` > 0, every late_every-th scan (after the first 10) reaches the node 5 scans
// (0.5 s) late, beyond the merge window; `pose_stamps` gets the stamp of each RBPF_POSE.
std::vector<int> RunNode(int steps, int mounting_after, std::string* log,
                         const RbpfSlamNodeOptions& node_options = RbpfSlamNodeOptions(),
                         std::vector<int>* trajectory_sizes = nullptr, int late_every = 0,
                         std::vector<Utime>* pose_stamps = nullptr) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  auto lcm = MakeLcm("memq://");
  int poses = 0;
  lcm->Subscribe<bot_core::pose_t>(channels::kRbpfPose,
                                   [&](const bot_core::pose_t& m, const std::string&) {
                                     ++poses;
                                     if (pose_stamps) pose_stamps->push_back(m.utime);
                                   });
  std::map<int, bot_core::planar_lidar_t> delayed;  // by the step they arrive at
  std::vector<int> sizes;
  lcm->Subscribe<fusionloc::trajectory_t>(
      channels::kRbpfTrajectory,
      [&](const fusionloc::trajectory_t& m, const std::string&) { sizes.push_back(m.num_poses); });
  testing::internal::CaptureStderr();
  std::vector<int> out;
  {
    RbpfSlamNode node(RbpfSlamOptions(), node_options, lcm.get(), ChannelMap());
    const Pose2 T_base_laser(0.15, 0.0, 0.0);
    for (int k = 0; k < steps; ++k) {
      if (k == mounting_after) {
        lcm->Publish(channels::kLaserToBase, TransformToLcm(T_base_laser.ToIsometry3(), 0), 0);
      }
      const Utime t = 1000000 + 100000 * static_cast<Utime>(k);
      const Pose2 T_world_base(-8.5 + 0.05 * k, -4.5, 0.0);
      fusionloc::wheel_odometry_t odom{};
      odom.utime = t;
      odom.x = T_world_base.x;
      odom.y = T_world_base.y;
      lcm->Publish(channels::kOdometry, odom, t);
      bot_core::planar_lidar_t scan{};
      scan.utime = t;
      scan.ranges = world.Scan(T_world_base * T_base_laser, 181, -M_PI / 2, M_PI / 180, 25.0);
      for (float& r : scan.ranges) {
        if (!std::isfinite(r)) r = 0.0f;
      }
      scan.nranges = static_cast<int32_t>(scan.ranges.size());
      scan.rad0 = static_cast<float>(-M_PI / 2);
      scan.radstep = static_cast<float>(M_PI / 180);
      if (late_every > 0 && k > 10 && k + 5 < steps && k % late_every == 0) {
        delayed[k + 5] = scan;
      } else {
        lcm->Publish(channels::kLaser, scan, t);
      }
      if (delayed.count(k)) lcm->Publish(channels::kLaser, delayed[k], delayed[k].utime);
      while (lcm->HandleSubscriptions(0) > 0) {
      }
      node.Poll();
      while (lcm->HandleSubscriptions(0) > 0) {
      }
      out.push_back(poses);
    }
    node.Finish();
    while (lcm->HandleSubscriptions(0) > 0) {
    }
    out.push_back(poses);
  }
  *log = testing::internal::GetCapturedStderr();
  if (trajectory_sizes) *trajectory_sizes = sizes;
  return out;
}

TEST(RbpfSlamNode, EveryScansPoseIsPublishedAtTheEndOnlyWhenAsked) {
  std::string log;
  // Default (a robot running for hours): the scan path is not kept; RBPF_TRAJECTORY holds the
  // keyframes, at the end too.
  std::vector<int> sizes;
  RunNode(40, 0, &log, RbpfSlamNodeOptions(), &sizes);
  ASSERT_FALSE(sizes.empty()) << log;
  EXPECT_LT(sizes.back(), 40) << log;
  EXPECT_GE(sizes.back(), 2) << log;
  // --scan-trajectory (a log replay to score): the final RBPF_TRAJECTORY has every scan.
  RbpfSlamNodeOptions every_scan;
  every_scan.scan_trajectory = true;
  RunNode(40, 0, &log, every_scan, &sizes);
  ASSERT_FALSE(sizes.empty()) << log;
  EXPECT_EQ(sizes.back(), 40) << log;
  for (size_t i = 0; i + 1 < sizes.size(); ++i) EXPECT_LT(sizes[i], 40) << log;  // keyframes
}

TEST(RbpfSlamNode, TheFirstScansWaitForTheMountingAndNoneIsLost) {
  std::string log;
  // LASER_TO_BASE after 5 scans (a process respawned mid-run gets it within its 1 s period):
  // nothing is published before it, then every held scan, with the mounting.
  std::vector<int> poses = RunNode(12, 5, &log);
  EXPECT_EQ(poses[4], 0) << log;
  EXPECT_GE(poses[6], 5) << log;
  EXPECT_EQ(poses.back(), 12) << log;
  EXPECT_NE(log.find("T_base_laser from LASER_TO_BASE: x 0.15"), std::string::npos) << log;
  EXPECT_EQ(log.find("identity"), std::string::npos) << log;
  // Never: after mounting_wait_s (2 s of scans) the laser is taken to be at the base origin,
  // with a warning, and no scan is lost.
  poses = RunNode(30, -1, &log);
  EXPECT_EQ(poses[15], 0) << log;
  EXPECT_GE(poses[25], 20) << log;
  EXPECT_EQ(poses.back(), 30) << log;
  EXPECT_NE(log.find("identity T_base_laser"), std::string::npos) << log;
}

// Scans the network delivers 0.5 s late, beyond the 0.3 s merge window, are placed by their
// stamps: each gets its RBPF_POSE (late), none twice, and the final trajectory has them all.
TEST(RbpfSlamNode, LateScansBeyondTheMergeWindowGetTheirPoses) {
  std::string log;
  RbpfSlamNodeOptions every_scan;
  every_scan.scan_trajectory = true;
  std::vector<int> sizes;
  std::vector<Utime> stamps;
  const std::vector<int> poses = RunNode(60, 0, &log, every_scan, &sizes, 7, &stamps);
  EXPECT_EQ(poses.back(), 60) << log;
  std::vector<Utime> sorted = stamps;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(std::unique(sorted.begin(), sorted.end()), sorted.end());  // none twice
  int out_of_order = 0;  // the 6 late ones (steps 14, 21, ..., 49)
  for (size_t i = 1; i < stamps.size(); ++i) out_of_order += stamps[i] < stamps[i - 1] ? 1 : 0;
  EXPECT_EQ(out_of_order, 6);
  ASSERT_FALSE(sizes.empty());
  EXPECT_EQ(sizes.back(), 60) << log;
  EXPECT_EQ(log.find("dropped"), std::string::npos) << log;
}

// Found by fuzzing (tests/fuzz/regressions/rbpf_node/): odometry 4e8 m (or 1e169 m) from its
// origin put the robot where the grid has no cell (out-of-range int casts in the map and the
// scan matcher). The node drops such odometry, and a laser mounting 1e9 m away, and counts them;
// values beyond any range (1e169) or not finite never reach it: the LCM layer drops and counts
// them (message_checks.hpp).
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
  EXPECT_EQ(node.status().dropped(), 2);  // the mounting and 4.3e8 m
  EXPECT_EQ(lcm->invalid_values(), 2);     // -2.3e169 m and NaN
}

}  // namespace
}  // namespace fl::rbpf
