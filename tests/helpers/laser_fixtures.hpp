// Synthetic planar laser data for tests: a polygonal world (walls as line segments), exact
// ray casting, and a closed-loop drive with seeded noisy odometry.
//
//   fl::test::LaserWorld world = fl::test::LaserWorld::RoomWithBoxes();
//   std::vector<float> ranges = world.Scan(T_world_laser, 181, -M_PI / 2, M_PI / 180, 30.0);
//   auto run = fl::test::MakeLoopRun(world, {...});   // scans + true and odometry poses
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::test {

struct Segment {
  Eigen::Vector2d a, b;
};

class LaserWorld {
 public:
  void AddSegment(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { segments_.push_back({a, b}); }
  // Axis-aligned rectangle outline [x0, x1] x [y0, y1].
  void AddBox(double x0, double y0, double x1, double y1) {
    AddSegment({x0, y0}, {x1, y0});
    AddSegment({x1, y0}, {x1, y1});
    AddSegment({x1, y1}, {x0, y1});
    AddSegment({x0, y1}, {x0, y0});
  }

  // A 20 m x 12 m room with a 14 m x 6 m block in the middle (a loop corridor around it, 3 m
  // wide) and boxes / pillars along the corridor so that no stretch looks the same.
  static LaserWorld RoomWithBoxes() {
    LaserWorld w;
    w.AddBox(-10, -6, 10, 6);
    w.AddBox(-7, -3, 7, 3);
    w.AddBox(-9.6, -5.6, -9.0, -5.0);
    w.AddBox(-3.0, -6.0, -2.4, -5.4);
    w.AddBox(2.0, 5.2, 3.1, 6.0);
    w.AddBox(9.2, 0.5, 10.0, 1.5);  // clear of the loop path at x = 8.5
    w.AddBox(-10.0, 1.0, -9.4, 2.2);
    w.AddBox(4.0, -6.0, 4.4, -5.2);
    w.AddBox(-5.0, 5.5, -4.2, 6.0);
    // Notches in the central block.
    w.AddBox(-1.0, 3.0, 0.0, 3.5);
    w.AddBox(5.0, -3.6, 5.8, -3.0);
    w.AddBox(7.0, 1.0, 7.5, 2.0);
    return w;
  }

  // A straight corridor with smooth walls at y = ±width/2 from x = 0 to x = length, closed at
  // both ends: along its axis a laser of shorter range than the length sees nothing.
  static LaserWorld Corridor(double length, double width) {
    LaserWorld w;
    w.AddBox(0.0, -width / 2, length, width / 2);
    return w;
  }

  // Range along a ray (origin, unit direction); +inf if nothing within max_range.
  double Cast(const Eigen::Vector2d& o, const Eigen::Vector2d& d, double max_range) const {
    double best = std::numeric_limits<double>::infinity();
    for (const Segment& s : segments_) {
      const Eigen::Vector2d e = s.b - s.a;
      const double den = d.x() * (-e.y()) - d.y() * (-e.x());
      if (std::abs(den) < 1e-12) continue;
      const Eigen::Vector2d r = s.a - o;
      const double t = (r.x() * (-e.y()) - r.y() * (-e.x())) / den;
      const double u = (d.x() * r.y() - d.y() * r.x()) / den;
      if (t > 1e-9 && u >= 0.0 && u <= 1.0 && t < best) best = t;
    }
    return best <= max_range ? best : std::numeric_limits<double>::infinity();
  }

  // A scan from the laser pose: beam k at bearing rad0 + k * radstep; no return = +inf.
  std::vector<float> Scan(const fl::Pose2& T_world_laser, int beams, double rad0, double radstep,
                          double max_range, double noise_sigma = 0.0,
                          std::mt19937* rng = nullptr) const {
    std::vector<float> out(beams);
    std::normal_distribution<double> n(0.0, noise_sigma > 0 ? noise_sigma : 1.0);
    for (int k = 0; k < beams; ++k) {
      const double a = T_world_laser.theta + rad0 + k * radstep;
      double r = Cast(T_world_laser.translation(), {std::cos(a), std::sin(a)}, max_range);
      if (std::isfinite(r) && noise_sigma > 0 && rng) r += n(*rng);
      out[k] = static_cast<float>(r);
    }
    return out;
  }

  const std::vector<Segment>& segments() const { return segments_; }

 private:
  std::vector<Segment> segments_;
};

// The finite returns of a scan of `beams` beams evenly over `fov` rad, centred ahead, from
// `pose`, as points in the laser frame; range noise `noise` [m] drawn from rng.
inline std::vector<Eigen::Vector2d> FanPoints(const LaserWorld& world, const fl::Pose2& pose,
                                              int beams, double fov, double max_range,
                                              double noise, std::mt19937* rng) {
  const double step = fov / (beams - 1);
  const auto r = world.Scan(pose, beams, -fov / 2, step, max_range, noise, rng);
  std::vector<Eigen::Vector2d> pts;
  for (int k = 0; k < beams; ++k) {
    if (!std::isfinite(r[k])) continue;
    const double a = -fov / 2 + k * step;
    pts.emplace_back(r[k] * std::cos(a), r[k] * std::sin(a));
  }
  return pts;
}

// The finite returns of a 361-beam, 180° scan (0.5° steps, first beam at the right) from `pose`,
// as points in the laser frame; range noise `noise` [m] drawn with `seed`.
inline std::vector<Eigen::Vector2d> ScanPoints(const LaserWorld& world, const fl::Pose2& pose,
                                               double noise, unsigned seed) {
  std::mt19937 rng(seed);
  return FanPoints(world, pose, 361, M_PI, 25.0, noise, &rng);
}

struct LoopRunOptions {
  int laps = 1;                 // times around the loop corridor
  double step_m = 0.1;          // [m] travel between scans
  int beams = 181;
  double rad0 = -M_PI / 2;
  double radstep = M_PI / 180;
  double max_range = 25.0;
  double range_noise = 0.01;    // [m]
  double odom_trans_noise = 0.03;  // [m/m] std of translation error per metre
  double odom_rot_noise = 0.02;    // [rad/m] std of heading error per metre (plus a bias below)
  double odom_rot_bias = 0.01;     // [rad/m] systematic heading drift
  unsigned seed = 7;
};

struct LoopRun {
  std::vector<fl::Utime> utimes;
  std::vector<std::vector<float>> ranges;
  std::vector<fl::Pose2> truth;  // T_world_base
  std::vector<fl::Pose2> odom;   // T_odom_base (drifting)
};

// Scans of `world` along `path` (T_world_base, the laser at the base) at 10 scans per second,
// with odometry drifting by o's noise (the loop options of o are unused).
inline LoopRun MakePathRun(const LaserWorld& world, const std::vector<fl::Pose2>& path,
                           const LoopRunOptions& o) {
  LoopRun run;
  std::mt19937 rng(o.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  fl::Pose2 odom = path.front();
  for (size_t k = 0; k < path.size(); ++k) {
    if (k > 0) {
      const fl::Pose2 u = path[k - 1].between(path[k]);
      const double d = std::hypot(u.x, u.y) + 0.2 * std::abs(u.theta);
      const fl::Pose2 noisy(u.x + o.odom_trans_noise * std::sqrt(d) * n01(rng),
                            u.y + o.odom_trans_noise * std::sqrt(d) * n01(rng),
                            u.theta + o.odom_rot_bias * d + o.odom_rot_noise * std::sqrt(d) * n01(rng));
      odom = odom * noisy;
    }
    run.utimes.push_back(1000000 + static_cast<fl::Utime>(k) * 100000);
    run.truth.push_back(path[k]);
    run.odom.push_back(odom);
    run.ranges.push_back(world.Scan(path[k], o.beams, o.rad0, o.radstep, o.max_range, o.range_noise, &rng));
  }
  return run;
}

// Makes the odometry's heading lead the truth by `scans` scans (a laser stamped late against
// the wheels: raw CSAIL's turns start and end 0.1-0.2 s early in its odometry); its positions
// are unchanged. In a turn in place at 1.5 rad/s, two scans are 0.3 rad.
inline void LeadOdometryHeading(LoopRun* run, size_t scans) {
  const size_t n = run->odom.size();
  std::vector<fl::Pose2> led = run->odom;
  for (size_t k = 0; k < n; ++k) {
    const size_t ahead = std::min(k + scans, n - 1);
    led[k].theta = fl::WrapAngle(run->odom[k].theta +
                                 run->truth[k].between(run->truth[ahead]).theta);
  }
  run->odom = std::move(led);
}

// Drives counter-clockwise around the corridor (rectangle x ±8.5, y ±4.5, rounded corners)
// starting at (-8.5, -4.5) heading +x, at 10 scans per second.
inline LoopRun MakeLoopRun(const LaserWorld& world, const LoopRunOptions& o) {
  // Waypoints of the loop.
  const std::vector<Eigen::Vector2d> wp = {{-8.5, -4.5}, {8.5, -4.5}, {8.5, 4.5}, {-8.5, 4.5}};
  std::vector<fl::Pose2> path;
  for (int lap = 0; lap < o.laps; ++lap) {
    for (int s = 0; s < 4; ++s) {
      const Eigen::Vector2d a = wp[s], b = wp[(s + 1) % 4];
      const double len = (b - a).norm();
      const double heading = std::atan2(b.y() - a.y(), b.x() - a.x());
      const int n = static_cast<int>(std::round(len / o.step_m));
      for (int i = 0; i < n; ++i) path.emplace_back(a.x() + (b - a).x() * i / n, a.y() + (b - a).y() * i / n, heading);
      // Turn in place at the corner in 0.15 rad steps.
      for (double t = 0.15; t < M_PI / 2; t += 0.15) path.emplace_back(b.x(), b.y(), fl::WrapAngle(heading + t));
    }
  }
  path.push_back(path.front());
  return MakePathRun(world, path, o);
}

}  // namespace fl::test
