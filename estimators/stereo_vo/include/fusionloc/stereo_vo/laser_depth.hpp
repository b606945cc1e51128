// Pixel-level depth association (LV-SLAM, Dai et al., Sensors 2022, Figs. 4 and 5): laser
// points give image features their depth. Pure library: no LCM.
//
//   fl::vo::LaserDepthMap map(options, camera, width, height, points_in_left_camera);
//   fl::vo::FeatureDepth d = map.Associate(u, v, stereo_depth_m, stereo_sigma_m);
//
// Frames: the laser points are already in the LEFT rectified camera's optical frame (x right,
// y down, z forward; the caller applies the extrinsic T_camera_laser). Projection is
// StereoCamera::Project (motion.hpp). A feature's depth is z along its ray
// p = z (x_n, y_n, 1), x_n = (u - cx) / fx, y_n = (v - cy) / fy.
//
// Association of a feature at (u, v):
//   1. the laser points whose projection lies within search_radius_px of (u, v) (a grid of
//      search_radius_px cells indexes the projections), nearest first, at most max_neighbours;
//   2. fewer than min_neighbours: no laser depth ("too few");
//   3. consistency (no depth discontinuity within the patch): a plane n.p = d is fitted to the
//      neighbours (least squares, smallest eigenvector of their scatter). If the plane is well
//      determined (second-smallest over largest scatter eigenvalue >= min_plane_spread, i.e. not
//      one scan line), the depth is the ray's intersection with it and the neighbours' largest
//      distance to the plane must be <= max_plane_residual_rel * depth; otherwise (points
//      along one line) the depth is the inverse-distance-weighted mean of the neighbours'
//      depths, their spread (max - min) must be <= max_depth_spread_rel * depth and the feature
//      must lie within max_line_offset_px of the line in the image. A failed
//      test is a discontinuity ("inconsistent");
//   4. sigma = sqrt(range_sigma_m^2 + (plane residual RMS or depth spread / 2)^2);
//   5. with a stereo depth: |z_laser - z_stereo| <= max_stereo_disagreement_sigma *
//      sqrt(sigma_laser^2 + sigma_stereo^2), else rejected ("disagrees with stereo"); both
//      agreeing gives source kBoth with the laser depth (the more precise at range).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/stereo_vo/motion.hpp"

