// What every scan consumer (RbpfSlam, MonteCarloLocalizer) does first with a scan and the
// odometry at its time: reject what it cannot use, before touching any state, and keep the
// odometry with its jumps removed.
//   - time must increase from scan to scan;
//   - the odometry pose must be finite;
//   - the scan must have beams and a finite, non-zero angle step, and the geometry of the first
//     scan (beam count, rad0, radstep): a laser cannot change it;
//   - an odometry step beyond motion.IsOdometryJump's limits for the time since the previous
//     scan (a wheel-base reset, a glitch) is a jump: it is not applied (odom() does not move)
//     and the caller treats it as "no motion plus large noise".
#pragma once

#include <cstddef>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/rbpf_slam/options.hpp"
#include "fusionloc/rbpf_slam/types.hpp"

namespace fl::rbpf {

class ScanInput {
 public:
  enum class Verdict {
    kAccepted,
    kTimeBackwards,  // not after the previous accepted scan
    kBadInput,       // odometry not finite, no beams, bad angles or a changed geometry
  };
  struct Step {
    bool first = false;          // the first accepted scan (no step)
    fl::Pose2 odometry_step;     // T_prev_cur of the raw odometry (identity on the first)
    bool odometry_jump = false;  // the step exceeded the jump limits and was not applied
    double dt_s = 0.0;           // [s] since the previous accepted scan (0 on the first)
  };

  // Checks the scan; if it is usable, takes it (the stamp, geometry and odometry advance) and
  // fills *step. Otherwise nothing changes and *error says why (naming the scan's utime).
  Verdict Accept(const LaserScan& scan, const fl::Pose2& odom_pose, const MotionOptions& motion,
                 Step* step, fl::Status* error);
  // The checks of Accept() but the time's, without taking the scan (a late scan placed by its
  // stamp): Ok, or why it cannot be used.
  fl::Status CheckContent(const LaserScan& scan, const fl::Pose2& odom_pose) const;

  bool initialized() const { return initialized_; }
  fl::Utime last_utime() const { return last_utime_; }
  // T_odom_base with the flagged jumps removed, at the last accepted scan.
  const fl::Pose2& odom() const { return odom_; }
  // The raw odometry pose at the last accepted scan.
  const fl::Pose2& odom_raw() const { return last_odom_raw_; }

 private:
  bool initialized_ = false;
  fl::Utime last_utime_ = 0;
  size_t beam_count_ = 0;
  double rad0_ = 0.0, radstep_ = 0.0;
  fl::Pose2 last_odom_raw_;  // last accepted raw odometry
  fl::Pose2 odom_;           // odometry with flagged jumps removed
};

}  // namespace fl::rbpf
