// Laser and camera models against analytic geometry.
#include "fusionloc/sim/sensors.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace fl::sim {
namespace {

// A single long wall along the line x = wall_x.
World WallWorld(double wall_x) {
  World w;
  w.AddWall({{wall_x, -50.0}, {wall_x, 50.0}, 2.5, Texture::kBrick, 7});
  return w;
}

TEST(LaserModelTest, RangesMatchAnalyticWallDistance) {
  const World world = WallWorld(5.0);
  LaserOptions o;
  LaserModel laser(o);
  for (const Pose2& pose : {Pose2(0, 0, 0), Pose2(1.0, 2.0, 0.3), Pose2(-2.0, -1.0, -0.7)}) {
    std::vector<float> ranges;
    laser.TrueRanges(world, pose, &ranges);
    ASSERT_EQ(ranges.size(), 682u);
    const Pose2 T_world_laser = pose * Pose2(o.x_m, o.y_m, 0.0);
    int returns = 0;
    for (int i = 0; i < o.beams; ++i) {
      const double a = T_world_laser.theta + laser.BeamAngle(i);
      // Distance along the beam to the line x = 5 (positive only when the beam points at it).
      double expected = 0.0;
      if (std::cos(a) > 1e-9) {
        const double t = (5.0 - T_world_laser.x) / std::cos(a);
        if (t <= o.max_range_m) expected = t;
      }
      ASSERT_NEAR(ranges[i], expected, 1e-5) << "beam " << i << " pose " << pose.x;
      returns += expected > 0;
    }
    EXPECT_GT(returns, 50);
    EXPECT_LT(returns, 682);  // beams beyond 10 m and those facing away see nothing
  }
}

TEST(LaserModelTest, PillarAndNoReturnBeyondMaxRange) {
  World world;
  world.AddPillar({{4.0, 0.0}, 0.5, 2.5, Texture::kChecker, 1});
  LaserOptions o;
  LaserModel laser(o);
  std::vector<float> ranges;
  laser.TrueRanges(world, Pose2(0, 0, 0), &ranges);
  // Beam 341 points at +0.032 deg, nearly straight ahead: 4 - 0.5 - 0.15 m.
  const int ahead = static_cast<int>(std::lround(-o.first_angle_deg / o.step_deg));
  EXPECT_NEAR(ranges[ahead], 3.35, 1e-3);
  EXPECT_EQ(ranges[0], 0.0f);  // nothing to the side: "no return" is 0

  const World far = WallWorld(12.0);
  laser.TrueRanges(far, Pose2(0, 0, 0), &ranges);
  for (float r : ranges) EXPECT_EQ(r, 0.0f);
}

TEST(LaserModelTest, RangeNoiseHasConfiguredSigma) {
  const World world = WallWorld(5.0);
  LaserOptions o;
  o.range_sigma_m = 0.1;
  LaserModel laser(o);
  Rng rng(5);
  std::vector<float> truth, noisy;
  laser.TrueRanges(world, Pose2(0, 0, 0), &truth);
  double sum = 0, sum2 = 0;
  int n = 0;
  for (int scan = 0; scan < 60; ++scan) {
    laser.Scan(world, Pose2(0, 0, 0), &rng, &noisy);
    for (size_t i = 0; i < truth.size(); ++i) {
      ASSERT_EQ(truth[i] > 0, noisy[i] > 0) << "noise must not create or remove returns";
      if (truth[i] <= 0) continue;
      const double e = noisy[i] - truth[i];
      sum += e, sum2 += e * e, ++n;
    }
  }
  ASSERT_GT(n, 10000);
  EXPECT_NEAR(sum / n, 0.0, 0.004);
  EXPECT_NEAR(std::sqrt(sum2 / n), 0.1, 0.005);
}

TEST(Laser3dModelTest, PointsLieOnTheWallAndTheFloor) {
  // A 2.5 m wall at x = 5 and the floor: every noise-free point is on one of them, at the
  // azimuth and elevation of its beam; the upward lines above the wall's top see nothing.
  const World world = WallWorld(5.0);
  Laser3dOptions o;
  o.enabled = true;
  const Laser3dModel laser(o);
  const Pose2 pose(0.5, -1.0, 0.2);
  std::vector<Eigen::Vector3f> points;
  laser.Scan(world, pose, nullptr, &points);
  const Pose2 T_world_laser = pose * Pose2(o.x_m, o.y_m, 0.0);
  int on_wall = 0, on_floor = 0;
  for (const Eigen::Vector3f& p : points) {
    const Eigen::Vector2d xy = T_world_laser * Eigen::Vector2d(p.x(), p.y());
    const double z = o.z_m + p.z();
    if (std::abs(xy.x() - 5.0) < 1e-4) {
      ++on_wall;
      EXPECT_GE(z, -1e-4);
      EXPECT_LE(z, 2.5 + 1e-4);
    } else {
      ++on_floor;
      EXPECT_NEAR(z, 0.0, 1e-4) << "neither on the wall nor on the floor: " << p.transpose();
      EXPECT_LT(xy.x(), 5.0);
    }
    const double range = p.cast<double>().norm();
    EXPECT_GE(range, o.min_range_m);
    EXPECT_LE(range, o.max_range_m);
  }
  EXPECT_GT(on_wall, 500);
  EXPECT_GT(on_floor, 500);
  // Straight ahead on the level-most line (elevation -1 deg of 16 lines over 30 deg): the wall
  // at (5 - x_laser) / cos(heading) horizontally.
  const int line = 7;
  const double e = laser.LineElevation(line);
  EXPECT_NEAR(e, (-15.0 + 30.0 * 7 / 15) * M_PI / 180.0, 1e-12);
  std::vector<Eigen::Vector3f> only;
  Laser3dOptions one = o;
  one.lines = 1;
  one.vertical_fov_deg = 0.0;
  Laser3dModel(one).Scan(world, Pose2(0, 0, 0), nullptr, &only);
  ASSERT_FALSE(only.empty());
  EXPECT_NEAR(only.front().x(), 5.0 - o.x_m, 1e-4);  // azimuth 0 first
  EXPECT_NEAR(only.front().y(), 0.0, 1e-6);
}

TEST(Laser3dModelTest, RangeNoiseAlongTheBeamIsSeeded) {
  const World world = WallWorld(5.0);
  Laser3dOptions o;
  o.enabled = true;
  const Laser3dModel laser(o);
  std::vector<Eigen::Vector3f> exact, a, b;
  laser.Scan(world, Pose2(0, 0, 0), nullptr, &exact);
  Rng rng1(3), rng2(3);
  laser.Scan(world, Pose2(0, 0, 0), &rng1, &a);
  laser.Scan(world, Pose2(0, 0, 0), &rng2, &b);
  ASSERT_EQ(a.size(), exact.size());
  EXPECT_EQ(a, b);
  double sum2 = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const double d = a[i].cast<double>().norm() - exact[i].cast<double>().norm();
    sum2 += d * d;
    // Along the beam: the direction is unchanged.
    EXPECT_LT((a[i].normalized() - exact[i].normalized()).norm(), 1e-5);
  }
  EXPECT_NEAR(std::sqrt(sum2 / a.size()), o.range_sigma_m, 0.1 * o.range_sigma_m);
}

