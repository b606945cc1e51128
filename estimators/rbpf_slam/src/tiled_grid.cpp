#include "fusionloc/rbpf_slam/tiled_grid.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace fl::rbpf {

namespace {
inline int LocalIndex(int cx, int cy) {
  return ((cy & (kTileSize - 1)) << kTileBits) | (cx & (kTileSize - 1));
}
int16_t ScaleLogOdds(double l) { return static_cast<int16_t>(std::lround(l * kLogOddsScale)); }
}  // namespace

TiledGrid::TiledGrid(const GridOptions& options) : opt_(options) {
  const Status s = options.Validate();
  if (!s.ok()) throw std::invalid_argument("TiledGrid: " + s.message());
  res_ = options.resolution;
  inv_res_ = 1.0 / res_;
  radius_ = std::max(1, static_cast<int>(std::ceil(options.field_max_distance / res_ - 1e-9)));
  dist_max_ = radius_ * kDistScale;
  hit_ = ScaleLogOdds(options.log_odds_hit);
  miss_ = ScaleLogOdds(options.log_odds_miss);
  clamp_ = ScaleLogOdds(options.log_odds_clamp);
  occ_threshold_ = ScaleLogOdds(options.log_odds_occupied);
  free_threshold_ = ScaleLogOdds(options.log_odds_free);
  const int side = 2 * radius_ + 1;
  dist_table_.assign(static_cast<size_t>(side) * side, static_cast<uint8_t>(dist_max_));
  for (int dy = -radius_; dy <= radius_; ++dy) {
    for (int dx = -radius_; dx <= radius_; ++dx) {
      const int d = static_cast<int>(std::lround(std::sqrt(dx * dx + dy * dy) * kDistScale));
      dist_table_[static_cast<size_t>(dy + radius_) * side + (dx + radius_)] =
          static_cast<uint8_t>(std::min(d, dist_max_));
    }
  }
  for (int dy = -radius_; dy <= radius_; ++dy) {
    for (int dx = -radius_; dx <= radius_; ++dx) {
      const int d = static_cast<int>(std::lround(std::sqrt(dx * dx + dy * dy) * kDistScale));
      if (d <= dist_max_) disk_.push_back({dx, dy, d});
    }
  }
  std::stable_sort(disk_.begin(), disk_.end(),
                   [](const Offset& a, const Offset& b) { return a.d < b.d; });
  disk_rows_ = disk_;
  std::sort(disk_rows_.begin(), disk_rows_.end(), [](const Offset& a, const Offset& b) {
    return a.dy != b.dy ? a.dy < b.dy : a.dx < b.dx;
  });
  window_side_ = 4 * radius_ + 1;
  for (const Offset& o : disk_) disk_window_.push_back(o.dy * window_side_ + o.dx);
  disk_start_.assign(static_cast<size_t>(dist_max_) + 1, disk_.size());
  for (int d = 0; d <= dist_max_; ++d) {
    disk_start_[d] = std::lower_bound(disk_.begin(), disk_.end(), d,
                                      [](const Offset& o, int v) { return o.d < v; }) -
                     disk_.begin();
  }
  empty_ = std::make_shared<Tile>();
  empty_->log_odds.fill(0);
  empty_->dist.fill(static_cast<uint8_t>(dist_max_));
  empty_->occupied = 0;
}

void TiledGrid::Grow(int tx, int ty) {
  if (ntx_ == 0) {
    // First tile: start with a small window around it.
    tx0_ = tx - 2;
    ty0_ = ty - 2;
    ntx_ = nty_ = 5;
    tiles_.assign(static_cast<size_t>(ntx_) * nty_, nullptr);
    return;
  }
  const int nx0 = std::min(tx0_, tx - 2), ny0 = std::min(ty0_, ty - 2);
  const int nx1 = std::max(tx0_ + ntx_, tx + 3), ny1 = std::max(ty0_ + nty_, ty + 3);
  std::vector<std::shared_ptr<Tile>> next(static_cast<size_t>(nx1 - nx0) * (ny1 - ny0));
  for (int iy = 0; iy < nty_; ++iy) {
    for (int ix = 0; ix < ntx_; ++ix) {
      next[static_cast<size_t>(iy + ty0_ - ny0) * (nx1 - nx0) + (ix + tx0_ - nx0)] =
          std::move(tiles_[static_cast<size_t>(iy) * ntx_ + ix]);
    }
  }
  tiles_ = std::move(next);
  tx0_ = nx0;
  ty0_ = ny0;
  ntx_ = nx1 - nx0;
  nty_ = ny1 - ny0;
}

