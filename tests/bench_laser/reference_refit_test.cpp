#include "reference_refit.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "laser_fixtures.hpp"

namespace fl::rbpf {
namespace {

// The loop corridor of RoomWithBoxes, a scan every 0.25 m, little odometry noise; the scans'
// reference is the truth, optionally bent.
std::vector<RefitScan> LoopScans(const test::LoopRun& run) {
  std::vector<RefitScan> scans;
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    RefitScan s;
    s.scan.utime = run.utimes[k];
    s.scan.ranges = run.ranges[k];
    s.scan.rad0 = -M_PI / 2;
    s.scan.radstep = M_PI / 180;
    s.T_odom_base = run.odom[k];
    s.T_world_base_reference = run.truth[k];
    scans.push_back(std::move(s));
  }
  return scans;
}

test::LoopRun StraightLoopRun() {
  test::LoopRunOptions lo;
  lo.step_m = 0.25;
  lo.odom_rot_bias = 0.0;
  return test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
}

RbpfSlamOptions Options() {
  RbpfSlamOptions o;
  o.grid.max_range = 25.0;
  return o;
}

RefitOdometrySigma Sigma() {
  RefitOdometrySigma s;
  s.trans_per_m = 0.05;
  s.rot_per_m = 0.03;
  return s;
}

double MaxError(const std::vector<fl::Pose2>& a, const std::vector<fl::Pose2>& b) {
  double e = 0.0;
  for (size_t k = 0; k < a.size(); ++k)
    e = std::max(e, std::hypot(a[k].x - b[k].x, a[k].y - b[k].y));
  return e;
}

TEST(ReferenceRefit, TheTruthStaysWhereItIs) {
  const test::LoopRun run = StraightLoopRun();
  const std::vector<RefitScan> scans = LoopScans(run);
  const RefitResult r = RefitReference(scans, fl::Pose2(), Options(), Sigma(), RefitOptions());
  ASSERT_EQ(r.T_world_base.size(), scans.size());
  EXPECT_EQ(r.odometry_edges, static_cast<int>(scans.size()) - 1);
  // Every scan pairs with its predecessor, and with earlier scans where the loop closes.
  EXPECT_GT(r.icp_edges, static_cast<int>(scans.size()));
  EXPECT_LE(r.final_cost, r.initial_cost);
  EXPECT_LT(MaxError(r.T_world_base, run.truth), 0.03);
}

TEST(ReferenceRefit, ABentReferenceIsPulledBackByTheScans) {
  const test::LoopRun run = StraightLoopRun();
  std::vector<RefitScan> scans = LoopScans(run);
  // Bend the reference: a 0.15 m sideways bump over 20 scans in the middle of the first side.
  for (int k = 20; k < 40; ++k) {
    fl::Pose2& p = scans[k].T_world_base_reference;
    p = p * fl::Pose2(0.0, 0.15, 0.0);
  }
  std::vector<fl::Pose2> bent;
  for (const RefitScan& s : scans) bent.push_back(s.T_world_base_reference);
  ASSERT_NEAR(MaxError(bent, run.truth), 0.15, 1e-9);
  const RefitResult r = RefitReference(scans, fl::Pose2(), Options(), Sigma(), RefitOptions());
  // The optimum is back at the truth, 0.15 m from the bent reference.
  EXPECT_LT(MaxError(r.T_world_base, run.truth), 0.03);
  EXPECT_GT(MaxError(r.T_world_base, bent), 0.12);
  EXPECT_LT(r.final_cost, 0.5 * r.initial_cost);
}

TEST(ReferenceRefit, BadInputIsAClearError) {
  const test::LoopRun run = StraightLoopRun();
  std::vector<RefitScan> scans = LoopScans(run);
  RefitOptions bad;
  bad.max_pairs = -1;
  EXPECT_FALSE(bad.Validate().ok());
  EXPECT_NE(bad.Validate().message().find("refit.max_pairs"), std::string::npos);
  EXPECT_THROW(RefitReference(scans, fl::Pose2(), Options(), Sigma(), bad), std::invalid_argument);
  EXPECT_THROW(RefitReference({scans[0]}, fl::Pose2(), Options(), Sigma(), RefitOptions()),
               std::invalid_argument);
  scans[5].scan.utime = scans[4].scan.utime;
  try {
    RefitReference(scans, fl::Pose2(), Options(), Sigma(), RefitOptions());
    FAIL() << "a repeated time stamp must be an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("scan 5"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace fl::rbpf
