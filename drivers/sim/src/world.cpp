#include "fusionloc/sim/world.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "fusionloc/sim/random.hpp"

namespace fl::sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

inline double Cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

inline int64_t Cell(double x, double size) { return static_cast<int64_t>(std::floor(x / size)); }

// Fraction of x within its cell of `size`, in [0, size).
inline double Frac(double x, double size) { return x - std::floor(x / size) * size; }

double SegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                       const Eigen::Vector2d& b) {
  const Eigen::Vector2d e = b - a;
  const double len2 = e.squaredNorm();
  const double u = len2 > 0 ? std::clamp((p - a).dot(e) / len2, 0.0, 1.0) : 0.0;
  return (a + u * e - p).norm();
}

// Random-intensity squares at two scales: a corner at every cell junction.
double Blocks(uint64_t seed, double u, double v, double big, double small) {
  return 0.55 * Hash01(seed, Cell(u, big), Cell(v, big)) +
         0.45 * Hash01(seed + 1, Cell(u, small), Cell(v, small));
}

double PosterWall(uint64_t seed, double u, double v) {
  constexpr double kSlot = 2.2;  // [m] one poster, door or blank per slot
  if (v < 0.12) return 70.0;      // baseboard
  const int64_t slot = Cell(u, kSlot);
  const double local = u - slot * kSlot;
  const double kind = Hash01(seed, slot, 7);
  if (kind < 0.55) {  // poster
    const double w = 0.6 + 0.6 * Hash01(seed, slot, 1);
    const double a = 0.1 + (kSlot - 0.2 - w) * Hash01(seed, slot, 2);
    const double b = 1.0 + 0.3 * Hash01(seed, slot, 3);
    const double h = 0.5 + 0.4 * Hash01(seed, slot, 4);
    if (local >= a && local <= a + w && v >= b && v <= b + h) {
      const double lu = local - a, lv = v - b;
      if (lu < 0.03 || lu > w - 0.03 || lv < 0.03 || lv > h - 0.03) return 30.0;  // frame
      return 20.0 + 220.0 * Blocks(Hash3(seed, slot, 11), lu, lv, 0.15, 0.05);
    }
  } else if (kind < 0.75) {  // closed door, flush with the wall
    constexpr double kA = 0.6, kW = 0.9, kH = 2.05;
    if (local >= kA && local <= kA + kW && v <= kH) {
      const double lu = local - kA;
      if (lu < 0.05 || lu > kW - 0.05 || v > kH - 0.05) return 50.0;               // frame
      if (lu > kW - 0.17 && lu < kW - 0.09 && v > 0.95 && v < 1.0) return 25.0;  // handle
      if (v > 1.55 && v < 1.75 && lu > 0.25 && lu < 0.65) return 235.0;          // name plate
      return 115.0;
    }
  }
  return 185.0;  // painted wall
}

}  // namespace