Tile* TiledGrid::MutableTile(int tx, int ty) {
  int ix = tx - tx0_, iy = ty - ty0_;
  if (ix < 0 || iy < 0 || ix >= ntx_ || iy >= nty_) {
    Grow(tx, ty);
    ix = tx - tx0_;
    iy = ty - ty0_;
  }
  std::shared_ptr<Tile>& slot = tiles_[static_cast<size_t>(iy) * ntx_ + ix];
  if (!slot) {
    slot = std::make_shared<Tile>(*empty_);
  } else if (slot.use_count() > 1) {
    slot = std::make_shared<Tile>(*slot);  // copy on write
  }
  return slot.get();
}

void TiledGrid::SetRawDist(int cx, int cy, int value) {
  Tile* t = MutableTile(cx >> kTileBits, cy >> kTileBits);
  t->dist[LocalIndex(cx, cy)] = static_cast<uint8_t>(value);
}

float TiledGrid::LogOdds(int cx, int cy) const {
  const Tile* t = TileAt(cx >> kTileBits, cy >> kTileBits);
  return t ? t->log_odds[LocalIndex(cx, cy)] / kLogOddsScale : 0.0f;
}

bool TiledGrid::IsOccupied(int cx, int cy) const {
  const Tile* t = TileAt(cx >> kTileBits, cy >> kTileBits);
  return t && t->dist[LocalIndex(cx, cy)] == 0;
}

double TiledGrid::CellDistance(int cx, int cy) const {
  return RawDist(cx, cy) * (res_ / kDistScale);
}

const Tile* TiledGrid::TileAddress(int cx, int cy) const {
  return TileAt(cx >> kTileBits, cy >> kTileBits);
}

void TiledGrid::UpdateCell(int cx, int cy, int delta_scaled) {
  Tile* t = MutableTile(cx >> kTileBits, cy >> kTileBits);
  const int idx = LocalIndex(cx, cy);
  int16_t& l = t->log_odds[idx];
  const bool was = t->dist[idx] == 0;
  int v = l + delta_scaled;
  v = std::max<int>(-clamp_, std::min<int>(clamp_, v));
  if (v == 0) v = delta_scaled > 0 ? 1 : -1;  // 0 means "unknown": an observed cell never is
  l = static_cast<int16_t>(v);
  const bool now = was ? v >= free_threshold_ : v > occ_threshold_;
  if (now != was) {
    t->occupied += now ? 1 : -1;
    if (now) {
      OnBecameOccupied(cx, cy);
    } else {
      OnBecameFree(cx, cy);
    }
  }
}

void TiledGrid::BeginBatch() {
  batch_ = true;
  batch_dirty_.clear();
}

void TiledGrid::MarkBatchDirty(int cx, int cy) {
  Tile* t = MutableTile(cx >> kTileBits, cy >> kTileBits);  // written just before: no copy
  if (t->batch_dirty) return;
  t->batch_dirty = true;
  batch_dirty_.emplace_back(cx >> kTileBits, cy >> kTileBits);
}

void TiledGrid::EndBatch() {
  if (!batch_) return;
  batch_ = false;
  // Only obstacle changes in the batch move distances, and no farther than the field radius
  // (< one tile): the cells to recompute lie in the tiles whose obstacles changed and their 8
  // neighbours (`redo`), and the obstacles that can be nearest to them in `redo` and its
  // neighbours (`source`). Outside `redo`, every stored distance is still right.
  std::vector<std::pair<int, int>> redo, source;
  for (const auto& [tx, ty] : batch_dirty_) {
    MutableTile(tx, ty)->batch_dirty = false;
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) redo.emplace_back(tx + dx, ty + dy);
    }
  }
  std::sort(redo.begin(), redo.end());
  redo.erase(std::unique(redo.begin(), redo.end()), redo.end());
  for (const auto& [tx, ty] : redo) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) source.emplace_back(tx + dx, ty + dy);
    }
  }
  std::sort(source.begin(), source.end());
  source.erase(std::unique(source.begin(), source.end()), source.end());
  batch_dirty_.clear();
  // Reset the distances in `redo`, then let each obstacle cell of `source` stamp its disk.
  for (const auto& [tx, ty] : redo) {
    if (!TileAt(tx, ty)) continue;
    Tile* t = MutableTile(tx, ty);
    for (int k = 0; k < kTileCells; ++k) {
      if (t->dist[k] != 0) t->dist[k] = static_cast<uint8_t>(dist_max_);
    }
  }
  std::vector<std::pair<int, int>> obstacles;
  for (const auto& [tx, ty] : source) {
    const Tile* t = TileAt(tx, ty);
    if (!t) continue;
    for (int k = 0; k < kTileCells; ++k) {
      if (t->dist[k] == 0) {
        obstacles.emplace_back(tx * kTileSize + (k & (kTileSize - 1)),
                               ty * kTileSize + (k >> kTileBits));
      }
    }
  }
  for (const auto& [cx, cy] : obstacles) OnBecameOccupied(cx, cy);
}

