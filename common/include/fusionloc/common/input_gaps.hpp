// Gaps in input streams: per channel, the typical period between time stamps (the median of
// the last intervals) and the count of intervals longer than kGapFactor times it, i.e. one or
// more messages that never arrived (dropped by the network, a sensor that skipped). Processes
// report the counts in their STATUS (StatusReporter::CountIn(channel, utime)).
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <string>

#include "fusionloc/common/time.hpp"

namespace fl {

class InputGaps {
 public:
  static constexpr double kGapFactor = 1.8;   // an interval this many periods long is a gap
  static constexpr size_t kIntervals = 15;    // intervals the period is the median of
  static constexpr size_t kMinIntervals = 5;  // before this many, no period is known
  // [us] a step longer than this (or one that overflows) is a clock jump or a corrupt stamp,
  // not lost messages: the stream goes on from the new stamp and no gap is counted.
  static constexpr Utime kMaxGapUs = 600 * 1000000LL;

  // Records a message of `channel` stamped `utime`; true if it ends a gap. Stamps that do not
  // advance (repeats, out of order) are ignored here (the consumer rejects them).
  bool Add(const std::string& channel, Utime utime);
  int64_t gaps(const std::string& channel) const;
  // Estimated messages missing in the gaps (interval / period - 1, rounded, summed).
  int64_t missing(const std::string& channel) const;
  // [us] the typical period, 0 while unknown.
  Utime period(const std::string& channel) const;
  const std::map<std::string, int64_t>& all_gaps() const { return gaps_; }

 private:
  struct Stream {
    Utime last = 0;
    bool have_last = false;
    std::deque<Utime> intervals;
  };
  static Utime Median(const std::deque<Utime>& v);
  std::map<std::string, Stream> streams_;
  std::map<std::string, int64_t> gaps_, missing_;
};

}  // namespace fl
