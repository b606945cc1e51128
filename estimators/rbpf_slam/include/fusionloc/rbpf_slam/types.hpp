// Plain input/output structs of the RBPF-SLAM library (no LCM types inside the core).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::rbpf {

// One planar laser scan in the laser frame: beam k has bearing rad0 + k * radstep (CCW).
struct LaserScan {
  fl::Utime utime = 0;          // [us] time of the scan
  std::vector<float> ranges;    // [m] one per beam; NaN, inf, <= 0 or > max range are ignored
  double rad0 = 0.0;            // [rad] bearing of the first beam
  double radstep = 0.0;         // [rad] angle between consecutive beams
};

// A 2D point with its unit normal (normal is zero when it could not be estimated).
struct PointNormal {
  Eigen::Vector2d p = Eigen::Vector2d::Zero();
  Eigen::Vector2d n = Eigen::Vector2d::Zero();
  Eigen::Vector2d n_wide = Eigen::Vector2d::Zero();  // the normal of a fit as wide as the scan's
                                                    // noise needs (icp.hpp); zero: n
};

// A relative-pose measurement between two keyframes, in the robot BASE frame:
// T_i_j = T_world_base(i)^-1 * T_world_base(j); information over (x, y, yaw). On a revisit
// that reused keyframe i (graph.reuse_*), j is the scan at utime_j, not a keyframe.
struct KeyframeFactor {
  int keyframe_i = -1;
  int keyframe_j = -1;            // -1: a scan that reused keyframe i
  fl::Utime utime_i = 0;
  fl::Utime utime_j = 0;
  fl::Pose2 T_i_j;
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();  // [1/m², 1/(m rad), 1/rad²]
  bool is_loop_closure = false;
  double rms = 0.0;               // [m] point-to-line RMS of the ICP fit
  double inlier_fraction = 0.0;   // [-]
};

// A keyframe pose with its scan time.
struct StampedPose2 {
  fl::Utime utime = 0;
  fl::Pose2 T_world_base;
};

}  // namespace fl::rbpf
