// The simulated world: 2-D shapes extruded vertically (thin walls, boxes, round pillars) over a
// textured floor, with procedural deterministic textures, and exact ray casting against them.
//
// Frames: world frame x, y horizontal, z up; the floor is z = 0.
// Everything here is pure geometry; no randomness at query time (textures are hashes).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "fusionloc/sim/sim_options.hpp"

namespace fl::sim {

// Procedural surface textures (intensity 0..255 as a function of surface coordinates in metres).
enum class Texture : int {
  kBrick = 0,       // 0.5 m x 0.2 m bricks, random shades, dark mortar joints
  kBlocks = 1,      // random-intensity squares at two scales (0.4 m and 0.13 m)
  kPosterWall = 2,  // plain painted wall with posters and closed doors (flush: laser-smooth)
  kFloorTiles = 3,  // 0.6 m tiles, random shades, grout lines, speckles
  kCeiling = 4,     // ceiling panels with light fixtures
  kChecker = 5,     // 0.2 m checkerboard
};

// A thin wall from a to b (both faces visible), from z = 0 to `height`.
struct Wall {
  Eigen::Vector2d a, b;
  double height = 2.5;
  Texture texture = Texture::kBrick;
  uint64_t texture_seed = 0;
};

// A solid oriented box (footprint centre, half sizes along its own axes, yaw), z = 0..height.
struct Box {
  Eigen::Vector2d center;
  Eigen::Vector2d half_size;
  double yaw = 0.0;
  double height = 1.0;
  Texture texture = Texture::kBlocks;
  uint64_t texture_seed = 0;
};

// A solid round pillar, z = 0..height.
struct Pillar {
  Eigen::Vector2d center;
  double radius = 0.2;
  double height = 2.5;
  Texture texture = Texture::kChecker;
  uint64_t texture_seed = 0;
};

// One crossing of a horizontal ray with a shape: entry at t_in (and for solids the exit at
// t_out), in units of the ray direction's length.
struct RayHit {
  double t_in = 0.0;
  double t_out = 0.0;    // solids: exit; walls: = t_in
  double height = 0.0;   // [m] top of the shape
  int shape = -1;        // index into World::shapes order (walls, then boxes, then pillars)
  double s = 0.0;        // [m] horizontal surface coordinate at entry
  double normal_x = 0.0, normal_y = 0.0;  // unit outward normal at entry (facing the ray)
  bool solid = false;    // boxes and pillars have a lid (top face) visible from above
};

class World {
 public:
  World() = default;

  // Builds the named world of the options (throws std::invalid_argument on a bad name).
  // The route (closed polyline, world frame, metres) is built together with the world so that
  // random landmarks keep clear of it.
  static World Build(const SimOptions& options);

  void AddWall(const Wall& w) { walls_.push_back(w); }
  void AddBox(const Box& b) { boxes_.push_back(b); }
  void AddPillar(const Pillar& p) { pillars_.push_back(p); }
  void SetRoute(std::vector<Eigen::Vector2d> route) { route_ = std::move(route); }
  void SetFloor(Texture t, uint64_t seed) { floor_texture_ = t, floor_seed_ = seed; }
  // Ceiling at `height` (<= 0: open sky of constant intensity).
  void SetCeiling(double height, uint64_t seed) { ceiling_height_ = height, ceiling_seed_ = seed; }
  void SetName(const std::string& n) { name_ = n; }

  const std::vector<Wall>& walls() const { return walls_; }
  const std::vector<Box>& boxes() const { return boxes_; }
  const std::vector<Pillar>& pillars() const { return pillars_; }
  // Closed route: the robot drives route[0] -> route[1] -> ... -> route[0] -> ... repeatedly.
  const std::vector<Eigen::Vector2d>& route() const { return route_; }
  const std::string& name() const { return name_; }
  double ceiling_height() const { return ceiling_height_; }
  // Axis-aligned bounds of all shapes (min x, min y, max x, max y).
  Eigen::Vector4d Bounds() const;

  // Nearest hit of the horizontal ray origin + t * dir (t > t_min) with any shape whose top is
  // above `z` (the ray's height). Returns false if nothing is hit.
  bool CastHorizontal(const Eigen::Vector2d& origin, const Eigen::Vector2d& dir, double z,
                      double t_min, RayHit* hit) const;
  // All crossings of the horizontal ray with shapes (any height), sorted by t_in.
  void CastAll(const Eigen::Vector2d& origin, const Eigen::Vector2d& dir, double t_min,
               std::vector<RayHit>* hits) const;

  // Distance from a point to the nearest shape surface (for route clearance checks).
  double DistanceToObstacles(const Eigen::Vector2d& p) const;

  // Intensity (0..255) of a shape's side at surface coordinates (s, z), and of the floor and
  // ceiling at world (x, y).
  double ShapeIntensity(int shape, double s, double z) const;
  double LidIntensity(int shape, double x, double y) const;
  double FloorIntensity(double x, double y) const;
  double CeilingIntensity(double x, double y) const;

 private:
  std::string name_;
  std::vector<Wall> walls_;
  std::vector<Box> boxes_;
  std::vector<Pillar> pillars_;
  std::vector<Eigen::Vector2d> route_;
  Texture floor_texture_ = Texture::kFloorTiles;
  uint64_t floor_seed_ = 0;
  double ceiling_height_ = 0.0;
  uint64_t ceiling_seed_ = 0;
};

// Texture lookup (exposed for tests and the top-view tool).
double TextureIntensity(Texture t, uint64_t seed, double u, double v);

// Deterministic 64-bit hash of (seed, i, j) and its value in [0, 1).
uint64_t Hash3(uint64_t seed, int64_t i, int64_t j);
double Hash01(uint64_t seed, int64_t i, int64_t j);

}  // namespace fl::sim