namespace fl::vo {

struct LaserDepthOptions {
  bool enabled = false;                  // laser-aided mode of StereoVo (off: plain stereo VO)
  double search_radius_px = 6.0;         // [px] neighbours of a feature within this image distance
  int min_neighbours = 4;                // [-] fewer: no laser depth
  int max_neighbours = 12;               // [-] the nearest this many are used
  double min_depth_m = 1.0;              // [m] laser points nearer the camera are ignored
  double max_depth_m = 60.0;             // [m] and farther ones
  double min_plane_spread = 0.05;        // [-] eigenvalue ratio below which the patch is a line
  double max_plane_residual_rel = 0.02;  // [-] largest plane residual / depth (discontinuity)
  double max_depth_spread_rel = 0.05;    // [-] (max - min depth) / depth along one line
  // [px] on one line: largest image distance of the feature across the line (its depth is
  // known along the line only)
  double max_line_offset_px = 1.0;
  double range_sigma_m = 0.03;           // [m] laser range noise (HDL-64E: about 2 cm)
  double max_stereo_disagreement_sigma = 3.0;  // [-] allowed |z_laser - z_stereo| in sigmas
  double stereo_disparity_sigma_px = 0.3;      // [px] disparity noise for the stereo depth sigma
  // [px] lateral sigma of a laser-depth point across its ray, in pixels at its depth, in the
  // motion's 3D point error: its direction is the feature's own pixel, already in the
  // reprojection error, so it is kept weak (depth is what the laser adds).
  double point_lateral_sigma_px = 2.5;
  // A cloud with fewer points in the image than this is unusable (no scan, a scan in the wrong
  // frame): the frame runs on plain stereo and the result says so.
  int min_points_in_view = 200;
  template <class A>
  void Serialize(A* a) {
    a->Visit("enabled", &enabled);
    a->Visit("search_radius_px", &search_radius_px);
    a->Visit("min_neighbours", &min_neighbours);
    a->Visit("max_neighbours", &max_neighbours);
    a->Visit("min_depth_m", &min_depth_m);
    a->Visit("max_depth_m", &max_depth_m);
    a->Visit("min_plane_spread", &min_plane_spread);
    a->Visit("max_plane_residual_rel", &max_plane_residual_rel);
    a->Visit("max_depth_spread_rel", &max_depth_spread_rel);
    a->Visit("max_line_offset_px", &max_line_offset_px);
    a->Visit("range_sigma_m", &range_sigma_m);
    a->Visit("max_stereo_disagreement_sigma", &max_stereo_disagreement_sigma);
    a->Visit("stereo_disparity_sigma_px", &stereo_disparity_sigma_px);
    a->Visit("point_lateral_sigma_px", &point_lateral_sigma_px);
    a->Visit("min_points_in_view", &min_points_in_view);
  }
  fl::Status Validate() const;  // error naming the key (prefix laser_depth.) or OK
};

// Where a feature's depth came from.
enum class DepthSource : uint8_t { kNone, kStereo, kLaser, kBoth };
const char* ToString(DepthSource s);

// Why a laser depth was not given (kOk: given).
enum class LaserDepthVerdict : uint8_t {
  kOk,
  kTooFew,          // fewer than min_neighbours laser points around the pixel
  kInconsistent,    // depth discontinuity / no plane within the patch
  kStereoDisagrees  // laser and stereo depth differ by more than allowed
};

struct FeatureDepth {
  DepthSource source = DepthSource::kNone;
  LaserDepthVerdict verdict = LaserDepthVerdict::kTooFew;
  double depth_m = 0;        // [m] z along the feature's ray (laser if validated, else stereo)
  double sigma_m = 0;        // [m] its standard deviation
  double laser_depth_m = 0;  // [m] the laser estimate (also when rejected; 0: none)
  int neighbours = 0;        // laser points used
};

// Standard deviation of a stereo depth z [m] from the disparity noise: z^2 / (fx b) sigma_d.
double StereoDepthSigma(const StereoCamera& camera, double depth_m, double disparity_sigma_px);

// The projected laser points of one scan, indexed by pixel.
class LaserDepthMap {
 public:
  // points: laser points [m], mapped into the left camera frame by T_camera_points
  // (p_camera = R p + t, in float); those with z in [min_depth_m, max_depth_m] that project
  // inside the width x height image are kept.
  LaserDepthMap(const LaserDepthOptions& options, const StereoCamera& camera, int width, int height,
                const std::vector<Eigen::Vector3f>& points,
                const Eigen::Isometry3d& T_camera_points = Eigen::Isometry3d::Identity());

  int points_in_view() const { return static_cast<int>(pixels_.size()); }
  bool usable() const { return points_in_view() >= options_.min_points_in_view; }
  // Projected position [px] (u, v) and camera-frame point of kept point i.
  const Eigen::Vector2f& pixel(int i) const { return pixels_[static_cast<size_t>(i)]; }
  const Eigen::Vector3f& point(int i) const { return points_[static_cast<size_t>(i)]; }

  // Depth of the feature at (u, v) [px]; stereo_depth_m <= 0: no stereo depth. See the file
  // comment for the rules.
  FeatureDepth Associate(double u, double v, double stereo_depth_m, double stereo_sigma_m) const;

 private:
  LaserDepthOptions options_;
  StereoCamera camera_;
  int width_ = 0, height_ = 0;
  double cell_px_ = 1;
  int cols_ = 0, rows_ = 0;
  std::vector<Eigen::Vector2f> pixels_;  // sorted by cell
  std::vector<Eigen::Vector3f> points_;
  std::vector<int> cell_start_;  // cols_ * rows_ + 1 offsets into pixels_ / points_
  // Image distance of (u, v) across the line through the neighbours' pixels [px].
  double LineOffsetPx(const std::vector<std::pair<double, int>>& near, double u, double v) const;
};

}  // namespace fl::vo