uint64_t Hash3(uint64_t seed, int64_t i, int64_t j) {
  // splitmix64 finaliser over a combination of the inputs.
  uint64_t z = seed * 0x9E3779B97F4A7C15ull + static_cast<uint64_t>(i) * 0xBF58476D1CE4E5B9ull +
               static_cast<uint64_t>(j) * 0x94D049BB133111EBull + 0x2545F4914F6CDD1Dull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

double Hash01(uint64_t seed, int64_t i, int64_t j) {
  return static_cast<double>(Hash3(seed, i, j) >> 11) * 0x1.0p-53;
}

double TextureIntensity(Texture t, uint64_t seed, double u, double v) {
  switch (t) {
    case Texture::kBrick: {
      const int64_t row = Cell(v, 0.2);
      const double uu = u + ((row & 1) ? 0.25 : 0.0);
      const int64_t col = Cell(uu, 0.5);
      if (Frac(uu, 0.5) < 0.025 || Frac(v, 0.2) < 0.025) return 60.0;  // mortar
      return 95.0 + 120.0 * Hash01(seed, col, row);
    }
    case Texture::kBlocks:
      return 30.0 + 200.0 * Blocks(seed, u, v, 0.4, 0.13);
    case Texture::kPosterWall:
      return PosterWall(seed, u, v);
    case Texture::kFloorTiles: {
      if (Frac(u, 0.6) < 0.02 || Frac(v, 0.6) < 0.02) return 65.0;  // grout
      const double tile = Hash01(seed, Cell(u, 0.6), Cell(v, 0.6));
      const double speckle = Hash01(seed + 2, Cell(u, 0.08), Cell(v, 0.08)) - 0.5;
      return 100.0 + 80.0 * tile + 40.0 * speckle;
    }
    case Texture::kCeiling: {
      if (Frac(u, 1.2) < 0.03 || Frac(v, 1.2) < 0.03) return 120.0;
      const int64_t i = Cell(u, 1.2), j = Cell(v, 1.2);
      if (Hash01(seed, i, j) < 0.25) return 250.0;  // light fixture
      return 200.0;
    }
    case Texture::kChecker: {
      const int64_t i = Cell(u, 0.2), j = Cell(v, 0.2);
      const double jitter = 40.0 * (Hash01(seed, i, j) - 0.5);
      return (((i + j) & 1) ? 195.0 : 55.0) + jitter;
    }
  }
  return 128.0;
}

// ------------------------------------------------------------------------------------------
// Ray casting

void World::CastAll(const Eigen::Vector2d& o, const Eigen::Vector2d& d, double t_min,
                    std::vector<RayHit>* hits) const {
  hits->clear();
  const int nw = static_cast<int>(walls_.size());
  const int nb = static_cast<int>(boxes_.size());
  for (int i = 0; i < nw; ++i) {
    const Wall& w = walls_[i];
    const Eigen::Vector2d e = w.b - w.a;
    const double denom = Cross(d, e);
    if (std::fabs(denom) < 1e-15) continue;  // parallel: grazing rays see nothing
    const Eigen::Vector2d ao = w.a - o;
    const double t = Cross(ao, e) / denom;
    const double u = Cross(ao, d) / denom;
    if (t <= t_min || u < 0.0 || u > 1.0) continue;
    RayHit h;
    h.t_in = h.t_out = t;
    h.height = w.height;
    h.shape = i;
    h.s = u * e.norm();
    Eigen::Vector2d n(-e.y(), e.x());
    n.normalize();
    if (n.dot(d) > 0) n = -n;
    h.normal_x = n.x();
    h.normal_y = n.y();
    hits->push_back(h);
  }
  for (int i = 0; i < nb; ++i) {
    const Box& b = boxes_[i];
    const double c = std::cos(b.yaw), s = std::sin(b.yaw);
    const Eigen::Vector2d rel = o - b.center;
    const Eigen::Vector2d ol(c * rel.x() + s * rel.y(), -s * rel.x() + c * rel.y());
    const Eigen::Vector2d dl(c * d.x() + s * d.y(), -s * d.x() + c * d.y());
    double t_near = -kInf, t_far = kInf;
    int axis = -1;
    bool miss = false;
    for (int k = 0; k < 2; ++k) {
      if (std::fabs(dl[k]) < 1e-15) {
        if (std::fabs(ol[k]) > b.half_size[k]) miss = true;
        continue;
      }
      double t1 = (-b.half_size[k] - ol[k]) / dl[k];
      double t2 = (b.half_size[k] - ol[k]) / dl[k];
      if (t1 > t2) std::swap(t1, t2);
      if (t1 > t_near) {
        t_near = t1;
        axis = k;
      }
      t_far = std::min(t_far, t2);
    }
    if (miss || axis < 0 || t_near > t_far || t_near <= t_min) continue;
    const Eigen::Vector2d p = ol + t_near * dl;
    const double hx = b.half_size.x(), hy = b.half_size.y();
    Eigen::Vector2d nl = Eigen::Vector2d::Zero();
    double perimeter_s;
    if (axis == 0) {
      nl.x() = dl.x() > 0 ? -1.0 : 1.0;
      perimeter_s = nl.x() > 0 ? p.y() + hy : 2 * hy + 2 * hx + (hy - p.y());
    } else {
      nl.y() = dl.y() > 0 ? -1.0 : 1.0;
      perimeter_s = nl.y() > 0 ? 2 * hy + (hx - p.x()) : 4 * hy + 2 * hx + (p.x() + hx);
    }
    RayHit h;
    h.t_in = t_near;
    h.t_out = t_far;
    h.height = b.height;
    h.shape = nw + i;
    h.s = perimeter_s;
    h.normal_x = c * nl.x() - s * nl.y();
    h.normal_y = s * nl.x() + c * nl.y();
    h.solid = true;
    hits->push_back(h);
  }
  for (size_t i = 0; i < pillars_.size(); ++i) {
    const Pillar& p = pillars_[i];
    const Eigen::Vector2d oc = o - p.center;
    const double a = d.squaredNorm();
    const double b = 2.0 * d.dot(oc);
    const double c = oc.squaredNorm() - p.radius * p.radius;
    const double disc = b * b - 4.0 * a * c;
    if (disc <= 0.0) continue;
    const double sq = std::sqrt(disc);
    const double t1 = (-b - sq) / (2.0 * a);
    const double t2 = (-b + sq) / (2.0 * a);
    if (t1 <= t_min) continue;
    const Eigen::Vector2d n = (oc + t1 * d) / p.radius;
    RayHit h;
    h.t_in = t1;
    h.t_out = t2;
    h.height = p.height;
    h.shape = nw + nb + static_cast<int>(i);
    h.s = p.radius * (std::atan2(n.y(), n.x()) + M_PI);
    h.normal_x = n.x();
    h.normal_y = n.y();
    h.solid = true;
    hits->push_back(h);
  }
  std::sort(hits->begin(), hits->end(), [](const RayHit& x, const RayHit& y) {
    return x.t_in < y.t_in || (x.t_in == y.t_in && x.shape < y.shape);
  });
}

bool World::CastHorizontal(const Eigen::Vector2d& origin, const Eigen::Vector2d& dir, double z,
                           double t_min, RayHit* hit) const {
  // Shapes are few (tens); a linear pass is exact and fast enough (see docs/SIMULATOR.md).
  thread_local std::vector<RayHit> hits;
  CastAll(origin, dir, t_min, &hits);
  for (const RayHit& h : hits) {
    if (h.height > z && z >= 0.0) {
      *hit = h;
      return true;
    }
  }
  return false;
}

double World::DistanceToObstacles(const Eigen::Vector2d& p) const {
  double best = kInf;
  for (const Wall& w : walls_) best = std::min(best, SegmentDistance(p, w.a, w.b));
  for (const Box& b : boxes_) {
    const double c = std::cos(b.yaw), s = std::sin(b.yaw);
    const Eigen::Vector2d rel = p - b.center;
    const Eigen::Vector2d q(std::fabs(c * rel.x() + s * rel.y()) - b.half_size.x(),
                            std::fabs(-s * rel.x() + c * rel.y()) - b.half_size.y());
    const double outside = q.cwiseMax(0.0).norm();
    const double inside = std::min(std::max(q.x(), q.y()), 0.0);
    best = std::min(best, outside + inside);
  }
  for (const Pillar& pl : pillars_) best = std::min(best, (p - pl.center).norm() - pl.radius);
  return best;
}

Eigen::Vector4d World::Bounds() const {
  Eigen::Vector4d b(kInf, kInf, -kInf, -kInf);
  auto add = [&b](const Eigen::Vector2d& p, double r) {
    b[0] = std::min(b[0], p.x() - r);
    b[1] = std::min(b[1], p.y() - r);
    b[2] = std::max(b[2], p.x() + r);
    b[3] = std::max(b[3], p.y() + r);
  };
  for (const Wall& w : walls_) add(w.a, 0), add(w.b, 0);
  for (const Box& x : boxes_) add(x.center, x.half_size.norm());
  for (const Pillar& p : pillars_) add(p.center, p.radius);
  for (const Eigen::Vector2d& p : route_) add(p, 0);
  return b;
}

double World::ShapeIntensity(int shape, double s, double z) const {
  const int nw = static_cast<int>(walls_.size());
  const int nb = static_cast<int>(boxes_.size());
  if (shape < nw) return TextureIntensity(walls_[shape].texture, walls_[shape].texture_seed, s, z);
  if (shape < nw + nb) {
    const Box& b = boxes_[shape - nw];
    return TextureIntensity(b.texture, b.texture_seed, s, z);
  }
  const Pillar& p = pillars_[shape - nw - nb];
  return TextureIntensity(p.texture, p.texture_seed, s, z);
}

double World::LidIntensity(int shape, double x, double y) const {
  const int nw = static_cast<int>(walls_.size());
  const int nb = static_cast<int>(boxes_.size());
  if (shape >= nw && shape < nw + nb) {
    const Box& b = boxes_[shape - nw];
    return TextureIntensity(Texture::kBlocks, b.texture_seed + 17, x, y);
  }
  if (shape >= nw + nb) {
    return TextureIntensity(Texture::kChecker, pillars_[shape - nw - nb].texture_seed + 17, x, y);
  }
  return 128.0;
}

double World::FloorIntensity(double x, double y) const {
  return TextureIntensity(floor_texture_, floor_seed_, x, y);
}

double World::CeilingIntensity(double x, double y) const {
  if (ceiling_height_ <= 0.0) return 235.0;  // sky
  return TextureIntensity(Texture::kCeiling, ceiling_seed_, x, y);
}

// ------------------------------------------------------------------------------------------
// The worlds

namespace {

// Paper world: 30 m x 30 m walled square centred on the origin; a figure-eight route whose two
// lobes cross at the origin; random pillars and boxes kept clear of the route.
World BuildPaper(const SimOptions& o) {
  World w;
  w.SetName("paper");
  Rng rng(Hash3(static_cast<uint64_t>(o.seed), 1, 0));
  const double h = o.world.wall_height_m;
  const double r = 15.0;
  const Eigen::Vector2d c[4] = {{-r, -r}, {r, -r}, {r, r}, {-r, r}};
  for (int i = 0; i < 4; ++i) {
    w.AddWall({c[i], c[(i + 1) % 4], h, Texture::kBrick, rng.Next()});
  }
  w.SetFloor(Texture::kFloorTiles, rng.Next());
  w.SetCeiling(0.0, 0);
  constexpr double a = 6.0;
  std::vector<Eigen::Vector2d> route = {{0, 0},  {a, 0},  {a, a},  {0, a},
                                        {0, -a}, {-a, -a}, {-a, 0}};
  w.SetRoute(route);

  auto route_distance = [&route](const Eigen::Vector2d& p) {
    double best = kInf;
    for (size_t i = 0; i < route.size(); ++i) {
      best = std::min(best, SegmentDistance(p, route[i], route[(i + 1) % route.size()]));
    }
    return best;
  };
  // Rejection sampling; each landmark is described by its centre and bounding radius.
  std::vector<std::pair<Eigen::Vector2d, double>> placed;
  int attempts = 0;
  while (static_cast<int>(placed.size()) < o.world.landmarks && attempts < 200000) {
    ++attempts;
    const bool pillar = rng.Uniform() < 0.5;
    const double radius = pillar ? rng.Uniform(0.15, 0.4) : 0.0;
    const Eigen::Vector2d half(rng.Uniform(0.2, 0.7), rng.Uniform(0.2, 0.7));
    const double bound = pillar ? radius : half.norm();
    const Eigen::Vector2d p(rng.Uniform(-r + 0.5 + bound, r - 0.5 - bound),
                            rng.Uniform(-r + 0.5 + bound, r - 0.5 - bound));
    const double yaw = rng.Uniform(-M_PI, M_PI);
    const double height = pillar ? rng.Uniform(1.5, h) : rng.Uniform(0.6, 1.5);
    const uint64_t seed = rng.Next();
    if (route_distance(p) - bound < o.world.route_clearance_m) continue;
    bool overlaps = false;
    for (const auto& q : placed) overlaps |= (p - q.first).norm() < bound + q.second + 0.5;
    if (overlaps) continue;
    placed.emplace_back(p, bound);
    if (pillar) {
      w.AddPillar({p, radius, height, (seed & 1) ? Texture::kChecker : Texture::kBlocks, seed});
    } else {
      w.AddBox({p, half, yaw, height, Texture::kBlocks, seed});
    }
  }
  if (static_cast<int>(placed.size()) < o.world.landmarks) {
    throw std::invalid_argument("world.landmarks = " + std::to_string(o.world.landmarks) +
                                " do not fit clear of the route; use fewer landmarks or a "
                                "smaller world.route_clearance_m");
  }
  return w;
}

// Corridor world: a long corridor along x with three rooms off it through open doorways.
// Walls are straight and unbroken between doorways (featureless for the laser) but textured
// with posters and flush doors for the camera. Route: from below room A east to room C (south),
// loop inside, on to room B (north), loop, back west the whole corridor to room A, loop.
World BuildCorridor(const SimOptions& o) {
  World w;
  w.SetName("corridor");
  Rng rng(Hash3(static_cast<uint64_t>(o.seed), 2, 0));
  const double h = o.world.wall_height_m;
  const double half_len = 0.5 * o.world.corridor_length_m;
  const double hw = 0.5 * o.world.corridor_width_m;
  constexpr double kRoomW = 6.0, kRoomD = 5.0, kDoor = 1.6;
  struct Room {
    double xc;
    int side;  // +1 north, -1 south
  };
  const Room rooms[3] = {{-half_len + 5.0, +1}, {half_len - 20.0, -1}, {half_len - 5.0, +1}};
  w.SetFloor(Texture::kFloorTiles, rng.Next());
  w.SetCeiling(h, rng.Next());

  // Corridor side walls, broken by doorways.
  for (int side : {+1, -1}) {
    double x = -half_len;
    const double y = side * hw;
    for (const Room& room : rooms) {
      if (room.side != side) continue;
      w.AddWall({{x, y}, {room.xc - kDoor / 2, y}, h, Texture::kPosterWall, rng.Next()});
      x = room.xc + kDoor / 2;
    }
    w.AddWall({{x, y}, {half_len, y}, h, Texture::kPosterWall, rng.Next()});
  }
  w.AddWall({{-half_len, -hw}, {-half_len, hw}, h, Texture::kPosterWall, rng.Next()});
  w.AddWall({{half_len, -hw}, {half_len, hw}, h, Texture::kPosterWall, rng.Next()});

  for (const Room& room : rooms) {
    const double s = room.side;
    const double y0 = s * hw, y1 = s * (hw + kRoomD);
    const double x0 = room.xc - kRoomW / 2, x1 = room.xc + kRoomW / 2;
    const Texture t = (room.xc < 0) ? Texture::kBrick : Texture::kBlocks;
    w.AddWall({{x0, y0}, {x0, y1}, h, t, rng.Next()});
    w.AddWall({{x0, y1}, {x1, y1}, h, t, rng.Next()});
    w.AddWall({{x1, y1}, {x1, y0}, h, t, rng.Next()});
    // Furniture: cabinets in the two back corners and a pillar in the middle.
    const double yc = s * (hw + kRoomD / 2);
    for (int k : {-1, 1}) {
      const Eigen::Vector2d half(rng.Uniform(0.25, 0.4), rng.Uniform(0.25, 0.4));
      const Eigen::Vector2d centre(room.xc + k * (kRoomW / 2 - 0.6), y1 - s * 0.6);
      w.AddBox({centre, half, rng.Uniform(-0.3, 0.3), rng.Uniform(0.7, 1.6), Texture::kBlocks,
                rng.Next()});
    }
    w.AddPillar({{room.xc, yc}, 0.25, h, Texture::kChecker, rng.Next()});
  }
  // Route: from the corridor below room A into room A and round it, out and east to room C
  // (south), round it, on to room B (north, east end), round it, and back west along the whole
  // corridor to the start. Each room is entered and left along the doorway's centre line.
  std::vector<Eigen::Vector2d> route;
  for (const Room& room : {rooms[0], rooms[1], rooms[2]}) {
    const double s = room.side;
    const double yc = s * (hw + kRoomD / 2);
    const double xc = room.xc;
    constexpr double lx = 1.3, ly = 1.1;  // half sizes of the loop around the room's pillar
    route.push_back({xc, 0.0});
    route.push_back({xc, yc - s * ly});
    route.push_back({xc + lx, yc - s * ly});
    route.push_back({xc + lx, yc + s * ly});
    route.push_back({xc - lx, yc + s * ly});
    route.push_back({xc - lx, yc - s * ly});
    route.push_back({xc, yc - s * ly});
    route.push_back({xc, 0.0});
  }
  w.SetRoute(route);
  return w;
}

}  // namespace

World World::Build(const SimOptions& options) {
  if (options.world.name == "paper") return BuildPaper(options);
  if (options.world.name == "corridor") return BuildCorridor(options);
  throw std::invalid_argument("unknown world '" + options.world.name +
                              "'; use 'paper' or 'corridor'");
}

}  // namespace fl::sim
