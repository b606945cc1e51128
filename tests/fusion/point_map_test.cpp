#include "fusionloc/fusion/point_map.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace fl::fusion {
namespace {

TEST(FusionPointMap, PlacesKeyframesByPoseAndVoxelFilters) {
  PointMapOptions o;
  o.voxel_size_m = 0.1;
  PointMap map(o);
  // Keyframe 1: 1000 points within one 10 cm voxel at (1.02, 0.02, 0.02) in the base frame.
  std::vector<Eigen::Vector3f> dense;
  for (int k = 0; k < 1000; ++k) dense.emplace_back(1.02f + 0.00005f * k, 0.02f, 0.02f);
  ASSERT_TRUE(map.AddKeyframe(100, dense).ok());
  // Keyframe 2: one point 1 m ahead, but the robot has turned left by 90 degrees.
  ASSERT_TRUE(map.AddKeyframe(200, {Eigen::Vector3f(1.0f, 0.0f, 0.5f)}).ok());
  EXPECT_EQ(map.num_keyframes(), 2);
  EXPECT_EQ(map.stored_points(), 2);  // thinned on arrival
  int skipped = -1;
  const auto points = map.Build(
      [](Utime t, Pose2* p) {
        *p = t == 100 ? Pose2(0, 0, 0) : Pose2(5.0, 0.0, M_PI / 2);
        return true;
      },
      &skipped);
  EXPECT_EQ(skipped, 0);
  ASSERT_EQ(points.size(), 2u);
  bool found_turned = false;
  for (const auto& p : points) {
    if (std::fabs(p.x() - 5.0f) < 1e-4 && std::fabs(p.y() - 1.0f) < 1e-4) found_turned = true;
  }
  EXPECT_TRUE(found_turned);
  // A keyframe without a pose is skipped and counted.
  const auto none = map.Build(
      [](Utime t, Pose2* p) {
        *p = Pose2();
        return t == 100;
      },
      &skipped);
  EXPECT_EQ(skipped, 1);
  EXPECT_EQ(none.size(), 1u);
}

// Found by fuzzing the fusion node (tests/fuzz/regressions/fusion_node/huge-pose-voxel-key):
// a keyframe placed at a huge or non-finite pose (from corrupt RBPF_POSE / factor values)
// gave infinite map points, whose voxel-tile index was an out-of-range cast (undefined
// behaviour). Such keyframes are skipped and counted; the rest of the map is built.
TEST(FusionPointMap, KeyframesAtAbsurdPosesAreSkipped) {
  PointMap map(PointMapOptions{});
  for (Utime t : {1, 2, 3, 4}) ASSERT_TRUE(map.AddKeyframe(t, {Eigen::Vector3f(1, 0, 0)}).ok());
  int skipped = -1;
  const auto points = map.Build(
      [](Utime t, Pose2* p) {
        if (t == 1) *p = Pose2(1e300, 0, 0);
        if (t == 2) *p = Pose2(0, -1e7, 0);
        if (t == 3) *p = Pose2(0, 0, std::nan(""));
        if (t == 4) *p = Pose2(2, 0, 0);
        return true;
      },
      &skipped);
  EXPECT_EQ(skipped, 3);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_NEAR(points[0].x(), 3.0f, 0.1f);
}

TEST(FusionPointMap, BadPointsAndDuplicateKeyframesAreRejected) {
  PointMap map(PointMapOptions{});
  const float nan = std::nanf("");
  ASSERT_TRUE(map.AddKeyframe(1, {Eigen::Vector3f(nan, 0, 0), Eigen::Vector3f(100, 0, 0),
                                  Eigen::Vector3f(1, 0, 0)})
                  .ok());
  EXPECT_EQ(map.dropped_points(), 2);  // NaN and beyond max_range_m
  EXPECT_FALSE(map.AddKeyframe(1, {Eigen::Vector3f(1, 0, 0)}).ok());
  PointMapOptions bad;
  bad.voxel_size_m = 0.0;
  EXPECT_FALSE(bad.Validate().ok());
  EXPECT_THROW(PointMap m(bad), std::invalid_argument);
}

}  // namespace
}  // namespace fl::fusion
