// Copy-on-write tiled occupancy grid with an incrementally maintained likelihood field.
//
// The plane is cut into square tiles of kTileSize x kTileSize cells. A TiledGrid holds
// shared_ptrs to tiles; copying a TiledGrid (a particle being resampled) copies only the
// pointers, and a tile is deep-copied the first time a grid writes to a tile it shares
// (use_count() > 1). Memory therefore grows with the area the particles disagree about, not
// with particles x map size.
//
// Each cell stores the log-odds of occupancy (int16, scaled by kLogOddsScale; 0 = unknown) and
// the Euclidean distance from its centre to the nearest obstacle cell centre (uint8, in
// 1/kDistScale cells, saturated at the field radius). The distance field is updated locally
// whenever a cell becomes or stops being an obstacle, so the likelihood field of eq. 3,
// p(z) ∝ z_hit exp(-d²/2σ²) + z_rand, is a table lookup for any particle at any time.
// A cell is an obstacle (distance 0) from when its log-odds exceeds log_odds_occupied until it
// falls below log_odds_free.
//
// Cell (cx, cy) covers x in [cx*res, (cx+1)*res), likewise y; its centre is (cx+0.5)*res.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/rbpf_slam/options.hpp"

namespace fl::rbpf {

constexpr int kTileBits = 6;
constexpr int kTileSize = 1 << kTileBits;  // cells per tile side
constexpr int kTileCells = kTileSize * kTileSize;
constexpr int kDistScale = 16;           // distance units per cell
constexpr float kLogOddsScale = 100.0f;  // stored log-odds = round(log-odds * scale)

struct Tile {
  std::array<int16_t, kTileCells> log_odds;
  std::array<uint8_t, kTileCells> dist;
  int occupied = 0;          // number of obstacle cells in this tile
  bool batch_dirty = false;  // an obstacle changed here in the open batch (TiledGrid::EndBatch)
};

inline int FloorDiv(int a, int b) { return (a >= 0) ? a / b : -((-a + b - 1) / b); }

class TiledGrid {
 public:
  explicit TiledGrid(const GridOptions& options);

  double resolution() const { return res_; }
  // Field radius in cells and the saturated stored distance value.
  int field_radius_cells() const { return radius_; }
  // [cells] the largest |x| or |y| cell index IntegrateScan touches (2^24: 840 km at 5 cm).
  static constexpr double kMaxCellIndex = 16777216.0;

  // Integrates one scan: `origin_world` is the laser position, `endpoints_world` the beam
  // ends, `is_hit[k]` false for beams only clearing free space (longer than max range).
  // Returns false, leaving the map as it was, when the scan would grow the map beyond
  // grid.max_size_m a side or its origin is beyond kMaxCellIndex cells or not finite.
  bool IntegrateScan(const Eigen::Vector2d& origin_world,
                     const std::vector<Eigen::Vector2d>& endpoints_world,
                     const std::vector<uint8_t>& is_hit);

  // Distance [m] from a world point to the nearest obstacle, saturated at field_max_distance,
  // bilinearly interpolated between cell centres; `gradient` (optional) is d(distance)/d(p).
  double Distance(const Eigen::Vector2d& p_world, Eigen::Vector2d* gradient = nullptr) const;
  // Same, without interpolation: the value of the cell holding p.
  double CellDistance(int cx, int cy) const;

  float LogOdds(int cx, int cy) const;
  bool IsOccupied(int cx, int cy) const;
  bool IsKnown(int cx, int cy) const { return LogOdds(cx, cy) != 0.0f; }
  // Whether the cell holding a world point was ever observed (hit or passed through).
  bool IsKnownAt(const Eigen::Vector2d& p_world) const {
    return IsKnown(CellX(p_world.x()), CellX(p_world.y()));
  }

  // Batch building (map rebuilds from many keyframes): between BeginBatch() and EndBatch() the
  // log-odds and obstacle flags are updated as usual but the distance field is not; EndBatch()
  // recomputes it once for the whole grid. The result is identical to integrating the scans one
  // by one, and much cheaper, since no cell's distance is repaired again and again as obstacles
  // come and go. Distance() is not valid inside a batch. EndBatch() recomputes only the tiles
  // near obstacles that changed, so a batch on a grid continued from a finished one (a map
  // rebuild that keeps its first keyframes) costs what the new scans touch.
  void BeginBatch();
  void EndBatch();

  // Adds log-odds to one cell (used by IntegrateScan; public for tests).
  void UpdateCell(int cx, int cy, int delta_scaled);

  // Bounding box of allocated tiles in cells: [min_cx, max_cx) x [min_cy, max_cy).
  // Returns false if the grid is empty.
  bool Bounds(int* min_cx, int* min_cy, int* max_cx, int* max_cy) const;

