// World geometry: ray casting primitives, distances, textures and the two built worlds.
#include "fusionloc/sim/world.hpp"

#include "fusionloc/sim/sensors.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace fl::sim {
namespace {

TEST(WorldTest, CastHitsNearestShapeAboveRayHeight) {
  World w;
  w.AddWall({{5, -1}, {5, 1}, 2.5, Texture::kBrick, 1});
  w.AddBox({{3, 0}, {0.5, 0.5}, 0.0, 0.2, Texture::kBlocks, 2});  // lower than the ray
  w.AddPillar({{8, 0}, 0.5, 2.5, Texture::kChecker, 3});
  RayHit hit;
  ASSERT_TRUE(w.CastHorizontal({0, 0}, {1, 0}, 0.3, 0.0, &hit));
  EXPECT_NEAR(hit.t_in, 5.0, 1e-12);  // the low box is passed over
  EXPECT_EQ(hit.shape, 0);
  ASSERT_TRUE(w.CastHorizontal({0, 0}, {1, 0}, 0.1, 0.0, &hit));
  EXPECT_NEAR(hit.t_in, 2.5, 1e-12);  // at 0.1 m the box is in the way
  EXPECT_NEAR(hit.t_out, 3.5, 1e-12);
  EXPECT_NEAR(hit.normal_x, -1.0, 1e-12);
  ASSERT_TRUE(w.CastHorizontal({6, 0}, {1, 0}, 1.0, 0.0, &hit));
  EXPECT_NEAR(hit.t_in, 1.5, 1e-12);  // pillar front at x = 7.5
  EXPECT_FALSE(w.CastHorizontal({0, 0}, {-1, 0}, 1.0, 0.0, &hit));
  // Non-unit direction: t is in units of the direction's length.
  ASSERT_TRUE(w.CastHorizontal({0, 0}, {2, 0}, 1.0, 0.0, &hit));
  EXPECT_NEAR(hit.t_in, 2.5, 1e-12);
}

TEST(WorldTest, RotatedBoxAndDistances) {
  World w;
  w.AddBox({{0, 0}, {1.0, 0.5}, M_PI / 2, 1.0, Texture::kBlocks, 1});  // long side along y
  RayHit hit;
  ASSERT_TRUE(w.CastHorizontal({-3, 0}, {1, 0}, 0.5, 0.0, &hit));
  EXPECT_NEAR(hit.t_in, 2.5, 1e-9);
  ASSERT_TRUE(w.CastHorizontal({0, -3}, {0, 1}, 0.5, 0.0, &hit));
  EXPECT_NEAR(hit.t_in, 2.0, 1e-9);
  EXPECT_NEAR(w.DistanceToObstacles({-3, 0}), 2.5, 1e-9);
  EXPECT_NEAR(w.DistanceToObstacles({1.5, 2.0}), std::hypot(1.0, 1.0), 1e-9);
  w.AddPillar({{5, 0}, 0.5, 2.0, Texture::kChecker, 2});
  EXPECT_NEAR(w.DistanceToObstacles({7, 0}), 1.5, 1e-9);
}

TEST(WorldTest, TexturesAreDeterministicWithCorners) {
  for (Texture t : {Texture::kBrick, Texture::kBlocks, Texture::kPosterWall, Texture::kFloorTiles,
                    Texture::kCeiling, Texture::kChecker}) {
    double lo = 255, hi = 0;
    for (int i = 0; i < 400; ++i) {
      const double u = 0.037 * i, v = 0.011 * i + 0.3;
      const double a = TextureIntensity(t, 42, u, v);
      EXPECT_EQ(a, TextureIntensity(t, 42, u, v));
      EXPECT_GE(a, 0.0);
      EXPECT_LE(a, 255.0);
      lo = std::min(lo, a), hi = std::max(hi, a);
    }
    EXPECT_GT(hi - lo, 60.0) << "texture " << static_cast<int>(t) << " lacks contrast";
  }
  EXPECT_NE(Hash3(1, 2, 3), Hash3(1, 3, 2));
  EXPECT_NE(Hash3(1, 2, 3), Hash3(2, 2, 3));
}

TEST(WorldTest, PaperWorldLayout) {
  SimOptions o;
  const World w = World::Build(o);
  EXPECT_EQ(w.name(), "paper");
  EXPECT_EQ(w.walls().size(), 4u);
  EXPECT_EQ(static_cast<int>(w.boxes().size() + w.pillars().size()), o.world.landmarks);
  const Eigen::Vector4d b = w.Bounds();
  EXPECT_NEAR(b[0], -15.0, 1e-9);
  EXPECT_NEAR(b[3], 15.0, 1e-9);
  EXPECT_EQ(w.route().front(), Eigen::Vector2d(0, 0));
  // Landmarks keep the configured clearance from the route line.
  for (const Pillar& p : w.pillars()) {
    World one;
    one.AddPillar(p);
    for (size_t i = 0; i < w.route().size(); ++i) {
      const Eigen::Vector2d a = w.route()[i], c = w.route()[(i + 1) % w.route().size()];
      for (double s = 0; s <= 1.0; s += 0.01) {
        EXPECT_GE(one.DistanceToObstacles(a + s * (c - a)), o.world.route_clearance_m - 1e-9);
      }
    }
  }
  // Another seed, another layout; same seed, same layout.
  SimOptions o2 = o;
  o2.seed = 2;
  EXPECT_NE(World::Build(o2).pillars().front().center, w.pillars().front().center);
  EXPECT_EQ(World::Build(o).pillars().front().center, w.pillars().front().center);
}

TEST(WorldTest, TooManyLandmarksIsAClearError) {
  SimOptions o;
  o.world.landmarks = 1000;
  o.world.route_clearance_m = 5.0;
  try {
    World::Build(o);
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("world.landmarks"), std::string::npos) << e.what();
  }
}

TEST(WorldTest, CorridorWorldIsLongWithSmoothWalls) {
  SimOptions o = DefaultOptionsForWorld("corridor");
  const World w = World::Build(o);
  EXPECT_EQ(w.name(), "corridor");
  const Eigen::Vector4d b = w.Bounds();
  EXPECT_GE(b[2] - b[0], 40.0);
  EXPECT_GT(w.ceiling_height(), 0.0);
  // In the middle stretch of the corridor the laser sees only the two parallel side walls:
  // every return lies on y = +-width/2 (nothing constrains motion along the corridor).
  LaserModel laser(o.laser);
  std::vector<float> ranges;
  for (double x : {-10.0, -8.0, -5.0}) {
    laser.TrueRanges(w, Pose2(x, 0.3, 0.1), &ranges);
    const Pose2 T_world_laser = Pose2(x, 0.3, 0.1) * Pose2(o.laser.x_m, o.laser.y_m, 0.0);
    int returns = 0;
    for (int i = 0; i < o.laser.beams; ++i) {
      if (ranges[i] <= 0) continue;
      ++returns;
      const double a = T_world_laser.theta + laser.BeamAngle(i);
      const double y = T_world_laser.y + ranges[i] * std::sin(a);
      EXPECT_NEAR(std::fabs(y), 0.5 * o.world.corridor_width_m, 1e-4) << "x " << x << " beam " << i;
    }
    EXPECT_GT(returns, 500);
  }
  // Three rooms: walls at |y| > corridor half width.
  int room_walls = 0;
  for (const Wall& wall : w.walls()) room_walls += std::fabs(wall.b.y()) > 2.0;
  EXPECT_GE(room_walls, 6);
}

}  // namespace
}  // namespace fl::sim
