// The fusion's 3D map: the VO keyframe points (robot base frame), placed by the FUSED poses
// and thinned with a voxel filter (PCL VoxelGrid, kept out of this header).
//
// Keyframes are stored in their own base frame (each voxel-filtered once on arrival); once a
// keyframe's pose is final, one whose view is already mapped (a kept keyframe within the merge
// spacing) is dropped, so that memory stays bounded by the scene, not by time
// (MergeFinalKeyframes); Build() places every keyframe with the current
// fused pose at its time and voxel-filters the union, so the map follows every correction of
// the trajectory (loop closures included). Planar poses are embedded in 3D as a rotation
// about z at z = 0.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/state_buffer.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::fusion {

struct PointMapOptions {
  double voxel_size_m = 0.05;  // [m] voxel edge of the filter (keyframes and the map)
  double max_range_m = 30.0;   // [m] keyframe points farther from the base are dropped
  int max_points = 5000000;    // map points before Build() refuses (memory guard)
  // A keyframe whose pose is final (the fusion retired it) is dropped when an older final
  // keyframe lies within this distance and heading (a view already mapped): memory bounded by
  // the scene.
  double merge_spacing_m = 1.0;    // [m] (0: never merge; memory grows with time)
  double merge_spacing_rad = 0.5;  // [rad]

  template <class A>
  void Serialize(A* a) {
    a->Visit("voxel_size_m", &voxel_size_m);
    a->Visit("max_range_m", &max_range_m);
    a->Visit("max_points", &max_points);
    a->Visit("merge_spacing_m", &merge_spacing_m);
    a->Visit("merge_spacing_rad", &merge_spacing_rad);
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

  // Keyframes at or before `final_until` have their final pose pose_at(utime) (the fusion's
  // frozen past): each one not yet final is kept, or, if a kept final keyframe lies within
  // merge_spacing_m and merge_spacing_rad of it (that view is already in the map), removed.
  // Returns the number removed.
  int MergeFinalKeyframes(const std::function<bool(Utime, Pose2*)>& pose_at, Utime final_until);

  // Saved state (the fusion process's journal snapshot): the keyframes, their final poses and
  // the counters; LoadState replaces them or throws StateError and leaves this map unchanged.
  void SaveState(StateWriter* out) const;
  void LoadState(StateReader* in);

  int num_keyframes() const;
  int64_t merged_keyframes() const { return merged_keyframes_; }
  int64_t stored_points() const;
  int64_t dropped_points() const { return dropped_points_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  PointMapOptions options_;
  int64_t dropped_points_ = 0;
  int64_t merged_keyframes_ = 0;
};

}  // namespace fl::fusion
