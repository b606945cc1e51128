#include "fusionloc/viewer/decimate.hpp"

#include <cmath>

#include "fusionloc/common/geometry.hpp"

namespace fl::viewer {
namespace {

// 21 bits per axis (about ±10^6 voxels), enough for any map the system makes.
uint64_t VoxelKey(float x, float y, float z, double voxel) {
  auto q = [voxel](float v) {
    return static_cast<uint64_t>(static_cast<int64_t>(std::floor(v / voxel)) + (1 << 20)) &
           ((1u << 21) - 1);
  };
  return q(x) | (q(y) << 21) | (q(z) << 42);
}

bool Moved(const ViewPose& a, const ViewPose& b, double min_distance_m, double min_turn_rad) {
  const double d = std::hypot(std::hypot(b.x - a.x, b.y - a.y), b.z - a.z);
  return d >= min_distance_m || std::abs(WrapAngle(b.yaw - a.yaw)) >= min_turn_rad;
}

}  // namespace

VoxelSet::VoxelSet(double voxel_m) : voxel_(voxel_m > 0 ? voxel_m : 0.1) {}

size_t VoxelSet::Add(const float* xyz, size_t n, std::vector<float>* kept) {
  size_t added = 0;
  for (size_t i = 0; i < n; ++i) {
    const float x = xyz[3 * i], y = xyz[3 * i + 1], z = xyz[3 * i + 2];
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) continue;
    if (voxels_.insert(VoxelKey(x, y, z, voxel_)).second) {
      kept->insert(kept->end(), {x, y, z});
      ++added;
    }
  }
  return added;
}

std::vector<float> VoxelDecimate(const float* xyz, size_t n, double voxel_m) {
  VoxelSet set(voxel_m);
  std::vector<float> kept;
  set.Add(xyz, n, &kept);
  return kept;
}

TrailDecimator::TrailDecimator(double min_period_s, double min_distance_m, double min_turn_rad)
    : min_period_s_(min_period_s), min_distance_m_(min_distance_m), min_turn_rad_(min_turn_rad) {}

bool TrailDecimator::Accept(const ViewPose& p, bool* restart) {
  if (restart) *restart = false;
  if (have_last_ && p.utime < last_.utime) {
    if (restart) *restart = true;
    have_last_ = false;
  }
  if (have_last_) {
    if (p.utime - last_.utime < SecondsToUtime(min_period_s_)) return false;
    if (!Moved(last_, p, min_distance_m_, min_turn_rad_)) return false;
  }
  last_ = p;
  have_last_ = true;
  return true;
}

std::vector<ViewPose> DecimateTrajectory(const std::vector<ViewPose>& poses, double min_distance_m,
                                         double min_turn_rad) {
  std::vector<ViewPose> out;
  if (poses.empty()) return out;
  out.push_back(poses.front());
  double path = 0;
  for (size_t i = 1; i + 1 < poses.size(); ++i) {
    path += std::hypot(poses[i].x - poses[i - 1].x, poses[i].y - poses[i - 1].y);
    if (path >= min_distance_m ||
        std::abs(WrapAngle(poses[i].yaw - out.back().yaw)) >= min_turn_rad) {
      out.push_back(poses[i]);
      path = 0;
    }
  }
  if (poses.size() > 1) out.push_back(poses.back());
  return out;
}

}  // namespace fl::viewer
