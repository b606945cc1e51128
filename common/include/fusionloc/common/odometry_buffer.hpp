// Wheel odometry poses buffered by time, interpolated at a sensor time (a laser scan, a stereo
// frame); the RBPF-SLAM and the stereo VO read ODOMETRY through it.
#pragma once

#include <deque>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"

namespace fl {

class OdometryBuffer {
 public:
  // max_age_us: samples older than (newest − max_age_us) are forgotten.
  // max_gap_us: two samples farther apart than this are not interpolated between.
  explicit OdometryBuffer(fl::Utime max_age_us = 10 * fl::kUtimePerSecond,
                          fl::Utime max_gap_us = 2 * fl::kUtimePerSecond)
      : max_age_us_(max_age_us), max_gap_us_(max_gap_us) {}

  // Adds T_odom_base at utime. Error (sample ignored) if the time does not increase or the pose
  // is not finite.
  fl::Status Add(fl::Utime utime, const fl::Pose2& T_odom_base);

  // Interpolated pose at utime (linear in x, y and shortest-arc in θ). An exact time stamp
  // matches without interpolation. Error if utime is outside the buffered span or in a gap.
  fl::Status Lookup(fl::Utime utime, fl::Pose2* T_odom_base) const;

  bool empty() const { return samples_.empty(); }
  fl::Utime newest() const { return samples_.empty() ? 0 : samples_.back().utime; }

 private:
  struct Sample {
    fl::Utime utime;
    fl::Pose2 pose;
  };
  fl::Utime max_age_us_;
  fl::Utime max_gap_us_;
  std::deque<Sample> samples_;
};

}  // namespace fl
