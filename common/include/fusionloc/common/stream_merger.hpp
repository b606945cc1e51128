// Merges several time-stamped sensor streams into one stream ordered by time (utime), so that
// estimators see e.g. odometry and laser in the order they happened, whatever order the
// transport delivered them in. Lives in a library class, not in LCM callbacks.
//
//   fl::StreamMerger<Item> merger(/*max_latency_us=*/200000);
//   const int laser = merger.AddStream("LASER"), odom = merger.AddStream("ODOMETRY");
//   merger.Push(laser, scan.utime, item);            // from callbacks
//   while (merger.Pop(&out)) process(out);           // in time order
//
// An item is released when every stream has delivered something at or after its time (so no
// earlier item can still arrive), or when it is older than `max_latency_us` behind the newest
// item seen (a silent stream cannot stall the others). An item older than the last of its own
// stream (reordered or late by the transport) is placed by its time stamp as long as nothing
// newer has been released; one that arrives after items of a later time were released is
// rejected with a reason; the caller counts and reports it.
//
// A clock that jumps forward (a sensor's stamps suddenly a minute ahead) would otherwise
// release everything queued and then reject every other stream as late until real time caught
// up. When the caller passes each item's arrival time (its receive time live, the log time in
// replay), an item stamped more than max_lead_us ahead of the newest stamp of another stream
// that is still arriving (an item of it arrived within max_lead_us) is rejected instead, and the
// stream is accepted again as soon as its stamps agree with the others. A stream alone, or
// whose peers have gone silent, is not checked (nothing to compare with).
#pragma once

#include <algorithm>
#include <cstdint>
#include <deque>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"

namespace fl {

template <class T>
class StreamMerger {
 public:
  struct Item {
    Utime utime = 0;
    int stream = -1;
    T value;
  };

  static constexpr Utime kNoArrival = std::numeric_limits<Utime>::min();

  // max_lead_us: how far [us] one stream's stamps may run ahead of another's (see the file
  // comment); 0 means max_latency_us + 1 s.
  explicit StreamMerger(Utime max_latency_us = 200000, Utime max_lead_us = 0)
      : max_latency_us_(max_latency_us),
        max_lead_us_(max_lead_us > 0 ? max_lead_us : max_latency_us + 1000000) {}

  int AddStream(const std::string& name) {
    streams_.push_back(Stream{name, {}, std::numeric_limits<Utime>::min(), kNoArrival});
    return static_cast<int>(streams_.size()) - 1;
  }

  // `arrival` [us]: when the item arrived (receive time live, log time in replay), for the
  // clock-jump check; kNoArrival skips it.
  Status Push(int stream, Utime utime, T value, Utime arrival = kNoArrival) {
    Stream& s = streams_.at(static_cast<size_t>(stream));
    if (arrival != kNoArrival) {
      for (const Stream& other : streams_) {
        if (&other == &s || other.last_arrival == kNoArrival ||
            UtimeDifference(other.last_arrival, arrival) > max_lead_us_) {
          continue;  // silent or never heard: nothing to compare with
        }
        if (UtimeDifference(other.last_utime, utime) > max_lead_us_) {
          return Status::Error(
              "stream '" + s.name + "': time stamp " + FormatUtime(utime) + " is " +
              FormatDouble(SecondsBetween(other.last_utime, utime)) +
              " s ahead of stream '" + other.name + "' (" + FormatUtime(other.last_utime) +
              "): its clock jumped forward; message dropped until the stamps "
              "agree again");
        }
      }
    }
    if (utime < released_utime_) {
      return Status::Error("stream '" + s.name + "': message at " + FormatUtime(utime) +
                           " arrived after data up to " + FormatUtime(released_utime_) +
                           " was processed (more than the merge latency late, or its clock "
                           "went back); dropped");
    }
    if (utime < s.last_utime) {
      // Reordered within the merge window: placed by its stamp.
      auto at = std::upper_bound(s.queue.begin(), s.queue.end(), utime,
                                 [](Utime t, const Item& item) { return t < item.utime; });
      s.queue.insert(at, Item{utime, stream, std::move(value)});
      return Status::Ok();
    }
    s.last_utime = utime;
    if (arrival != kNoArrival) s.last_arrival = arrival;
    if (utime > newest_utime_) newest_utime_ = utime;
    s.queue.push_back(Item{utime, stream, std::move(value)});
    return Status::Ok();
  }

  // Pops the earliest releasable item; false if none can be released yet.
  bool Pop(Item* out) {
    int best = -1;
    for (size_t i = 0; i < streams_.size(); ++i) {
      if (streams_[i].queue.empty()) continue;
      if (best < 0 || streams_[i].queue.front().utime < streams_[best].queue.front().utime) {
        best = static_cast<int>(i);
      }
    }
    if (best < 0) return false;
    const Utime t = streams_[best].queue.front().utime;
    bool safe = true;
    for (const auto& s : streams_) {
      if (s.last_utime < t) safe = false;  // this stream may still send something earlier
    }
    if (!safe && UtimeDifference(t, newest_utime_) < max_latency_us_ && !flushing_) return false;
    *out = std::move(streams_[best].queue.front());
    streams_[best].queue.pop_front();
    released_utime_ = t;
    return true;
  }

  // The stamp of the last item released: an item older than it is refused by Push() (late).
  Utime released_utime() const { return released_utime_; }

  // After Flush(), Pop() releases everything queued (end of a log, shutdown).
  void Flush() { flushing_ = true; }
  size_t queued() const {
    size_t n = 0;
    for (const auto& s : streams_) n += s.queue.size();
    return n;
  }

 private:
  struct Stream {
    std::string name;
    std::deque<Item> queue;
    Utime last_utime;
    Utime last_arrival;  // [us] of its last accepted item; kNoArrival if none was given
  };
  Utime max_latency_us_;
  Utime max_lead_us_;
  std::vector<Stream> streams_;
  Utime newest_utime_ = std::numeric_limits<Utime>::min();
  Utime released_utime_ = std::numeric_limits<Utime>::min();
  bool flushing_ = false;
};

}  // namespace fl