TEST(CameraModelTest, DepthAtKnownPixels) {
  const World world = WallWorld(5.0);
  CameraOptions o;
  CameraModel camera(o);
  // Robot at the origin facing the wall: the wall is fronto-parallel, depth 5 - 0.2 everywhere
  // on it. Row 100 is above the horizon (wall), row 400 sees the floor.
  std::vector<float> depth;
  camera.RenderDepth(world, Pose2(0, 0, 0), CameraModel::kLeft, &depth);
  ASSERT_EQ(depth.size(), 640u * 480u);
  EXPECT_NEAR(depth[100 * 640 + 320], 4.8, 1e-5);
  EXPECT_NEAR(depth[100 * 640 + 10], 4.8, 1e-5);
  EXPECT_NEAR(depth[400 * 640 + 320], 0.5 / ((400 - 239.5) / 400.0), 1e-5);  // floor
  // Above the 2.5 m wall top: sky (no ceiling in this world).
  EXPECT_TRUE(std::isinf(depth[0 * 640 + 320]));

  // Turned by 0.3 rad: depth along the optical axis of the ray through pixel (u, 200).
  const Pose2 pose(0.5, -1.0, 0.3);
  camera.RenderDepth(world, pose, CameraModel::kRight, &depth);
  const Eigen::Vector3d c = camera.CameraCenterWorld(pose, CameraModel::kRight);
  for (int u : {0, 100, 320, 500, 639}) {
    const double lateral = -(u - o.cx) / o.fx;  // left component per unit depth
    const double dir_x = std::cos(pose.theta) - lateral * std::sin(pose.theta);
    const double expected = (5.0 - c.x()) / dir_x;
    EXPECT_NEAR(depth[200 * 640 + u], expected, 1e-4) << "u = " << u;
  }
}

