#include "fusionloc/sim/sensors.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace fl::sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kDegToRad = M_PI / 180.0;

// Fixed light direction (horizontal part) for Lambert-like shading of vertical faces, so that
// the faces of a box differ in brightness like under a real light.
const Eigen::Vector2d kLight = Eigen::Vector2d(0.6, 0.8);

}  // namespace

// ------------------------------------------------------------------------------------------
// Laser

double LaserModel::BeamAngle(int i) const {
  return (options_.first_angle_deg + i * options_.step_deg) * kDegToRad;
}

void LaserModel::TrueRanges(const World& world, const Pose2& T_world_base,
                            std::vector<float>* ranges) const {
  const Pose2 T_world_laser = T_world_base * Pose2(options_.x_m, options_.y_m, 0.0);
  const Eigen::Vector2d origin = T_world_laser.translation();
  ranges->assign(static_cast<size_t>(options_.beams), 0.0f);
  for (int i = 0; i < options_.beams; ++i) {
    const double a = T_world_laser.theta + BeamAngle(i);
    RayHit hit;
    if (!world.CastHorizontal(origin, Eigen::Vector2d(std::cos(a), std::sin(a)), options_.z_m,
                              0.0, &hit)) {
      continue;
    }
    if (hit.t_in >= options_.min_range_m && hit.t_in <= options_.max_range_m) {
      (*ranges)[static_cast<size_t>(i)] = static_cast<float>(hit.t_in);
    }
  }
}

void LaserModel::Scan(const World& world, const Pose2& T_world_base, Rng* rng,
                      std::vector<float>* ranges) const {
  TrueRanges(world, T_world_base, ranges);
  for (float& r : *ranges) {
    const double noise = rng->Normal(options_.range_sigma_m);  // drawn for every beam
    if (r > 0.0f) r = static_cast<float>(std::max(options_.min_range_m, r + noise));
  }
}

// ------------------------------------------------------------------------------------------
// Multi-line laser

double Laser3dModel::LineElevation(int line) const {
  const int n = options_.lines;
  const double fov = options_.vertical_fov_deg * kDegToRad;
  return n == 1 ? 0.0 : -0.5 * fov + fov * line / (n - 1);
}

void Laser3dModel::Scan(const World& world, const Pose2& T_world_base, Rng* rng,
                        std::vector<Eigen::Vector3f>* points) const {
  points->clear();
  const Pose2 T_world_laser = T_world_base * Pose2(options_.x_m, options_.y_m, 0.0);
  const Eigen::Vector2d origin = T_world_laser.translation();
  const int azimuths = std::max(1, static_cast<int>(std::lround(360.0 / options_.azimuth_step_deg)));
  std::vector<double> slope(static_cast<size_t>(options_.lines));
  std::vector<double> cos_e(slope.size()), sin_e(slope.size());
  for (int line = 0; line < options_.lines; ++line) {
    const double e = LineElevation(line);
    slope[static_cast<size_t>(line)] = std::tan(e);
    cos_e[static_cast<size_t>(line)] = std::cos(e);
    sin_e[static_cast<size_t>(line)] = std::sin(e);
  }
  std::vector<RayHit> hits;
  for (int a = 0; a < azimuths; ++a) {
    const double azimuth = a * options_.azimuth_step_deg * kDegToRad;  // in the laser frame
    const double heading = T_world_laser.theta + azimuth;
    const Eigen::Vector2d dir(std::cos(heading), std::sin(heading));  // unit: t is horizontal
    world.CastAll(origin, dir, 1e-9, &hits);
    for (size_t line = 0; line < slope.size(); ++line) {
      const Surface surface = FirstSurface(world, options_.z_m, slope[line], hits);
      if (surface.kind == Surface::kSky) continue;
      const double range = surface.t / cos_e[line];  // along the beam
      if (range < options_.min_range_m || range > options_.max_range_m) continue;
      // Noise draws only for returns: the scan is deterministic given the seed.
      const double r = std::max(options_.min_range_m,
                                range + (rng != nullptr ? rng->Normal(options_.range_sigma_m) : 0.0));
      points->emplace_back(static_cast<float>(r * cos_e[line] * std::cos(azimuth)),
                           static_cast<float>(r * cos_e[line] * std::sin(azimuth)),
                           static_cast<float>(r * sin_e[line]));
    }
  }
}

// ------------------------------------------------------------------------------------------
// Camera

Eigen::Vector3d CameraModel::CameraCenterWorld(const Pose2& T_world_base, Eye eye) const {
  const double y = options_.y_m - (eye == kRight ? options_.baseline_m : 0.0);
  const Eigen::Vector2d c = T_world_base * Eigen::Vector2d(options_.x_m, y);
  return {c.x(), c.y(), options_.z_m};
}

