#include "fusionloc/common/message_checks.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

namespace fl {
namespace {

const double kNan = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

TEST(MessageChecks, SaneMessagesPass) {
  bot_core::pose_t pose{};
  pose.orientation[0] = 1.0;
  EXPECT_EQ(BadField(pose), "");
  fusionloc::wheel_odometry_t odo{};
  odo.left_ticks = 1e9;  // large but real
  EXPECT_EQ(BadField(odo), "");
  fusionloc::relative_pose_factor_t f{};
  f.information[0] = 1e12;  // a very confident factor
  EXPECT_EQ(BadField(f), "");
  fusionloc::trajectory_t t{};
  t.x = {1.0, 2.0};
  EXPECT_EQ(BadField(t), "");
}

// A static transform's stamp is not used by its consumers, so the edge judges it: a mounting
// stamped before 1970 or beyond 2^61 us is from a broken sender; 0 (a static transform's usual
// stamp) is fine.
TEST(MessageChecks, AStaticTransformWithAnImpossibleStampIsNamed) {
  bot_core::rigid_transform_t tf{};
  tf.quat[0] = 1.0;
  EXPECT_EQ(BadField(tf), "");
  tf.utime = 1000000000000000;
  EXPECT_EQ(BadField(tf), "");
  tf.utime = -1;
  EXPECT_EQ(BadField(tf), "utime = -1");
  tf.utime = kMaxStampUs;
  EXPECT_EQ(BadField(tf), "utime = " + std::to_string(kMaxStampUs));
}

TEST(MessageChecks, EachBadValueIsNamedWithItsField) {
  for (const double bad : {kNan, kInf, -kInf, 1e30}) {
    bot_core::pose_t pose{};
    pose.vel[2] = bad;  // a field no consumer reads is still a broken sender
    EXPECT_EQ(BadField(pose).rfind("vel[2] = ", 0), 0u) << BadField(pose);
    bot_core::rigid_transform_t tf{};
    tf.quat[3] = bad;
    EXPECT_EQ(BadField(tf).rfind("quat[3] = ", 0), 0u);
    fusionloc::wheel_odometry_t odo{};
    odo.omega = bad;
    EXPECT_EQ(BadField(odo).rfind("omega = ", 0), 0u);
    fusionloc::stereo_calibration_t cal{};
    cal.cx = bad;
    EXPECT_EQ(BadField(cal).rfind("cx = ", 0), 0u);
    fusionloc::relative_pose_factor_t f{};
    f.information[35] = bad;
    EXPECT_EQ(BadField(f).rfind("information[35] = ", 0), 0u);
    fusionloc::fused_pose_t fp{};
    fp.covariance[4] = bad;
    EXPECT_EQ(BadField(fp).rfind("covariance[4] = ", 0), 0u);
    fusionloc::trajectory_t t{};
    t.theta = {0.0, bad};
    EXPECT_EQ(BadField(t).rfind("theta[1] = ", 0), 0u);
    fusionloc::point_cloud_t pc{};
    pc.points = {{0.f, 0.f, 1.f}, {0.f, static_cast<float>(bad), 1.f}};
    EXPECT_EQ(BadField(pc).rfind("points[1][1] = ", 0), 0u) << BadField(pc);
    pc.points = {{0.f, 0.f, 1.f}};
    pc.intensities = {static_cast<float>(bad)};
    EXPECT_EQ(BadField(pc).rfind("intensities[0] = ", 0), 0u);
    bot_core::planar_lidar_t scan{};
    scan.radstep = static_cast<float>(bad);
    EXPECT_EQ(BadField(scan).rfind("radstep = ", 0), 0u);
  }
  fusionloc::wheel_odometry_t odo{};
  odo.x = kNan;
  EXPECT_EQ(BadField(odo), "x = nan");
}

TEST(MessageChecks, LaserBeamsWithoutAReturnAreNotErrors) {
  // REP 117: +inf, -inf and NaN ranges are beams without a return; the consumers skip them.
  bot_core::planar_lidar_t scan{};
  scan.rad0 = -1.0f;
  scan.radstep = 0.01f;
  scan.ranges = {1.0f, static_cast<float>(kInf), static_cast<float>(kNan),
                 static_cast<float>(-kInf)};
  scan.intensities = {static_cast<float>(kNan)};
  EXPECT_EQ(BadField(scan), "");
}

}  // namespace
}  // namespace fl
