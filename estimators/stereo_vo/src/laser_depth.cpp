#include "fusionloc/stereo_vo/laser_depth.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace fl::vo {

fl::Status LaserDepthOptions::Validate() const {
  if (!(search_radius_px >= 1.0 && search_radius_px <= 50.0)) {
    return fl::Status::Error("laser_depth.search_radius_px must be in [1, 50] px");
  }
  if (min_neighbours < 3 || max_neighbours < min_neighbours || max_neighbours > 64) {
    return fl::Status::Error("laser_depth.min_neighbours must be >= 3 and <= max_neighbours <= 64");
  }
  if (!(min_depth_m > 0 && max_depth_m > min_depth_m)) {
    return fl::Status::Error("laser_depth: need 0 < min_depth_m < max_depth_m");
  }
  if (!(min_plane_spread > 0 && min_plane_spread < 1)) {
    return fl::Status::Error("laser_depth.min_plane_spread must be in (0, 1)");
  }
  if (!(max_plane_residual_rel > 0 && max_depth_spread_rel > 0 && max_line_offset_px >= 0)) {
    return fl::Status::Error(
        "laser_depth.max_plane_residual_rel and max_depth_spread_rel must be > 0, "
        "max_line_offset_px >= 0");
  }
  if (!(range_sigma_m > 0 && stereo_disparity_sigma_px > 0 && max_stereo_disagreement_sigma > 0 &&
        point_lateral_sigma_px > 0)) {
    return fl::Status::Error(
        "laser_depth.range_sigma_m, stereo_disparity_sigma_px, max_stereo_disagreement_sigma and "
        "point_lateral_sigma_px must be > 0");
  }
  if (min_points_in_view < 0) {
    return fl::Status::Error("laser_depth.min_points_in_view must be >= 0");
  }
  return fl::Status::Ok();
}

const char* ToString(DepthSource s) {
  switch (s) {
    case DepthSource::kNone:
      return "none";
    case DepthSource::kStereo:
      return "stereo";
    case DepthSource::kLaser:
      return "laser";
    case DepthSource::kBoth:
      return "both";
  }
  return "?";
}

double StereoDepthSigma(const StereoCamera& camera, double depth_m, double disparity_sigma_px) {
  return depth_m * depth_m / (camera.fx * camera.baseline) * disparity_sigma_px;
}

LaserDepthMap::LaserDepthMap(const LaserDepthOptions& options, const StereoCamera& camera,
                             int width, int height, const std::vector<Eigen::Vector3f>& points,
                             const Eigen::Isometry3d& T_camera_points)
    : options_(options), camera_(camera), width_(width), height_(height) {
  cell_px_ = options.search_radius_px;
  cols_ = std::max(1, static_cast<int>(std::ceil(width / cell_px_)));
  rows_ = std::max(1, static_cast<int>(std::ceil(height / cell_px_)));
  // One pass over the scan: into the camera frame, the depth gate, the projection. Only the
  // points in view are stored (a fifth of a Velodyne scan), so nothing scan-sized is allocated.
  struct Kept {
    int cell;
    Eigen::Vector2f pixel;
    Eigen::Vector3f point;  // camera frame
  };
  std::vector<Kept> kept;
  const Eigen::Matrix3f R = T_camera_points.linear().cast<float>();
  const Eigen::Vector3f t = T_camera_points.translation().cast<float>();
  const Eigen::RowVector3f R_z = R.row(2);
  const float min_z = static_cast<float>(options.min_depth_m);
  const float max_z = static_cast<float>(options.max_depth_m);
  Eigen::Vector3d uvu;
  for (const Eigen::Vector3f& p_points : points) {
    // The depth first: most of a 360-degree scan is behind or beside the camera.
    const float z = R_z.dot(p_points) + t.z();
    if (!(z >= min_z && z <= max_z)) continue;
    const Eigen::Vector3f p_camera = R * p_points + t;
    if (!camera.Project(p_camera.cast<double>(), &uvu)) continue;
    if (!(uvu(0) >= 0 && uvu(0) < width && uvu(1) >= 0 && uvu(1) < height)) continue;
    const int cx = std::min(cols_ - 1, static_cast<int>(uvu(0) / cell_px_));
    const int cy = std::min(rows_ - 1, static_cast<int>(uvu(1) / cell_px_));
    kept.push_back({cy * cols_ + cx, {static_cast<float>(uvu(0)), static_cast<float>(uvu(1))},
                    p_camera});
  }
  // Counting sort by cell.
  cell_start_.assign(static_cast<size_t>(cols_ * rows_ + 1), 0);
  for (const Kept& k : kept) ++cell_start_[static_cast<size_t>(k.cell + 1)];
  for (size_t c = 1; c < cell_start_.size(); ++c) cell_start_[c] += cell_start_[c - 1];
  std::vector<int> fill(cell_start_.begin(), cell_start_.end() - 1);
  pixels_.resize(kept.size());
  points_.resize(kept.size());
  for (const Kept& k : kept) {
    const size_t at = static_cast<size_t>(fill[static_cast<size_t>(k.cell)]++);
    pixels_[at] = k.pixel;
    points_[at] = k.point;
  }
}

double LaserDepthMap::LineOffsetPx(const std::vector<std::pair<double, int>>& near, double u,
                                   double v) const {
  // Principal direction of the neighbours' pixels; the feature's distance across it.
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& [d2, i] : near) mean += pixels_[static_cast<size_t>(i)].cast<double>();
  mean /= static_cast<double>(near.size());
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (const auto& [d2, i] : near) {
    const Eigen::Vector2d d = pixels_[static_cast<size_t>(i)].cast<double>() - mean;
    scatter += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter);
  const Eigen::Vector2d across = eig.eigenvectors().col(0);  // smallest spread: the normal
  return std::abs(across.dot(Eigen::Vector2d(u, v) - mean));
}