TEST(CameraModelTest, BoxLidSeenFromAbove) {
  World world;
  world.AddBox({{3.0, 0.0}, {0.5, 0.5}, 0.0, 0.3, Texture::kBlocks, 3});  // low box
  CameraOptions o;
  CameraModel camera(o);
  std::vector<float> depth;
  camera.RenderDepth(world, Pose2(0, 0, 0), CameraModel::kLeft, &depth);
  // Front face at x = 2.5 (depth 2.3) spans rows where 0.5 + up * 2.3 in [0, 0.3].
  // Face rows: 239.5 + [0.2, 0.5] / 2.3 * 400 = [274.3, 326.4].
  const int v_face = 300;
  EXPECT_NEAR(depth[v_face * 640 + 320], 2.3, 1e-5);
  // A ray just above the front face top meets the lid z = 0.3 before the back face.
  const int v_lid = static_cast<int>(std::lround(239.5 + 0.2 / 2.3 * 400 - 3));
  const double up = -(v_lid - 239.5) / 400.0;
  EXPECT_NEAR(depth[v_lid * 640 + 320], (0.5 - 0.3) / -up, 1e-5);
}

TEST(CameraModelTest, RightImageIsLeftShiftedByDisparity) {
  // A fronto-parallel wall at depth Z is seen with disparity fx * B / Z: 400 * 0.12 / 4.8 = 10
  // px. With the right camera to the right (+x optical) of the left one, a wall point at column
  // u in the left image is at column u - 10 in the right image.
  const World world = WallWorld(5.0);
  CameraOptions o;
  CameraModel camera(o);
  std::vector<uint8_t> left, right;
  camera.Render(world, Pose2(0, 0, 0), CameraModel::kLeft, nullptr, &left);
  camera.Render(world, Pose2(0, 0, 0), CameraModel::kRight, nullptr, &right);
  int same = 0, total = 0;
  for (int v = 200; v < 230; ++v) {  // wall rows
    for (int u = 20; u < 620; ++u) {
      same += std::abs(left[v * 640 + u] - right[v * 640 + u - 10]) <= 1;
      ++total;
    }
  }
  EXPECT_GT(same, 0.99 * total);
  // And not by a shift of the wrong sign.
  int wrong = 0;
  for (int v = 200; v < 230; ++v) {
    for (int u = 20; u < 620; ++u) wrong += std::abs(left[v * 640 + u] - right[v * 640 + u + 10]) <= 1;
  }
  EXPECT_LT(wrong, 0.8 * total);
}

TEST(CameraModelTest, NoiseIsSeededAndHasConfiguredSigma) {
  const World world = WallWorld(5.0);
  CameraOptions o;
  o.pixel_noise_sigma = 4.0;
  CameraModel camera(o);
  std::vector<uint8_t> clean, a, b;
  camera.Render(world, Pose2(0, 0, 0), CameraModel::kLeft, nullptr, &clean);
  Rng r1(3), r2(3);
  camera.Render(world, Pose2(0, 0, 0), CameraModel::kLeft, &r1, &a);
  camera.Render(world, Pose2(0, 0, 0), CameraModel::kLeft, &r2, &b);
  EXPECT_EQ(a, b);
  double sum2 = 0;
  int n = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (clean[i] < 20 || clean[i] > 235) continue;  // away from clamping
    const double e = static_cast<double>(a[i]) - clean[i];
    sum2 += e * e, ++n;
  }
  // Rounding adds 1/12 gray level^2 of variance.
  EXPECT_NEAR(std::sqrt(sum2 / n), std::sqrt(16.0 + 1.0 / 12), 0.15);
}

}  // namespace
}  // namespace fl::sim
