#include "fusionloc/common/odometry_buffer.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace fl {
namespace {

TEST(OdometryBuffer, InterpolatesAtScanTime) {
  OdometryBuffer b;
  ASSERT_TRUE(b.Add(1000, fl::Pose2(0, 0, 3.0)).ok());
  ASSERT_TRUE(b.Add(2000, fl::Pose2(1, 2, -3.0)).ok());
  fl::Pose2 p;
  ASSERT_TRUE(b.Lookup(1500, &p).ok());
  EXPECT_NEAR(p.x, 0.5, 1e-12);
  EXPECT_NEAR(p.y, 1.0, 1e-12);
  // Shortest arc across ±π: halfway between 3.0 and -3.0 is π.
  EXPECT_NEAR(std::abs(p.theta), M_PI, 1e-9);
  ASSERT_TRUE(b.Lookup(2000, &p).ok());
  EXPECT_EQ(p.x, 1.0);
}

TEST(OdometryBuffer, RejectsBadInputWithAClearError) {
  OdometryBuffer b(10'000'000, 500'000);
  EXPECT_FALSE(b.Lookup(5, nullptr).ok());
  ASSERT_TRUE(b.Add(1000, fl::Pose2()).ok());
  const Status back = b.Add(900, fl::Pose2());
  EXPECT_FALSE(back.ok());
  EXPECT_NE(back.message().find("does not come after"), std::string::npos);
  EXPECT_FALSE(b.Add(2000, fl::Pose2(NAN, 0, 0)).ok());
  ASSERT_TRUE(b.Add(1'000'000, fl::Pose2(1, 0, 0)).ok());
  fl::Pose2 p;
  const Status gap = b.Lookup(500'000, &p);  // samples 1 s apart, max gap 0.5 s
  EXPECT_FALSE(gap.ok());
  EXPECT_NE(gap.message().find("gap"), std::string::npos);
  EXPECT_FALSE(b.Lookup(2'000'000, &p).ok());  // after the newest sample
}

}  // namespace
}  // namespace fl
