// Sensor models on a World: the planar laser (exact 2-D ray casting plus Gaussian range noise)
// and the stereo camera (pinhole ray casting of the textured world, supersampled, plus
// Gaussian intensity noise).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/sim/random.hpp"
#include "fusionloc/sim/sim_options.hpp"
#include "fusionloc/sim/world.hpp"

namespace fl::sim {

class LaserModel {
 public:
  explicit LaserModel(const LaserOptions& options) : options_(options) {}

  // Noise-free range of each beam from the base pose T_world_base; 0 = no return (nothing
  // within [min_range, max_range]).
  void TrueRanges(const World& world, const Pose2& T_world_base, std::vector<float>* ranges) const;
  // True ranges plus N(0, range_sigma^2); a noisy range is clamped to >= min_range and a beam
  // whose true range is a return stays a return (noise never creates or removes returns).
  void Scan(const World& world, const Pose2& T_world_base, Rng* rng,
            std::vector<float>* ranges) const;

  double BeamAngle(int i) const;  // [rad] in the laser frame
  const LaserOptions& options() const { return options_; }

 private:
  LaserOptions options_;
};

// The first surface along the ray c + t (dir, up) from a point at height c_z: dir is the
// ray's horizontal part (any length; t counts in its units), up its rise per unit of dir; hits
// are World::CastAll's crossings of the horizontal ray, sorted. The camera's pixels and the
// multi-line laser's beams both use it.
struct Surface {
  enum Kind { kSky, kFace, kLid, kFloor, kCeiling };
  Kind kind = kSky;
  double t = std::numeric_limits<double>::infinity();  // +inf for the sky
  double z = 0.0;                                       // [m] height of the point
  const RayHit* hit = nullptr;                          // kFace, kLid: the shape crossed
};
Surface FirstSurface(const World& world, double c_z, double up, const std::vector<RayHit>& hits);

// The multi-line laser (Laser3dOptions): every beam's first surface, plus Gaussian range
// noise along the beam.
class Laser3dModel {
 public:
  explicit Laser3dModel(const Laser3dOptions& options) : options_(options) {}
  // Points [m] in the laser frame (x forward, y left, z up) of every beam with a return
  // within [min_range, max_range], at base pose T_world_base; rng == nullptr: noise-free.
  void Scan(const World& world, const Pose2& T_world_base, Rng* rng,
            std::vector<Eigen::Vector3f>* points) const;
  double LineElevation(int line) const;  // [rad], line 0 the lowest
  const Laser3dOptions& options() const { return options_; }

 private:
  Laser3dOptions options_;
};

class CameraModel {
 public:
  enum Eye { kLeft = 0, kRight = 1 };
  explicit CameraModel(const CameraOptions& options) : options_(options) {}

  // Gray image (row-major, width*height bytes) seen by one camera of the rig at base pose
  // T_world_base. rng == nullptr renders without noise.
  void Render(const World& world, const Pose2& T_world_base, Eye eye, Rng* rng,
              std::vector<uint8_t>* image) const;
  // Depth (optical z, metres) at the centre of every pixel; +inf where the ray sees sky.
  void RenderDepth(const World& world, const Pose2& T_world_base, Eye eye,
                   std::vector<float>* depth) const;

  // Optical centre of a camera and the horizontal heading of its optical axis, in the world.
  Eigen::Vector3d CameraCenterWorld(const Pose2& T_world_base, Eye eye) const;
  const CameraOptions& options() const { return options_; }

 private:
  // Intensity and depth seen along the pixel ray through (u, v) (pixel coordinates, may be
  // fractional) given the sorted hits of that column's horizontal ray.
  double Shade(const World& world, const Eigen::Vector2d& c_xy, double c_z,
               const Eigen::Vector2d& dir, const std::vector<RayHit>& hits, double v,
               double* depth) const;

  CameraOptions options_;
};

}  // namespace fl::sim
