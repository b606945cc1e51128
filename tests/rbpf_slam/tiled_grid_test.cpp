#include "fusionloc/rbpf_slam/tiled_grid.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <random>
#include <vector>

namespace fl::rbpf {
namespace {

GridOptions Opts() {
  GridOptions o;
  o.resolution = 0.05;
  o.field_max_distance = 0.4;
  return o;
}

// Makes cell (cx, cy) an obstacle (one hit is above the threshold).
void MakeObstacle(TiledGrid* g, int cx, int cy) { g->UpdateCell(cx, cy, 300); }

// Found by fuzzing the RBPF node (tests/fuzz/regressions/rbpf_node/far-origin-cell-cast): a
// pose from corrupt odometry 4e8 m away made the scan origin's cell index an out-of-range int
// cast (undefined behaviour). A scan from beyond kMaxCellIndex cells is left out, and so is a
// beam to there; the rest of a scan is integrated.
TEST(TiledGrid, ScansFromOrToAbsurdPlacesAreLeftOut) {
  TiledGrid g(Opts());
  g.IntegrateScan({4.3e8, 0.0}, {{4.3e8 + 1.0, 0.0}}, {1});
  g.IntegrateScan({std::nan(""), 0.0}, {{1.0, 0.0}}, {1});
  EXPECT_EQ(g.NumTiles(), 0);
  g.IntegrateScan({0.0, 0.0}, {{1.0, 0.0}, {0.0, -1e12}, {0.0, INFINITY}}, {1, 1, 0});
  EXPECT_TRUE(g.IsOccupied(20, 0));  // the good beam's end
  TiledGrid only_good(Opts());
  only_good.IntegrateScan({0.0, 0.0}, {{1.0, 0.0}}, {1});
  EXPECT_EQ(g.NumTiles(), only_good.NumTiles());
}

TEST(TiledGrid, AScanThatWouldGrowTheMapBeyondItsMaximumSizeIsRefused) {
  GridOptions o = Opts();
  o.max_size_m = 100.0;
  TiledGrid g(o);
  ASSERT_TRUE(g.IntegrateScan({0.0, 0.0}, {{1.0, 0.0}}, {1}));
  const int tiles = g.NumTiles();
  int x0, y0, x1, y1;
  ASSERT_TRUE(g.Bounds(&x0, &y0, &x1, &y1));
  // 60 m away along x: the box would be about 60 m wide, within 100 m.
  EXPECT_TRUE(g.IntegrateScan({60.0, 0.0}, {{61.0, 0.0}}, {1}));
  EXPECT_TRUE(g.IsOccupied(1220, 0));
  // An odometry jump of 5 km (or one beam 5 km long): refused, the map as it was.
  const int tiles_before = g.NumTiles();
  EXPECT_FALSE(g.IntegrateScan({5000.0, 5000.0}, {{5001.0, 5000.0}}, {1}));
  EXPECT_FALSE(g.IntegrateScan({0.0, 0.0}, {{1.0, 0.0}, {0.0, -5000.0}}, {1, 1}));
  EXPECT_EQ(g.NumTiles(), tiles_before);
  EXPECT_GT(tiles_before, tiles);
  int bx0, by0, bx1, by1;
  ASSERT_TRUE(g.Bounds(&bx0, &by0, &bx1, &by1));
  EXPECT_LE((bx1 - bx0) * o.resolution, 100.0);
  EXPECT_LE((by1 - by0) * o.resolution, 100.0);
  // The default (2000 m) takes a 1.5 km drive.
  TiledGrid wide(Opts());
  EXPECT_TRUE(wide.IntegrateScan({0.0, 0.0}, {{1.0, 0.0}}, {1}));
  EXPECT_TRUE(wide.IntegrateScan({1500.0, 0.0}, {{1501.0, 0.0}}, {1}));
  EXPECT_FALSE(wide.IntegrateScan({2100.0, 0.0}, {{2101.0, 0.0}}, {1}));
}

TEST(TiledGrid, DistanceFieldIsEuclideanDistanceToNearestObstacle) {
  TiledGrid g(Opts());
  MakeObstacle(&g, 10, 10);
  EXPECT_TRUE(g.IsOccupied(10, 10));
  EXPECT_DOUBLE_EQ(g.CellDistance(10, 10), 0.0);
  EXPECT_NEAR(g.CellDistance(13, 14), 5 * 0.05, 1e-3);  // 3-4-5 triangle
  EXPECT_NEAR(g.CellDistance(10, 16), 6 * 0.05, 1e-3);
  EXPECT_NEAR(g.CellDistance(10, 40), 0.4, 1e-9);  // saturated
  // Interpolated lookup at world points: the centre of cell 10 is 0.525 m.
  EXPECT_NEAR(g.Distance({0.525, 0.525}), 0.0, 1e-9);
  EXPECT_NEAR(g.Distance({0.525 + 0.15, 0.525}), 0.15, 1e-3);
  // Gradient points away from the obstacle.
  Eigen::Vector2d grad;
  g.Distance({0.525 + 0.12, 0.525}, &grad);
  EXPECT_GT(grad.x(), 0.8);
  // On a row of cell centres the bilinear y-derivative is one-sided (distance grows both ways).
  EXPECT_LT(std::abs(grad.y()), 0.5 * grad.x());
}

TEST(TiledGrid, DistanceFieldCrossesTileBordersAndNegativeCoordinates) {
  TiledGrid g(Opts());
  MakeObstacle(&g, -1, -1);  // a corner of four tiles
  EXPECT_NEAR(g.CellDistance(2, 3), 0.05 * std::sqrt(9.0 + 16.0), 1e-3);
  EXPECT_NEAR(g.CellDistance(-4, -5), 0.05 * 5.0, 1e-3);
  EXPECT_NEAR(g.Distance({-0.025, -0.025}), 0.0, 1e-9);
}

TEST(TiledGrid, ObstacleRemovedRestoresTheField) {
  TiledGrid g(Opts());
  MakeObstacle(&g, 0, 0);
  MakeObstacle(&g, 6, 0);
  EXPECT_NEAR(g.CellDistance(4, 0), 0.10, 1e-3);
  // Clear (6, 0) with misses until it is free.
  for (int i = 0; i < 40 && g.IsOccupied(6, 0); ++i) g.UpdateCell(6, 0, -30);
  ASSERT_FALSE(g.IsOccupied(6, 0));
  EXPECT_NEAR(g.CellDistance(4, 0), 0.20, 1e-3);
  EXPECT_NEAR(g.CellDistance(6, 0), 0.30, 1e-3);
}

TEST(TiledGrid, IntegrateScanClearsFreeSpaceAndMarksHits) {
  TiledGrid g(Opts());
  std::vector<Eigen::Vector2d> ends = {{2.0, 0.01}};
  std::vector<uint8_t> hit = {1};
  g.IntegrateScan({0.01, 0.01}, ends, hit);
  EXPECT_TRUE(g.IsOccupied(g.CellX(2.0), 0));
  EXPECT_LT(g.LogOdds(g.CellX(1.0), 0), 0.0f);
  EXPECT_FALSE(g.IsKnown(g.CellX(1.0), 5));
}

TEST(TiledGrid, FreeSpaceBeamStepClearsAlongEveryNthBeamAndMarksEveryHit) {
  // Four beams of 1 m (+x, +y, -x, -y): with step n, beams 0, n, 2n, ... clear their cells;
  // every beam's end cell becomes an obstacle.
  const std::vector<Eigen::Vector2d> dirs = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
  const Eigen::Vector2d origin(0.026, 0.026);  // inside cell (0, 0)
  for (int step = 1; step <= 3; ++step) {
    GridOptions o = Opts();
    o.free_space_beam_step = step;
    TiledGrid g(o);
    std::vector<Eigen::Vector2d> ends;
    for (const Eigen::Vector2d& d : dirs) ends.push_back(origin + 1.0 * d);
    g.IntegrateScan(origin, ends, std::vector<uint8_t>(ends.size(), 1));
    for (size_t k = 0; k < dirs.size(); ++k) {
      const Eigen::Vector2d mid = origin + 0.5 * dirs[k];
      const bool cleared = g.LogOdds(g.CellX(mid.x()), g.CellX(mid.y())) < 0.0f;
      EXPECT_EQ(cleared, k % step == 0) << "step " << step << " beam " << k;
      EXPECT_TRUE(g.IsOccupied(g.CellX(ends[k].x()), g.CellX(ends[k].y())))
          << "step " << step << " beam " << k;
    }
  }
}

TEST(TiledGrid, BatchBuildEqualsScanByScanIntegration) {
  // Scans from several origins over a few walls (hits that later get cleared, grazing rays,
  // negative coordinates, several tiles); the batch field must equal the incremental one.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-4.0, 4.0);
  TiledGrid one(Opts()), batch(Opts());
  batch.BeginBatch();
  for (int s = 0; s < 12; ++s) {
    const Eigen::Vector2d origin(u(rng) * 0.5, u(rng) * 0.5);
    std::vector<Eigen::Vector2d> ends;
    std::vector<uint8_t> hit;
    for (int k = 0; k < 180; ++k) {
      const double a = 2.0 * M_PI * k / 180.0;
      const double r = 2.0 + std::abs(u(rng)) * ((k + s) % 7 == 0 ? 1.0 : 0.1);
      ends.push_back(origin + r * Eigen::Vector2d(std::cos(a), std::sin(a)));
      hit.push_back(k % 11 == 0 ? 0 : 1);
    }
    one.IntegrateScan(origin, ends, hit);
    batch.IntegrateScan(origin, ends, hit);
  }
  batch.EndBatch();
  int x0, y0, x1, y1;
  ASSERT_TRUE(one.Bounds(&x0, &y0, &x1, &y1));
  int obstacles = 0, freed = 0;
  for (int y = y0 - 2; y < y1 + 2; ++y) {
    for (int x = x0 - 2; x < x1 + 2; ++x) {
      ASSERT_EQ(one.LogOdds(x, y), batch.LogOdds(x, y)) << x << "," << y;
      ASSERT_EQ(one.CellDistance(x, y), batch.CellDistance(x, y)) << x << "," << y;
      obstacles += one.IsOccupied(x, y) ? 1 : 0;
      freed += (!one.IsOccupied(x, y) && one.LogOdds(x, y) > 0.0f) ? 1 : 0;
    }
  }
  EXPECT_GT(obstacles, 500);
  EXPECT_GT(freed, 0) << "the scans should also clear some earlier hits";
}

TEST(TiledGrid, ContinuedBatchEqualsScanByScanIntegration) {
  // A batch on a finished grid (a continued map rebuild) recomputes only the tiles near the
  // obstacles it changed. The scans stay inside one tile (cells 0..63, 3.2 m) with walls up to
  // 2 cells from its border, so the field of the neighbouring tiles, which no scan touches,
  // changes with them; every fourth scan is in a far part of the map.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  TiledGrid one(Opts()), batch(Opts());
  auto scan = [&](int s, std::vector<Eigen::Vector2d>* ends, std::vector<uint8_t>* hit) {
    const Eigen::Vector2d origin =
        s % 4 == 3 ? Eigen::Vector2d(9.7, -7.0) : Eigen::Vector2d(1.6, 1.6);
    for (int k = 0; k < 180; ++k) {
      const double a = 2.0 * M_PI * k / 180.0;
      const double r = 1.3 + 0.15 * u(rng);  // a ragged wall, different in every scan
      ends->push_back(origin + r * Eigen::Vector2d(std::cos(a), std::sin(a)));
      hit->push_back(k % 13 == 0 ? 0 : 1);
    }
    return origin;
  };
  for (int part = 0; part < 3; ++part) {
    batch.BeginBatch();
    for (int s = 6 * part; s < 6 * part + 6; ++s) {
      std::vector<Eigen::Vector2d> ends;
      std::vector<uint8_t> hit;
      const Eigen::Vector2d origin = scan(s, &ends, &hit);
      one.IntegrateScan(origin, ends, hit);
      batch.IntegrateScan(origin, ends, hit);
    }
    batch.EndBatch();
    int x0, y0, x1, y1;
    ASSERT_TRUE(one.Bounds(&x0, &y0, &x1, &y1));
    for (int y = y0 - 2; y < y1 + 2; ++y) {
      for (int x = x0 - 2; x < x1 + 2; ++x) {
        ASSERT_EQ(one.LogOdds(x, y), batch.LogOdds(x, y)) << part << ": " << x << "," << y;
        ASSERT_EQ(one.CellDistance(x, y), batch.CellDistance(x, y))
            << part << ": " << x << "," << y;
      }
    }
  }
  // The walls reach the neighbouring tile's field (cell 64 is in the next tile).
  EXPECT_LT(one.CellDistance(64, 32), 0.4);
}

// Cells a ray clears, by the definition: the Bresenham line from origin to end cell, without
// the cells within `margin` (Chebyshev) of the end cell of a hit.
std::vector<std::pair<int, int>> ClearedCells(int ox, int oy, int ex, int ey, bool hit,
                                              int margin) {
  std::vector<std::pair<int, int>> cells;
  int x = ox, y = oy;
  const int dx = std::abs(ex - ox), dy = -std::abs(ey - oy);
  const int sx = ox < ex ? 1 : -1, sy = oy < ey ? 1 : -1;
  int err = dx + dy;
  while (true) {
    if (hit && std::max(std::abs(ex - x), std::abs(ey - y)) <= margin) break;
    cells.emplace_back(x, y);
    if (x == ex && y == ey) break;
    const int e2 = 2 * err;
    if (e2 >= dy) {
      err += dy;
      x += sx;
    }
    if (e2 <= dx) {
      err += dx;
      y += sy;
    }
  }
  return cells;
}

TEST(TiledGrid, RaysClearExactlyTheirBresenhamCellsUpToTheMargin) {
  // IntegrateScan counts the cells to clear instead of testing each one's distance to the end:
  // one miss on exactly the cells of the definition, every direction, margins 0-2.
  for (int margin = 0; margin <= 2; ++margin) {
    GridOptions o = Opts();
    o.free_space_margin = margin;
    for (int hit = 0; hit < 2; ++hit) {
      for (int ex = -9; ex <= 9; ++ex) {
        for (int ey = -9; ey <= 9; ++ey) {
          TiledGrid g(o);
          const Eigen::Vector2d origin(3 * 0.05 + 0.01, -2 * 0.05 + 0.02);  // cell (3, -2)
          const Eigen::Vector2d end((3 + ex) * 0.05 + 0.03, (-2 + ey) * 0.05 + 0.04);
          g.IntegrateScan(origin, {end}, {static_cast<uint8_t>(hit)});
          std::vector<std::pair<int, int>> expected =
              ClearedCells(3, -2, 3 + ex, -2 + ey, hit != 0, margin);
          std::sort(expected.begin(), expected.end());
          for (int y = -2 - 11; y <= -2 + 11; ++y) {
            for (int x = 3 - 11; x <= 3 + 11; ++x) {
              const bool cleared = g.LogOdds(x, y) < 0.0f;
              const bool want =
                  std::binary_search(expected.begin(), expected.end(), std::make_pair(x, y));
              ASSERT_EQ(cleared, want) << "end " << ex << "," << ey << " cell " << x << "," << y
                                       << " margin " << margin << " hit " << hit;
            }
          }
        }
      }
    }
  }
}

TEST(TiledGrid, LongRaysClearTheirBresenhamCellsAcrossTiles) {
  // Rays of up to 3 tiles from a cell next to a tile corner, in every octant and through tile
  // corners (slope 1): the ray's tile is followed step by step.
  const int ox = kTileSize - 1, oy = -1;  // the corner cell of tile (0, -1)
  std::vector<std::pair<int, int>> ends;
  for (int a = -3 * kTileSize; a <= 3 * kTileSize; a += 37) {
    for (const int b : {-3 * kTileSize, -kTileSize - 5, kTileSize + 3, 3 * kTileSize}) {
      ends.emplace_back(a, b);
      ends.emplace_back(b, a);
    }
    ends.emplace_back(a, a);
    ends.emplace_back(a, -a);
  }
  for (const auto& [ex, ey] : ends) {
    TiledGrid g(Opts());
    const Eigen::Vector2d origin((ox + 0.5) * 0.05, (oy + 0.5) * 0.05);
    const Eigen::Vector2d end((ox + ex + 0.5) * 0.05, (oy + ey + 0.5) * 0.05);
    g.IntegrateScan(origin, {end}, {0});
    std::vector<std::pair<int, int>> expected = ClearedCells(ox, oy, ox + ex, oy + ey, false, 0);
    for (const auto& [x, y] : expected) {
      ASSERT_LT(g.LogOdds(x, y), 0.0f) << "end " << ex << "," << ey << " cell " << x << "," << y;
    }
    // Nothing else: the number of observed cells is the line's.
    int min_cx, min_cy, max_cx, max_cy, observed = 0;
    ASSERT_TRUE(g.Bounds(&min_cx, &min_cy, &max_cx, &max_cy));
    for (int y = min_cy; y < max_cy; ++y) {
      for (int x = min_cx; x < max_cx; ++x) observed += g.IsKnown(x, y) ? 1 : 0;
    }
    EXPECT_EQ(observed, static_cast<int>(expected.size())) << "end " << ex << "," << ey;
  }
}

TEST(TiledGrid, CopyOnWriteCopiesOnlyTheTileWrittenTo) {
  TiledGrid a(Opts());
  MakeObstacle(&a, 0, 0);
  MakeObstacle(&a, 200, 0);  // another tile (64 cells per tile)
  TiledGrid b = a;           // a particle copy: shares every tile
  EXPECT_EQ(a.TileAddress(0, 0), b.TileAddress(0, 0));
  EXPECT_EQ(b.NumSharedTiles(), b.NumTiles());
  MakeObstacle(&b, 210, 5);  // far from tile borders: writes one tile only
  EXPECT_NE(a.TileAddress(200, 0), b.TileAddress(200, 0));
  EXPECT_EQ(a.TileAddress(0, 0), b.TileAddress(0, 0));  // untouched tile still shared
  EXPECT_FALSE(a.IsOccupied(210, 5));                   // the original is unchanged
  EXPECT_TRUE(b.IsOccupied(210, 5));
}

}  // namespace
}  // namespace fl::rbpf
