// The merge rule of fusionloc.trajectory_t messages (lcmtypes/fusionloc/trajectory_t.lcm): a
// message may carry only the latest part of a trajectory, the poses from its first time on;
// the poses before that are final and were sent in earlier messages. A producer that sends its
// whole trajectory every time (RBPF_TRAJECTORY) is the case where the first time is the start.
#pragma once

#include <algorithm>
#include <iterator>
#include <utility>
#include <vector>

#include "fusionloc/common/time.hpp"

namespace fl {

// Merges `latest` (in time order) into `trajectory` (in time order): the poses of `trajectory`
// older than latest's first are kept, the rest replaced by `latest`. An empty `latest` changes
// nothing. `utime_of(pose)` gives a pose's time.
template <class Pose, class UtimeOf>
void MergeTrajectoryTail(std::vector<Pose>* trajectory, std::vector<Pose> latest,
                         UtimeOf utime_of) {
  if (latest.empty()) return;
  const Utime first = utime_of(latest.front());
  const auto keep_end = std::lower_bound(
      trajectory->begin(), trajectory->end(), first,
      [&](const Pose& p, Utime t) { return utime_of(p) < t; });
  trajectory->erase(keep_end, trajectory->end());
  trajectory->insert(trajectory->end(), std::make_move_iterator(latest.begin()),
                     std::make_move_iterator(latest.end()));
}

}  // namespace fl
