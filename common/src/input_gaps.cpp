#include "fusionloc/common/input_gaps.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace fl {

Utime InputGaps::Median(const std::deque<Utime>& v) {
  std::vector<Utime> s(v.begin(), v.end());
  std::nth_element(s.begin(), s.begin() + static_cast<std::ptrdiff_t>(s.size() / 2), s.end());
  return s[s.size() / 2];
}

bool InputGaps::Add(const std::string& channel, Utime utime) {
  Stream& s = streams_[channel];
  gaps_.emplace(channel, 0);
  missing_.emplace(channel, 0);
  if (!s.have_last) {
    s.have_last = true;
    s.last = utime;
    return false;
  }
  if (utime <= s.last) return false;
  Utime interval = 0;
  const bool overflow = __builtin_sub_overflow(utime, s.last, &interval);
  s.last = utime;
  if (overflow || interval > kMaxGapUs) return false;
  bool gap = false;
  if (s.intervals.size() >= kMinIntervals) {
    const Utime period = Median(s.intervals);
    if (period > 0 && static_cast<double>(interval) > kGapFactor * static_cast<double>(period)) {
      gap = true;
      ++gaps_[channel];
      missing_[channel] += std::max<int64_t>(
          1, std::llround(static_cast<double>(interval) / static_cast<double>(period)) - 1);
    }
  }
  // A gap's interval is not a period: it stays out of the estimate.
  if (!gap) {
    s.intervals.push_back(interval);
    if (s.intervals.size() > kIntervals) s.intervals.pop_front();
  }
  return gap;
}

int64_t InputGaps::gaps(const std::string& channel) const {
  auto it = gaps_.find(channel);
  return it == gaps_.end() ? 0 : it->second;
}

int64_t InputGaps::missing(const std::string& channel) const {
  auto it = missing_.find(channel);
  return it == missing_.end() ? 0 : it->second;
}

Utime InputGaps::period(const std::string& channel) const {
  auto it = streams_.find(channel);
  if (it == streams_.end() || it->second.intervals.size() < kMinIntervals) return 0;
  return Median(it->second.intervals);
}

}  // namespace fl