void TiledGrid::OnBecameOccupied(int cx, int cy) {
  if (batch_) {  // only the obstacle flag; EndBatch() computes the field
    SetRawDist(cx, cy, 0);
    MarkBatchDirty(cx, cy);
    return;
  }
  // dist = min(dist, distance to this cell) over the square of side 2r+1 around it, tile part
  // by tile part, row by row (dist_table_ is that distance, saturated at dist_max_: outside the
  // disk the min changes nothing). A tile part is made writable (created, or copied if shared)
  // only when one of its cells actually gets nearer.
  const int side = 2 * radius_ + 1;
  const int x0 = cx - radius_, y0 = cy - radius_;
  for (int ty = y0 >> kTileBits; ty <= (y0 + side - 1) >> kTileBits; ++ty) {
    const int ya = std::max(y0, ty * kTileSize), yb = std::min(y0 + side, (ty + 1) * kTileSize);
    for (int tx = x0 >> kTileBits; tx <= (x0 + side - 1) >> kTileBits; ++tx) {
      const int xa = std::max(x0, tx * kTileSize), xb = std::min(x0 + side, (tx + 1) * kTileSize);
      const int n = xb - xa;
      Tile* write = nullptr;
      const int ix = tx - tx0_, iy = ty - ty0_;
      if (ix >= 0 && iy >= 0 && ix < ntx_ && iy < nty_) {
        const std::shared_ptr<Tile>& slot = tiles_[static_cast<size_t>(iy) * ntx_ + ix];
        if (slot && slot.use_count() == 1) write = slot.get();
      }
      if (!write) {
        const Tile* read = TileAt(tx, ty);
        bool nearer = false;
        for (int y = ya; y < yb && !nearer; ++y) {
          const uint8_t* d = &dist_table_[static_cast<size_t>(y - y0) * side + (xa - x0)];
          const uint8_t* row = read ? &read->dist[LocalIndex(xa, y)] : nullptr;
          for (int i = 0; i < n; ++i) nearer |= (row ? row[i] : dist_max_) > d[i];
        }
        if (!nearer) continue;
        write = MutableTile(tx, ty);
      }
      for (int y = ya; y < yb; ++y) {
        const uint8_t* d = &dist_table_[static_cast<size_t>(y - y0) * side + (xa - x0)];
        uint8_t* row = &write->dist[LocalIndex(xa, y)];
        for (int i = 0; i < n; ++i) row[i] = std::min(row[i], d[i]);
      }
    }
  }
}

void TiledGrid::OnBecameFree(int cx, int cy) {
  if (batch_) {  // any value but 0; EndBatch() computes the field
    SetRawDist(cx, cy, dist_max_);
    MarkBatchDirty(cx, cy);
    return;
  }
  // Only cells whose nearest obstacle was this one (stored distance == distance to it) change;
  // each of them searches the disk outwards (offsets sorted by distance) for its new nearest.
  // Every cell read lies within two field radii of (cx, cy): they are copied once into a window
  // (row-major, side window_side_). The window's values stay right while cells are repaired:
  // a repair writes a nonzero value over a nonzero one (the searches only look for zeros) and
  // each cell is visited once.
  SetRawDist(cx, cy, 1);  // no longer an obstacle (1 ≠ 0); recomputed below
  const int reach = 2 * radius_;
  thread_local std::vector<uint8_t> window;
  window.resize(static_cast<size_t>(window_side_) * window_side_);
  for (int wy = 0; wy < window_side_; ++wy) {
    const int y = cy - reach + wy;
    uint8_t* out = &window[static_cast<size_t>(wy) * window_side_];
    int wx = 0;
    while (wx < window_side_) {  // one tile's part of the row at a time
      const int x = cx - reach + wx;
      const int run = std::min(window_side_ - wx, kTileSize - (x & (kTileSize - 1)));
      const Tile* t = TileAt(x >> kTileBits, y >> kTileBits);
      if (t) {
        std::copy_n(&t->dist[LocalIndex(x, y)], run, out + wx);
      } else {
        std::fill_n(out + wx, run, static_cast<uint8_t>(dist_max_));
      }
      wx += run;
    }
  }
  const uint8_t* centre = &window[static_cast<size_t>(reach) * window_side_ + reach];
  for (const Offset& o : disk_rows_) {
    const int off = o.dy * window_side_ + o.dx;
    const int cur = centre[off];
    if (cur == 0) continue;                // another obstacle
    if (o.d != 0 && cur != o.d) continue;  // its nearest obstacle is another one
    // Its new nearest obstacle is at least as far as the old one (`cur`): offsets nearer than
    // that hold no obstacle and are skipped.
    int best = dist_max_;
    for (size_t i = disk_start_[cur]; i < disk_.size(); ++i) {
      if (disk_[i].d >= best) break;
      if (centre[off + disk_window_[i]] == 0) {
        best = disk_[i].d;
        break;
      }
    }
    if (best != cur) SetRawDist(cx + o.dx, cy + o.dy, best);
  }
}

