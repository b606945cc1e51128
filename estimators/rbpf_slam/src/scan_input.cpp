#include "fusionloc/rbpf_slam/scan_input.hpp"

#include <cmath>
#include <string>

#include "fusionloc/common/number_format.hpp"

namespace fl::rbpf {

fl::Status ScanInput::CheckContent(const LaserScan& scan, const fl::Pose2& odom_pose) const {
  const std::string at = "scan at utime " + std::to_string(scan.utime);
  if (!std::isfinite(odom_pose.x) || !std::isfinite(odom_pose.y) ||
      !std::isfinite(odom_pose.theta)) {
    return Status::Error("odometry pose at utime " + std::to_string(scan.utime) +
                         " is not finite; scan dropped");
  }
  if (scan.ranges.empty() || !std::isfinite(scan.rad0) || !std::isfinite(scan.radstep) ||
      scan.radstep == 0.0) {
    return Status::Error(at + " has no beams or a non-finite/zero angle step; dropped");
  }
  if (initialized_ && (scan.ranges.size() != beam_count_ || std::abs(scan.rad0 - rad0_) > 1e-6 ||
                       std::abs(scan.radstep - radstep_) > 1e-9)) {
    return Status::Error(at + " has " + std::to_string(scan.ranges.size()) + " beams (rad0 " +
                         FormatDouble(scan.rad0) + ", step " + FormatDouble(scan.radstep) +
                         ") but the first scan had " + std::to_string(beam_count_) + " (rad0 " +
                         FormatDouble(rad0_) + ", step " + FormatDouble(radstep_) +
                         "); a laser cannot change its geometry: check the LASER channel");
  }
  return Status::Ok();
}

ScanInput::Verdict ScanInput::Accept(const LaserScan& scan, const fl::Pose2& odom_pose,
                                     const MotionOptions& motion, Step* step, fl::Status* error) {
  const std::string at = "scan at utime " + std::to_string(scan.utime);
  if (initialized_ && scan.utime <= last_utime_) {
    *error = Status::Error(at + " does not come after the previous one (" +
                           std::to_string(last_utime_) + "); dropped");
    return Verdict::kTimeBackwards;
  }
  *error = CheckContent(scan, odom_pose);
  if (!error->ok()) return Verdict::kBadInput;
  *step = Step();
  if (!initialized_) {
    initialized_ = true;
    beam_count_ = scan.ranges.size();
    rad0_ = scan.rad0;
    radstep_ = scan.radstep;
    last_utime_ = scan.utime;
    last_odom_raw_ = odom_pose;
    odom_ = odom_pose;
    step->first = true;
    return Verdict::kAccepted;
  }
  step->dt_s = 1e-6 * static_cast<double>(UtimeDifference(last_utime_, scan.utime));
  last_utime_ = scan.utime;
  step->odometry_step = last_odom_raw_.between(odom_pose);
  last_odom_raw_ = odom_pose;
  const fl::Pose2& d = step->odometry_step;
  if (motion.IsOdometryJump(d, step->dt_s)) {
    step->odometry_jump = true;
  } else {
    odom_ = odom_ * d;
  }
  return Verdict::kAccepted;
}

}  // namespace fl::rbpf
