// What keeps the viewer's traffic small: voxel thinning of clouds and the thinning of poses
// into trails and trajectories.
#pragma once

#include <cstddef>
#include <cstdint>
#include <unordered_set>
#include <vector>

#include "fusionloc/common/time.hpp"

namespace fl::viewer {

struct ViewPose {
  Utime utime = 0;
  double x = 0, y = 0, z = 0;  // [m]
  double yaw = 0;              // [rad]
};

// A set of occupied voxels that grows: Add() keeps, of the points given, those that fall in a
// voxel not occupied yet (the first such point of each), so a growing cloud can be sent as
// the new points only. Non-finite points are skipped.
class VoxelSet {
 public:
  explicit VoxelSet(double voxel_m);
  // xyz: n points as x, y, z. Appends the kept points to *kept (x, y, z) and returns how many.
  size_t Add(const float* xyz, size_t n, std::vector<float>* kept);
  size_t size() const { return voxels_.size(); }
  void Clear() { voxels_.clear(); }
  double voxel() const { return voxel_; }

 private:
  double voxel_;
  std::unordered_set<uint64_t> voxels_;
};

// One point per voxel of `voxel_m` (the first of each), in the order of the input.
std::vector<float> VoxelDecimate(const float* xyz, size_t n, double voxel_m);

// Thins a stream of poses into a trail: a pose is kept if it is the first, if at least
// `min_period_s` of its time has passed since the last kept one and it moved by
// `min_distance_m` or turned by `min_turn_rad` since, or if time went backwards (a new run or a
// seek in a log: the trail restarts).
class TrailDecimator {
 public:
  TrailDecimator(double min_period_s, double min_distance_m, double min_turn_rad);
  // True if `p` is kept. *restart is set when time went backwards.
  bool Accept(const ViewPose& p, bool* restart = nullptr);
  void Reset() { have_last_ = false; }

 private:
  double min_period_s_, min_distance_m_, min_turn_rad_;
  bool have_last_ = false;
  ViewPose last_;
};

// The poses of a whole trajectory thinned to one every `min_distance_m` of path or
// `min_turn_rad` of turn; the first and the last pose are always kept.
std::vector<ViewPose> DecimateTrajectory(const std::vector<ViewPose>& poses, double min_distance_m,
                                         double min_turn_rad);

}  // namespace fl::viewer
