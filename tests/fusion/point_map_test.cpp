#include "fusionloc/fusion/point_map.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <map>

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

TEST(FusionPointMap, FinalKeyframesOfAMappedViewAreDroppedAndTheMapStaysTheSame) {
  // Three laps of a 4 m circle, a keyframe every 0.2 m, each seeing the same 4 walls: once
  // final, about one lap of keyframes is left, and the built map is the same.
  PointMapOptions o;
  o.voxel_size_m = 0.1;
  PointMap merged(o), all(o);
  std::map<Utime, Pose2> poses;
  const double r = 4.0 / (2 * M_PI);
  const int per_lap = 20;
  for (int k = 0; k < 3 * per_lap; ++k) {
    const double a = 2 * M_PI * k / per_lap;
    const Pose2 T_map_base(r * std::sin(a), r * (1 - std::cos(a)), a);
    const Utime t = 1000 + 100 * k;
    poses[t] = T_map_base;
    // The walls x = +-3.03, y = +-3.03 of the map (off the voxel boundaries), in the base frame.
    std::vector<Eigen::Vector3f> points;
    for (int q = -30; q <= 30; ++q) {
      const double v = 0.1 * q + 0.03;
      for (const Eigen::Vector2d& w : {Eigen::Vector2d(3.03, v), Eigen::Vector2d(-3.03, v),
                                       Eigen::Vector2d(v, 3.03), Eigen::Vector2d(v, -3.03)}) {
        const Pose2 local = T_map_base.inverse() * Pose2(w.x(), w.y(), 0);
        points.emplace_back(local.x, local.y, 0.5f);
      }
    }
    ASSERT_TRUE(merged.AddKeyframe(t, points).ok());
    ASSERT_TRUE(all.AddKeyframe(t, points).ok());
  }
  auto pose_at = [&](Utime t, Pose2* p) {
    *p = poses.at(t);
    return true;
  };
  // Nothing is final yet: nothing merges.
  EXPECT_EQ(merged.MergeFinalKeyframes(pose_at, 0), 0);
  const int n = merged.MergeFinalKeyframes(pose_at, 1000 + 100 * 3 * per_lap);
  EXPECT_GT(n, per_lap);  // laps 2 and 3 merged (the first lap's keyframes 0.2 m apart too)
  EXPECT_EQ(merged.merged_keyframes(), n);
  EXPECT_LE(merged.num_keyframes(), per_lap);
  EXPECT_LT(merged.stored_points(), all.stored_points() / 2);
  const auto a = all.Build(pose_at), b = merged.Build(pose_at);
  ASSERT_FALSE(a.empty());
  EXPECT_NEAR(static_cast<double>(b.size()), static_cast<double>(a.size()), 0.05 * a.size());
  // Every merged-map point is on a wall.
  for (const auto& p : b) {
    const float d =
        std::min(std::fabs(std::fabs(p.x()) - 3.03f), std::fabs(std::fabs(p.y()) - 3.03f));
    EXPECT_LT(d, 0.1f) << p.transpose();
  }
}

TEST(FusionPointMap, ASavedMapComesBackTheSame) {
  PointMapOptions o;
  o.voxel_size_m = 0.1;
  o.merge_spacing_m = 0.5;
  PointMap map(o);
  for (int k = 0; k < 6; ++k) {
    std::vector<Eigen::Vector3f> points;
    for (int i = 0; i < 50; ++i) points.emplace_back(1.0f + 0.1f * i, 0.3f * k, 0.5f);
    points.emplace_back(NAN, 0.0f, 0.0f);  // dropped, counted
    ASSERT_TRUE(map.AddKeyframe(100 * (k + 1), points).ok());
  }
  const auto pose_at = [](Utime t, Pose2* p) {
    *p = Pose2(t < 400 ? 0.0 : 0.1, 0.0, 0.0);  // 400-600 revisit the place of 100
    return true;
  };
  ASSERT_GT(map.MergeFinalKeyframes(pose_at, 450), 0);
  StateWriter w;
  map.SaveState(&w);
  const std::vector<uint8_t> bytes = w.Release();
  PointMap loaded(o);
  StateReader r(bytes.data(), bytes.size());
  loaded.LoadState(&r);
  EXPECT_EQ(loaded.num_keyframes(), map.num_keyframes());
  EXPECT_EQ(loaded.stored_points(), map.stored_points());
  EXPECT_EQ(loaded.dropped_points(), map.dropped_points());
  EXPECT_EQ(loaded.merged_keyframes(), map.merged_keyframes());
  EXPECT_EQ(loaded.Build(pose_at), map.Build(pose_at));
  // The kept final keyframes came back too: the same merges follow.
  EXPECT_EQ(loaded.MergeFinalKeyframes(pose_at, 700), map.MergeFinalKeyframes(pose_at, 700));
  EXPECT_EQ(loaded.num_keyframes(), map.num_keyframes());
  // Truncated: refused, the map unchanged.
  StateReader t(bytes.data(), bytes.size() - 1);
  EXPECT_THROW(loaded.LoadState(&t), StateError);
  EXPECT_EQ(loaded.num_keyframes(), map.num_keyframes());
}

}  // namespace
}  // namespace fl::fusion
