#include "fusionloc/rbpf_slam/scan_input.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace fl::rbpf {
namespace {

LaserScan Scan(Utime t, size_t beams = 3, double radstep = 0.1) {
  LaserScan s;
  s.utime = t;
  s.ranges.assign(beams, 1.0f);
  s.rad0 = -0.1;
  s.radstep = radstep;
  return s;
}

TEST(ScanInput, TheFirstScanSetsTheGeometryAndLaterStepsAreTheOdometryMotion) {
  ScanInput in;
  MotionOptions motion;
  ScanInput::Step step;
  Status error;
  ASSERT_EQ(in.Accept(Scan(1'000'000), Pose2(1, 2, 0.5), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  EXPECT_TRUE(step.first);
  EXPECT_TRUE(in.initialized());
  EXPECT_EQ(in.odom().x, 1.0);

  ASSERT_EQ(
      in.Accept(Scan(1'250'000), Pose2(1, 2, 0.5) * Pose2(0.3, 0, 0.1), motion, &step, &error),
      ScanInput::Verdict::kAccepted);
  EXPECT_FALSE(step.first);
  EXPECT_FALSE(step.odometry_jump);
  EXPECT_NEAR(step.dt_s, 0.25, 1e-12);
  EXPECT_NEAR(step.odometry_step.x, 0.3, 1e-12);
  EXPECT_NEAR(step.odometry_step.theta, 0.1, 1e-12);
  EXPECT_NEAR(in.odom().theta, 0.6, 1e-12);
  EXPECT_EQ(in.last_utime(), 1'250'000);
}

TEST(ScanInput, AJumpIsFlaggedAndNotAppliedAndTheNextStepCountsFromTheJumpedPose) {
  ScanInput in;
  MotionOptions motion;  // jump limits 3 m, 2 rad
  ScanInput::Step step;
  Status error;
  ASSERT_EQ(in.Accept(Scan(1), Pose2(0, 0, 0), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  ASSERT_EQ(in.Accept(Scan(2), Pose2(50, 0, 0), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  EXPECT_TRUE(step.odometry_jump);
  EXPECT_EQ(in.odom().x, 0.0);  // not moved
  ASSERT_EQ(in.Accept(Scan(3), Pose2(50.2, 0, 0), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  EXPECT_FALSE(step.odometry_jump);
  EXPECT_NEAR(in.odom().x, 0.2, 1e-12);
  ASSERT_EQ(in.Accept(Scan(4), Pose2(50.2, 0, 2.5), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  EXPECT_TRUE(step.odometry_jump);  // a rotation jump too
}

TEST(ScanInput, AcrossAGapInTheScansTheLimitsGrowWithTheTime) {
  MotionOptions motion;  // 3 m, 2 rad, or 2 m/s, 2 rad/s
  ScanInput in;
  ScanInput::Step step;
  Status error;
  ASSERT_EQ(in.Accept(Scan(1'000'000), Pose2(0, 0, 0), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  // 5 s without scans (a laser that stopped): 3.5 m and 2.5 rad of odometry are motion.
  ASSERT_EQ(in.Accept(Scan(6'000'000), Pose2(3.5, 0, 2.5), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  EXPECT_FALSE(step.odometry_jump);
  EXPECT_NEAR(in.odom().x, 3.5, 1e-12);
  // The same step 0.1 s later is a jump; so is 11 m after 5 s (2.2 m/s).
  ASSERT_EQ(in.Accept(Scan(6'100'000), Pose2(3.5, 0, 2.5) * Pose2(3.5, 0, 0), motion, &step,
                      &error),
            ScanInput::Verdict::kAccepted);
  EXPECT_TRUE(step.odometry_jump);
  ASSERT_EQ(in.Accept(Scan(11'100'000), Pose2(18.0, 0, 2.5), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  EXPECT_TRUE(step.odometry_jump);
  EXPECT_TRUE(motion.IsOdometryJump(Pose2(0, 0, 2.5), 1.0));
  EXPECT_FALSE(motion.IsOdometryJump(Pose2(0, 0, 2.5), 1.5));
  EXPECT_FALSE(motion.IsOdometryJump(Pose2(2.9, 0, 0), 0.0));
}

TEST(ScanInput, BadInputIsRefusedWithoutChangingState) {
  ScanInput in;
  MotionOptions motion;
  ScanInput::Step step;
  Status error;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(in.Accept(Scan(5), Pose2(nan, 0, 0), motion, &step, &error),
            ScanInput::Verdict::kBadInput);
  EXPECT_NE(error.message().find("not finite"), std::string::npos);
  EXPECT_EQ(in.Accept(Scan(5, 0), Pose2(), motion, &step, &error), ScanInput::Verdict::kBadInput);
  EXPECT_EQ(in.Accept(Scan(5, 3, 0.0), Pose2(), motion, &step, &error),
            ScanInput::Verdict::kBadInput);
  EXPECT_FALSE(in.initialized());

  ASSERT_EQ(in.Accept(Scan(10), Pose2(), motion, &step, &error), ScanInput::Verdict::kAccepted);
  EXPECT_EQ(in.Accept(Scan(10), Pose2(), motion, &step, &error),
            ScanInput::Verdict::kTimeBackwards);
  EXPECT_NE(error.message().find("does not come after"), std::string::npos);
  EXPECT_EQ(in.Accept(Scan(9), Pose2(), motion, &step, &error), ScanInput::Verdict::kTimeBackwards);
  const ScanInput::Verdict geometry = in.Accept(Scan(11, 4), Pose2(), motion, &step, &error);
  EXPECT_EQ(geometry, ScanInput::Verdict::kBadInput);
  EXPECT_NE(error.message().find("cannot change its geometry"), std::string::npos);
  EXPECT_EQ(in.last_utime(), 10);
  // The stamp did not advance: the next good scan is accepted.
  EXPECT_EQ(in.Accept(Scan(11), Pose2(), motion, &step, &error), ScanInput::Verdict::kAccepted);
}

TEST(ScanInput, StampsFarApartDoNotOverflowTheTimeStep) {
  ScanInput in;
  MotionOptions motion;
  ScanInput::Step step;
  Status error;
  ASSERT_EQ(in.Accept(Scan(std::numeric_limits<Utime>::min() + 1), Pose2(), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  ASSERT_EQ(in.Accept(Scan(std::numeric_limits<Utime>::max()), Pose2(), motion, &step, &error),
            ScanInput::Verdict::kAccepted);
  EXPECT_GT(step.dt_s, 0.0);
  EXPECT_TRUE(std::isfinite(step.dt_s));
}

}  // namespace
}  // namespace fl::rbpf