FeatureDepth LaserDepthMap::Associate(double u, double v, double stereo_depth_m,
                                      double stereo_sigma_m) const {
  FeatureDepth out;
  if (stereo_depth_m > 0) {
    out.source = DepthSource::kStereo;
    out.depth_m = stereo_depth_m;
    out.sigma_m = stereo_sigma_m;
  }
  // 1. Neighbours within the radius (the 3x3 cells around the pixel cover it), nearest first.
  const double r2 = options_.search_radius_px * options_.search_radius_px;
  const int cx = static_cast<int>(std::floor(u / cell_px_));
  const int cy = static_cast<int>(std::floor(v / cell_px_));
  std::vector<std::pair<double, int>> near;
  near.reserve(32);
  for (int y = std::max(0, cy - 1); y <= std::min(rows_ - 1, cy + 1); ++y) {
    for (int x = std::max(0, cx - 1); x <= std::min(cols_ - 1, cx + 1); ++x) {
      const int c = y * cols_ + x;
      for (int i = cell_start_[static_cast<size_t>(c)]; i < cell_start_[static_cast<size_t>(c + 1)];
           ++i) {
        const Eigen::Vector2f& p = pixels_[static_cast<size_t>(i)];
        const double d2 = (p.x() - u) * (p.x() - u) + (p.y() - v) * (p.y() - v);
        if (d2 <= r2) near.emplace_back(d2, i);
      }
    }
  }
  out.neighbours = static_cast<int>(near.size());
  // 2. Enough of them.
  if (out.neighbours < options_.min_neighbours) {
    out.verdict = LaserDepthVerdict::kTooFew;
    return out;
  }
  const size_t m = std::min(near.size(), static_cast<size_t>(options_.max_neighbours));
  std::partial_sort(near.begin(), near.begin() + static_cast<std::ptrdiff_t>(m), near.end());
  near.resize(m);
  out.neighbours = static_cast<int>(m);

  // 3. Plane fit (or a line of points: weighted depth), consistency.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  double zmin = 1e300, zmax = -1e300;
  for (const auto& [d2, i] : near) {
    const Eigen::Vector3d p = points_[static_cast<size_t>(i)].cast<double>();
    mean += p;
    zmin = std::min(zmin, p.z());
    zmax = std::max(zmax, p.z());
  }
  mean /= static_cast<double>(m);
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& [d2, i] : near) {
    const Eigen::Vector3d d = points_[static_cast<size_t>(i)].cast<double>() - mean;
    scatter += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
  const Eigen::Vector3d ev = eig.eigenvalues();  // ascending
  const Eigen::Vector3d ray((u - camera_.cx) / camera_.fx, (v - camera_.cy) / camera_.fy, 1.0);
  double z = 0, spread_sigma = 0;
  bool consistent = false;
  const Eigen::Vector3d n = eig.eigenvectors().col(0);
  const double n_ray = n.dot(ray);
  const bool plane = ev(2) > 0 && ev(1) >= options_.min_plane_spread * ev(2) &&
                     std::abs(n_ray) > 1e-3 * ray.norm();
  if (plane) {
    z = n.dot(mean) / n_ray;
    double max_res = 0, sum_sq = 0;
    for (const auto& [d2, i] : near) {
      const double r = n.dot(points_[static_cast<size_t>(i)].cast<double>() - mean);
      max_res = std::max(max_res, std::abs(r));
      sum_sq += r * r;
    }
    spread_sigma = std::sqrt(sum_sq / static_cast<double>(m));
    // The intersection must lie within the patch's depth range (a plane seen edge-on can put
    // it anywhere).
    consistent = z > 0 && max_res <= options_.max_plane_residual_rel * z &&
                 z >= zmin - options_.max_plane_residual_rel * z &&
                 z <= zmax + options_.max_plane_residual_rel * z;
  } else {
    double wsum = 0;
    for (const auto& [d2, i] : near) {
      const double w = 1.0 / (std::sqrt(d2) + 0.5);
      z += w * static_cast<double>(points_[static_cast<size_t>(i)].z());
      wsum += w;
    }
    z /= wsum;
    spread_sigma = 0.5 * (zmax - zmin);
    // The line's depth holds along it, not across it (on the floor, 5 m away, the depth changes
    // by ~2.5 % a pixel across a scan line): the feature must lie on the line in the image.
    consistent = zmax - zmin <= options_.max_depth_spread_rel * z &&
                 LineOffsetPx(near, u, v) <= options_.max_line_offset_px;
  }
  out.laser_depth_m = z;
  if (!consistent) {
    out.verdict = LaserDepthVerdict::kInconsistent;
    return out;
  }
  // 4. Uncertainty.
  const double sigma =
      std::sqrt(options_.range_sigma_m * options_.range_sigma_m + spread_sigma * spread_sigma);
  // 5. Agreement with the stereo depth.
  if (stereo_depth_m > 0) {
    const double tol = options_.max_stereo_disagreement_sigma *
                       std::sqrt(sigma * sigma + stereo_sigma_m * stereo_sigma_m);
    if (std::abs(z - stereo_depth_m) > tol) {
      out.verdict = LaserDepthVerdict::kStereoDisagrees;
      return out;
    }
  }
  out.verdict = LaserDepthVerdict::kOk;
  out.source = stereo_depth_m > 0 ? DepthSource::kBoth : DepthSource::kLaser;
  out.depth_m = z;
  out.sigma_m = sigma;
  return out;
}

}  // namespace fl::vo
