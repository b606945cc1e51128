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
// item seen (a silent stream cannot stall the others). Items whose time goes backwards within
// their stream, or that arrive after items of a later time were already released, are rejected
// with a reason; the caller counts and reports them.
#pragma once

#include <cstdint>
#include <deque>
#include <limits>
#include <string>
#include <utility>
#include <vector>

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

  explicit StreamMerger(Utime max_latency_us = 200000) : max_latency_us_(max_latency_us) {}

  int AddStream(const std::string& name) {
    streams_.push_back(Stream{name, {}, std::numeric_limits<Utime>::min()});
    return static_cast<int>(streams_.size()) - 1;
  }

  Status Push(int stream, Utime utime, T value) {
    Stream& s = streams_.at(static_cast<size_t>(stream));
    if (utime < s.last_utime) {
      return Status::Error("stream '" + s.name + "': time went backwards (" + FormatUtime(utime) +
                           " after " + FormatUtime(s.last_utime) + "); message dropped");
    }
    if (utime < released_utime_) {
      return Status::Error("stream '" + s.name + "': message at " + FormatUtime(utime) +
                           " arrived after data up to " + FormatUtime(released_utime_) +
                           " was processed (more than the merge latency late); dropped");
    }
    s.last_utime = utime;
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
    if (!safe && newest_utime_ - t < max_latency_us_ && !flushing_) return false;
    *out = std::move(streams_[best].queue.front());
    streams_[best].queue.pop_front();
    released_utime_ = t;
    return true;
  }

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
  };
  Utime max_latency_us_;
  std::vector<Stream> streams_;
  Utime newest_utime_ = std::numeric_limits<Utime>::min();
  Utime released_utime_ = std::numeric_limits<Utime>::min();
  bool flushing_ = false;
};

}  // namespace fl