bool TiledGrid::FitsMaxSize(int cx0, int cy0, int cx1, int cy1) const {
  // The tiles Grow would hold after touching cells [cx0, cx1] x [cy0, cy1], the likelihood
  // field's radius around them included.
  const int tx0 = FloorDiv(cx0 - radius_, kTileSize) - 2, ty0 = FloorDiv(cy0 - radius_, kTileSize) - 2;
  const int tx1 = FloorDiv(cx1 + radius_, kTileSize) + 3, ty1 = FloorDiv(cy1 + radius_, kTileSize) + 3;
  const int64_t nx = static_cast<int64_t>(ntx_ > 0 ? std::max(tx0_ + ntx_, tx1) : tx1) -
                     (ntx_ > 0 ? std::min(tx0_, tx0) : tx0);
  const int64_t ny = static_cast<int64_t>(nty_ > 0 ? std::max(ty0_ + nty_, ty1) : ty1) -
                     (nty_ > 0 ? std::min(ty0_, ty0) : ty0);
  const double max_tiles = opt_.max_size_m * inv_res_ / kTileSize + 5.0;  // + Grow's margins
  return static_cast<double>(nx) <= max_tiles && static_cast<double>(ny) <= max_tiles;
}

bool TiledGrid::IntegrateScan(const Eigen::Vector2d& origin_world,
                              const std::vector<Eigen::Vector2d>& endpoints_world,
                              const std::vector<uint8_t>& is_hit) {
  // Cell indices are ints: a scan from (or a beam to) beyond kMaxCellIndex cells, or not
  // finite, comes from a corrupt pose or range and is left out (it was an out-of-range cast).
  const auto in_range = [&](const Eigen::Vector2d& p) {
    return std::abs(p.x() * inv_res_) < kMaxCellIndex && std::abs(p.y() * inv_res_) < kMaxCellIndex;
  };
  if (!in_range(origin_world)) return false;
  const int ox = static_cast<int>(std::floor(origin_world.x() * inv_res_));
  const int oy = static_cast<int>(std::floor(origin_world.y() * inv_res_));
  // The tile table is dense over the map's bounding box: a scan far from the map (an odometry
  // jump) would allocate it for the whole box, so such a scan is refused before any growth.
  {
    int cx0 = ox, cy0 = oy, cx1 = ox, cy1 = oy;
    for (const Eigen::Vector2d& e : endpoints_world) {
      if (!in_range(e)) continue;
      const int ex = static_cast<int>(std::floor(e.x() * inv_res_));
      const int ey = static_cast<int>(std::floor(e.y() * inv_res_));
      cx0 = std::min(cx0, ex);
      cx1 = std::max(cx1, ex);
      cy0 = std::min(cy0, ey);
      cy1 = std::max(cy1, ey);
    }
    if (!FitsMaxSize(cx0, cy0, cx1, cy1)) return false;
  }
  const int step = std::max(1, opt_.free_space_beam_step);
  // Copies of the members the inner loop reads: stores into int16 log-odds could alias them, so
  // the compiler would reload them for every cell.
  const int miss = miss_, neg_clamp = -clamp_, free_threshold = free_threshold_;
  const int margin = opt_.free_space_margin;
  // Free space first for all beams, then the hits, so that a grazing ray of this scan does not
  // erase a wall cell another beam of the same scan hits.
  for (size_t k = 0; k < endpoints_world.size(); k += step) {
    if (!in_range(endpoints_world[k])) continue;
    const int ex = static_cast<int>(std::floor(endpoints_world[k].x() * inv_res_));
    const int ey = static_cast<int>(std::floor(endpoints_world[k].y() * inv_res_));
    // Bresenham from (ox, oy) to (ex, ey), excluding the end cell of a hit.
    int x = ox, y = oy;
    const int dx = std::abs(ex - ox), dy = -std::abs(ey - oy);
    const int sx = ox < ex ? 1 : -1, sy = oy < ey ? 1 : -1;
    int err = dx + dy;
    // The tile and the in-tile coordinates follow the steps; the tile is looked up again only
    // after a step leaves it.
    int lx = x & (kTileSize - 1), ly = y & (kTileSize - 1);
    Tile* tile = nullptr;
    // Hits stop clearing `free_space_margin` cells before the end cell, so rays grazing a wall
    // do not erode it (and the likelihood field does not flicker). Every step of this
    // Bresenham line advances the major axis by one cell, so the end cell is max(dx, -dy) steps
    // away and the Chebyshev distance to it falls by one per step: a hit clears the first
    // steps - margin cells, a free-space-only ray all steps + 1 (test
    // TiledGrid.RaysClearExactlyTheirBresenhamCellsUpToTheMargin checks it cell by cell).
    const int steps = std::max(dx, -dy);
    const int cells = is_hit[k] ? steps - margin : steps + 1;
    for (int n = 0; n < cells; ++n) {
      if (!tile) tile = MutableTile(x >> kTileBits, y >> kTileBits);
      const int idx = (ly << kTileBits) | lx;
      int16_t& l = tile->log_odds[idx];
      const int old = l;
      int v = std::max<int>(neg_clamp, old + miss);
      if (v == 0) v = -1;
      l = static_cast<int16_t>(v);
      // An obstacle cell (dist 0) has log-odds >= free_threshold (hysteresis, UpdateCell), so
      // only a cell crossing free_threshold can stop being one: the common already-free cell
      // does not read its distance.
      if (old >= free_threshold && v < free_threshold && tile->dist[idx] == 0) {
        tile->occupied -= 1;
        OnBecameFree(x, y);
      }
      const int e2 = 2 * err;
      if (e2 >= dy) {
        err += dy;
        x += sx;
        lx += sx;
        if (static_cast<unsigned>(lx) >= static_cast<unsigned>(kTileSize)) {
          lx &= kTileSize - 1;
          tile = nullptr;
        }
      }
      if (e2 <= dx) {
        err += dx;
        y += sy;
        ly += sy;
        if (static_cast<unsigned>(ly) >= static_cast<unsigned>(kTileSize)) {
          ly &= kTileSize - 1;
          tile = nullptr;
        }
      }
    }
  }
  for (size_t k = 0; k < endpoints_world.size(); ++k) {
    if (!is_hit[k] || !in_range(endpoints_world[k])) continue;
    UpdateCell(static_cast<int>(std::floor(endpoints_world[k].x() * inv_res_)),
               static_cast<int>(std::floor(endpoints_world[k].y() * inv_res_)), hit_);
  }
  return true;
}

