#include "fusionloc/viewer/decimate.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace fl::viewer {
namespace {

TEST(VoxelSet, KeepsTheFirstPointOfEachVoxelAndReportsOnlyNewOnes) {
  VoxelSet set(0.1);
  // Three points in voxel (0,0,0), one in (1,0,0), one in (-1,0,0) (negative side), one NaN.
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<float> a = {0.01f, 0.02f, 0.03f, 0.05f, 0.05f, 0.05f, 0.09f, 0.0f, 0.0f,
                                0.15f, 0.0f,  0.0f,  -0.05f, 0.0f, 0.0f, nan,  0.0f, 0.0f};
  std::vector<float> kept;
  EXPECT_EQ(set.Add(a.data(), a.size() / 3, &kept), 3u);
  ASSERT_EQ(kept.size(), 9u);
  EXPECT_FLOAT_EQ(kept[0], 0.01f);  // the first of voxel (0,0,0)
  EXPECT_FLOAT_EQ(kept[3], 0.15f);
  EXPECT_FLOAT_EQ(kept[6], -0.05f);
  // Again: nothing new; one point in a new voxel: just that one.
  kept.clear();
  EXPECT_EQ(set.Add(a.data(), a.size() / 3, &kept), 0u);
  const std::vector<float> b = {0.02f, 0.02f, 0.02f, 0.0f, 0.0f, 0.35f};
  EXPECT_EQ(set.Add(b.data(), 2, &kept), 1u);
  ASSERT_EQ(kept.size(), 3u);
  EXPECT_FLOAT_EQ(kept[2], 0.35f);
  EXPECT_EQ(set.size(), 4u);
}

TEST(VoxelDecimate, ADenseCloudShrinksToOnePointPerVoxel) {
  // A 1 m cube sampled every 1 cm: 100^3 points, 10^3 voxels of 10 cm.
  std::vector<float> xyz;
  for (int i = 0; i < 100; ++i)
    for (int j = 0; j < 100; ++j)
      for (int k = 0; k < 100; ++k) xyz.insert(xyz.end(), {i * 0.01f + 0.005f, j * 0.01f + 0.005f, k * 0.01f + 0.005f});
  const std::vector<float> out = VoxelDecimate(xyz.data(), xyz.size() / 3, 0.1);
  EXPECT_EQ(out.size() / 3, 1000u);
}

TEST(TrailDecimator, ThinsByTimeAndMotionAndRestartsWhenTimeGoesBack) {
  TrailDecimator d(0.1, 0.02, 0.02);
  EXPECT_TRUE(d.Accept({0, 0, 0, 0, 0}));
  EXPECT_FALSE(d.Accept({50000, 1, 0, 0, 0}));    // too soon (0.05 s)
  EXPECT_FALSE(d.Accept({200000, 0.01, 0, 0, 0}));  // standing still (1 cm)
  EXPECT_TRUE(d.Accept({200000, 0.0, 0, 0, 0.05}));   // turned
  EXPECT_TRUE(d.Accept({300000, 0.5, 0, 0, 0.05}));   // moved
  bool restart = false;
  EXPECT_TRUE(d.Accept({100000, 0.5, 0, 0, 0.05}, &restart));  // a seek back
  EXPECT_TRUE(restart);
}

TEST(DecimateTrajectory, KeepsEndsAndOnePosePerDistance) {
  std::vector<ViewPose> poses;
  for (int i = 0; i <= 1000; ++i) poses.push_back({i, i * 0.001, 0, 0, 0});  // 1 m, 1 mm steps
  const std::vector<ViewPose> out = DecimateTrajectory(poses, 0.05, 0.1);
  ASSERT_GE(out.size(), 20u);
  EXPECT_LE(out.size(), 22u);
  EXPECT_EQ(out.front().utime, 0);
  EXPECT_EQ(out.back().utime, 1000);
  EXPECT_TRUE(DecimateTrajectory({}, 0.05, 0.1).empty());
  EXPECT_EQ(DecimateTrajectory({poses[0]}, 0.05, 0.1).size(), 1u);
}

}  // namespace
}  // namespace fl::viewer