  // Number of distinct tiles this grid points to and how many it shares with someone else.
  int NumTiles() const;
  int NumSharedTiles() const;
  // Identity of the tile holding a cell (nullptr if not allocated); for copy-on-write tests.
  const Tile* TileAddress(int cx, int cy) const;

  int CellX(double x) const { return static_cast<int>(std::floor(x * inv_res_)); }

 private:
  const Tile* TileAt(int tx, int ty) const {
    const int ix = tx - tx0_, iy = ty - ty0_;
    if (ix < 0 || iy < 0 || ix >= ntx_ || iy >= nty_) return nullptr;
    return tiles_[static_cast<size_t>(iy) * ntx_ + ix].get();
  }
  Tile* MutableTile(int tx, int ty);
  void Grow(int tx, int ty);
  // Whether touching cells [cx0, cx1] x [cy0, cy1] keeps the tile table within max_size_m.
  bool FitsMaxSize(int cx0, int cy0, int cx1, int cy1) const;
  int RawDist(int cx, int cy) const {
    const Tile* t = TileAt(cx >> kTileBits, cy >> kTileBits);
    return t ? t->dist[((cy & (kTileSize - 1)) << kTileBits) | (cx & (kTileSize - 1))] : dist_max_;
  }
  void SetRawDist(int cx, int cy, int value);
  void MarkBatchDirty(int cx, int cy);
  void OnBecameOccupied(int cx, int cy);
  void OnBecameFree(int cx, int cy);

  GridOptions opt_;
  double res_;
  double inv_res_;
  int radius_;    // field radius in cells
  int dist_max_;  // stored value meaning "radius or farther"
  int16_t hit_, miss_, clamp_, occ_threshold_, free_threshold_;
  std::vector<uint8_t> dist_table_;  // scaled distance of offset (dx, dy), |dx|, |dy| <= radius
  // Precomputed offsets within the field radius and their scaled distances.
  struct Offset {
    int dx, dy, d;
  };
  std::vector<Offset> disk_;        // sorted by distance
  std::vector<Offset> disk_rows_;   // the same offsets in row-major order
  std::vector<size_t> disk_start_;  // [d]: index of the first offset of disk_ at distance >= d
  int window_side_ = 0;             // OnBecameFree's window: cells within 2 radii, row-major
  std::vector<int> disk_window_;    // disk_[i] as an offset in that window

  int tx0_ = 0, ty0_ = 0, ntx_ = 0, nty_ = 0;
  std::vector<std::shared_ptr<Tile>> tiles_;
  std::shared_ptr<Tile> empty_;  // prototype of a fresh tile
  bool batch_ = false;           // inside BeginBatch() / EndBatch()
  // Tiles (tx, ty) where a cell became or stopped being an obstacle in this batch (each once:
  // Tile::batch_dirty).
  std::vector<std::pair<int, int>> batch_dirty_;
};

// Inline: the scan matcher calls it for every point of every iteration.
__attribute__((always_inline)) inline double TiledGrid::Distance(const Eigen::Vector2d& p,
                                                                  Eigen::Vector2d* gradient) const {
  const double u = p.x() * inv_res_ - 0.5, v = p.y() * inv_res_ - 0.5;
  const double fu = std::floor(u), fv = std::floor(v);
  const int x0 = static_cast<int>(fu), y0 = static_cast<int>(fv);
  const double a = u - fu, b = v - fv;
  double d00, d10, d01, d11;
  const Tile* t = TileAt(x0 >> kTileBits, y0 >> kTileBits);
  if (((x0 + 1) & (kTileSize - 1)) != 0 && ((y0 + 1) & (kTileSize - 1)) != 0) {
    // All four cells in one tile (the common case).
    if (!t) {
      if (gradient) gradient->setZero();
      return opt_.field_max_distance;
    }
    const int i = ((y0 & (kTileSize - 1)) << kTileBits) | (x0 & (kTileSize - 1));
    d00 = t->dist[i];
    d10 = t->dist[i + 1];
    d01 = t->dist[i + kTileSize];
    d11 = t->dist[i + kTileSize + 1];
  } else {
    d00 = RawDist(x0, y0);
    d10 = RawDist(x0 + 1, y0);
    d01 = RawDist(x0, y0 + 1);
    d11 = RawDist(x0 + 1, y0 + 1);
  }
  const double scale = res_ / kDistScale;
  const double d = ((1 - a) * (1 - b) * d00 + a * (1 - b) * d10 + (1 - a) * b * d01 + a * b * d11);
  if (gradient) {
    if (d * scale >= opt_.field_max_distance) {
      gradient->setZero();
      return opt_.field_max_distance;
    }
    const double gu = (1 - b) * (d10 - d00) + b * (d11 - d01);
    const double gv = (1 - a) * (d01 - d00) + a * (d11 - d10);
    *gradient = Eigen::Vector2d(gu, gv) * (scale * inv_res_);
  }
  return std::min(d * scale, opt_.field_max_distance);
}

}  // namespace fl::rbpf
