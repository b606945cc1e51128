// The fusion's 3D map: the VO keyframe points (robot base frame), placed by the FUSED poses
// and thinned with a voxel filter (PCL VoxelGrid, kept out of this header).
//
// Keyframes are stored in their own base frame (each voxel-filtered once on arrival, so memory
// stays bounded by the scene, not by time); Build() places every keyframe with the current
// fused pose at its time and voxel-filters the union, so the map follows every correction of
// the trajectory (loop closures included). Planar poses are embedded in 3D as a rotation
// about z at z = 0.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::fusion {

struct PointMapOptions {
  double voxel_size_m = 0.05;  // [m] voxel edge of the filter (keyframes and the map)
  double max_range_m = 30.0;   // [m] keyframe points farther from the base are dropped
  int max_points = 5000000;    // map points before Build() refuses (memory guard)

  template <class A>
  void Serialize(A* a) {
    a->Visit("voxel_size_m", &voxel_size_m);
    a->Visit("max_range_m", &max_range_m);
    a->Visit("max_points", &max_points);
  }
  Status Validate() const;
};

// [m] the largest |x| or |y| of a keyframe pose that Build() places (1000 km).
constexpr double kMaxMapExtentM = 1e6;

class PointMap {
 public:
  explicit PointMap(const PointMapOptions& options);
  ~PointMap();
  PointMap(PointMap&&) noexcept;
  PointMap& operator=(PointMap&&) noexcept;

  // Points of one keyframe in the BASE frame at utime. Non-finite and out-of-range points are
  // dropped (counted in dropped_points()). Error if the keyframe time is already stored.
  Status AddKeyframe(Utime utime, const std::vector<Eigen::Vector3f>& points_base);

  // Places every keyframe with pose_at(utime) (false, or a pose that is not finite or beyond
  // kMaxMapExtentM: the keyframe is skipped, counted in *skipped) and voxel-filters the result
  // (map frame).
  std::vector<Eigen::Vector3f> Build(const std::function<bool(Utime, Pose2*)>& pose_at,
                                     int* skipped = nullptr) const;

  int num_keyframes() const;
  int64_t stored_points() const;
  int64_t dropped_points() const { return dropped_points_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  PointMapOptions options_;
  int64_t dropped_points_ = 0;
};

}  // namespace fl::fusion