// The pixel ray (u, v) is, in the world, c + t * (f - (u - cx)/fx * l + up(v) * z) with f and l
// the base's forward and left axes and up(v) = -(v - cy)/fx. Its optical z component is 1, so
// t is the depth. All rays of an image column share the horizontal part `dir`, so the 2-D
// crossings (`hits`) are computed once per column and only the heights differ per row.
Surface FirstSurface(const World& world, double c_z, double up, const std::vector<RayHit>& hits) {
  Surface out;
  const double ceiling = world.ceiling_height();
  const double t_floor = up < 0.0 ? c_z / -up : kInf;
  const double t_ceiling = (ceiling > 0.0 && up > 0.0) ? (ceiling - c_z) / up : kInf;
  const double t_limit = std::min(t_floor, t_ceiling);
  for (const RayHit& h : hits) {
    if (h.t_in >= t_limit) break;
    const double z = c_z + up * h.t_in;
    if (z >= 0.0 && z <= h.height) {
      out.kind = Surface::kFace;
      out.t = h.t_in;
      out.z = z;
      out.hit = &h;
      return out;
    }
    if (h.solid && up < 0.0 && z > h.height) {
      const double t_lid = (c_z - h.height) / -up;
      if (t_lid < h.t_out) {
        out.kind = Surface::kLid;
        out.t = t_lid;
        out.z = h.height;
        out.hit = &h;
        return out;
      }
    }
  }
  if (t_floor < t_ceiling) {
    out.kind = Surface::kFloor;
    out.t = t_floor;
  } else if (t_ceiling < kInf) {
    out.kind = Surface::kCeiling;
    out.t = t_ceiling;
    out.z = ceiling;
  }
  return out;
}

double CameraModel::Shade(const World& world, const Eigen::Vector2d& c_xy, double c_z,
                          const Eigen::Vector2d& dir, const std::vector<RayHit>& hits, double v,
                          double* depth) const {
  const double up = -(v - options_.cy) / options_.fx;
  const Surface surface = FirstSurface(world, c_z, up, hits);
  *depth = surface.t;
  const Eigen::Vector2d p = c_xy + (std::isfinite(surface.t) ? surface.t : 0.0) * dir;
  switch (surface.kind) {
    case Surface::kFace: {
      const RayHit& h = *surface.hit;
      const double lambert = std::fabs(kLight.x() * h.normal_x + kLight.y() * h.normal_y);
      return world.ShapeIntensity(h.shape, h.s, surface.z) * (0.6 + 0.4 * lambert);
    }
    case Surface::kLid:
      return world.LidIntensity(surface.hit->shape, p.x(), p.y());
    case Surface::kFloor:
      return 0.9 * world.FloorIntensity(p.x(), p.y());
    case Surface::kCeiling:
      return 0.95 * world.CeilingIntensity(p.x(), p.y());
    case Surface::kSky:
      break;
  }
  return world.CeilingIntensity(0.0, 0.0);  // sky
}

void CameraModel::Render(const World& world, const Pose2& T_world_base, Eye eye, Rng* rng,
                         std::vector<uint8_t>* image) const {
  const int w = options_.width, h = options_.height, ss = options_.supersampling;
  const Eigen::Vector3d c = CameraCenterWorld(T_world_base, eye);
  const Eigen::Vector2d c_xy = c.head<2>();
  const Eigen::Vector2d f(std::cos(T_world_base.theta), std::sin(T_world_base.theta));
  const Eigen::Vector2d l(-f.y(), f.x());
  std::vector<float> acc(static_cast<size_t>(w) * h, 0.0f);
  std::vector<RayHit> hits;
  double depth = 0.0;
  for (int u = 0; u < w; ++u) {
    for (int i = 0; i < ss; ++i) {
      const double us = u - 0.5 + (i + 0.5) / ss;
      const Eigen::Vector2d dir = f - ((us - options_.cx) / options_.fx) * l;
      world.CastAll(c_xy, dir, 1e-9, &hits);
      for (int v = 0; v < h; ++v) {
        double sum = 0.0;
        for (int j = 0; j < ss; ++j) {
          sum += Shade(world, c_xy, c.z(), dir, hits, v - 0.5 + (j + 0.5) / ss, &depth);
        }
        acc[static_cast<size_t>(v) * w + u] += static_cast<float>(sum);
      }
    }
  }
  image->resize(acc.size());
  const double scale = 1.0 / (ss * ss);
  const double sigma = options_.pixel_noise_sigma;
  for (size_t k = 0; k < acc.size(); ++k) {
    double value = acc[k] * scale;
    if (rng != nullptr && sigma > 0.0) value += rng->Normal(sigma);
    (*image)[k] = static_cast<uint8_t>(std::clamp(std::lround(value), 0L, 255L));
  }
}

void CameraModel::RenderDepth(const World& world, const Pose2& T_world_base, Eye eye,
                              std::vector<float>* depth) const {
  const int w = options_.width, h = options_.height;
  const Eigen::Vector3d c = CameraCenterWorld(T_world_base, eye);
  const Eigen::Vector2d f(std::cos(T_world_base.theta), std::sin(T_world_base.theta));
  const Eigen::Vector2d l(-f.y(), f.x());
  depth->assign(static_cast<size_t>(w) * h, 0.0f);
  std::vector<RayHit> hits;
  for (int u = 0; u < w; ++u) {
    const Eigen::Vector2d dir = f - ((u - options_.cx) / options_.fx) * l;
    world.CastAll(c.head<2>(), dir, 1e-9, &hits);
    for (int v = 0; v < h; ++v) {
      double d = 0.0;
      Shade(world, c.head<2>(), c.z(), dir, hits, v, &d);
      (*depth)[static_cast<size_t>(v) * w + u] = static_cast<float>(d);
    }
  }
}

}  // namespace fl::sim