bool TiledGrid::Bounds(int* min_cx, int* min_cy, int* max_cx, int* max_cy) const {
  int tx_min = INT32_MAX, ty_min = INT32_MAX, tx_max = INT32_MIN, ty_max = INT32_MIN;
  for (int iy = 0; iy < nty_; ++iy) {
    for (int ix = 0; ix < ntx_; ++ix) {
      if (!tiles_[static_cast<size_t>(iy) * ntx_ + ix]) continue;
      tx_min = std::min(tx_min, ix + tx0_);
      ty_min = std::min(ty_min, iy + ty0_);
      tx_max = std::max(tx_max, ix + tx0_);
      ty_max = std::max(ty_max, iy + ty0_);
    }
  }
  if (tx_min == INT32_MAX) return false;
  *min_cx = tx_min * kTileSize;
  *min_cy = ty_min * kTileSize;
  *max_cx = (tx_max + 1) * kTileSize;
  *max_cy = (ty_max + 1) * kTileSize;
  return true;
}

int TiledGrid::NumTiles() const {
  int n = 0;
  for (const auto& t : tiles_) n += t ? 1 : 0;
  return n;
}

int TiledGrid::NumSharedTiles() const {
  int n = 0;
  for (const auto& t : tiles_) n += (t && t.use_count() > 1) ? 1 : 0;
  return n;
}

}  // namespace fl::rbpf
