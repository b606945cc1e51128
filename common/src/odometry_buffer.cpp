#include "fusionloc/common/odometry_buffer.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "fusionloc/common/time.hpp"

namespace fl {

fl::Status OdometryBuffer::Add(fl::Utime utime, const fl::Pose2& p) {
  if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.theta)) {
    return Status::Error("odometry at utime " + std::to_string(utime) + " is not finite; ignored");
  }
  if (!samples_.empty() && utime <= samples_.back().utime) {
    return Status::Error("odometry at utime " + std::to_string(utime) +
                         " does not come after the previous one (" +
                         std::to_string(samples_.back().utime) + "); ignored");
  }
  samples_.push_back({utime, p});
  while (samples_.size() > 2 && samples_.front().utime < utime - max_age_us_) samples_.pop_front();
  return Status::Ok();
}

fl::Status OdometryBuffer::Lookup(fl::Utime utime, fl::Pose2* out) const {
  if (samples_.empty()) return Status::Error("no odometry received yet");
  if (utime < samples_.front().utime || utime > samples_.back().utime) {
    return Status::Error("no odometry around utime " + std::to_string(utime) + " (buffered " +
                         std::to_string(samples_.front().utime) + " .. " +
                         std::to_string(samples_.back().utime) + ")");
  }
  const auto it = std::lower_bound(samples_.begin(), samples_.end(), utime,
                                   [](const Sample& s, fl::Utime t) { return s.utime < t; });
  if (it->utime == utime) {
    *out = it->pose;
    return Status::Ok();
  }
  const Sample& b = *it;
  const Sample& a = *(it - 1);
  // Saturating: samples stamped at the ends of int64 would overflow the difference.
  const fl::Utime gap = fl::UtimeDifference(a.utime, b.utime);
  if (gap > max_gap_us_) {
    return Status::Error("odometry gap of " + std::to_string(gap / 1000) +
                         " ms around utime " + std::to_string(utime));
  }
  const double f = static_cast<double>(utime - a.utime) / static_cast<double>(b.utime - a.utime);
  *out = fl::Pose2(a.pose.x + f * (b.pose.x - a.pose.x), a.pose.y + f * (b.pose.y - a.pose.y),
                   fl::WrapAngle(a.pose.theta + f * fl::WrapAngle(b.pose.theta - a.pose.theta)));
  return Status::Ok();
}

}  // namespace fl
