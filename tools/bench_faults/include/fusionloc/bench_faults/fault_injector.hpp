// The faults of a network between LCM processes, applied to a stream of encoded messages
// (the fault benchmark's relay forwards every message of one bus to the next through one of
// these). Pure: no LCM, no clock of its own; the caller passes its time.
//
//   FaultInjector faults(options);
//   faults.Push(channel, bytes, now_s);             // a message arrives
//   while (faults.Pop(now_s, &event)) forward(event); // what is due now, in due order
//
// Faults, each on the channels matching `channels` (others pass at once, unchanged):
//  - drop: a message is removed;
//  - duplicate: it is sent twice (the copy right after the original);
//  - delay: it is held back a random time in (0, max_delay_s], so later messages overtake it
//    (reordered, late);
//  - clock jump: messages whose time stamp lies in [t0 + jump_start_s, t0 + jump_start_s +
//    jump_duration_s), t0 the first stamp seen, get jump_offset_s added to every stamp
//    (a sensor clock jumping backwards or forwards, and back again after the window);
//  - outage: messages whose time stamp lies in [t0 + outage_start_s, t0 + outage_start_s +
//    outage_duration_s) are removed (a sensor unplugged, then back);
//  - corrupt: one numeric field is set to NaN, +-inf or an out-of-range value
//    (message_faults.hpp).
// Random choices come from `seed`: the same input gives the same faults.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"

namespace fl::bench_faults {

struct FaultOptions {
  std::string channels = ".*";      // regex (whole name) of the channels the faults apply to
  double drop_fraction = 0.0;       // [0, 1] of the messages removed
  double duplicate_fraction = 0.0;  // [0, 1] sent twice
  double delay_fraction = 0.0;      // [0, 1] held back ...
  double max_delay_s = 0.0;         // [s] ... by a uniform random time up to this
  double corrupt_fraction = 0.0;    // [0, 1] with one numeric field made bad
  double jump_offset_s = 0.0;       // [s] added to the stamps in the jump window (0: none)
  double jump_start_s = 0.0;        // [s] after the first stamp seen
  double jump_duration_s = 0.0;     // [s] of stamps (original time) that are shifted
  double outage_start_s = 0.0;      // [s] after the first stamp seen
  double outage_duration_s = 0.0;   // [s] of stamps removed (0: none)
  uint64_t seed = 1;
  Status Validate() const;
  bool any() const;
};

struct FaultEvent {
  std::string channel;
  std::vector<uint8_t> data;
};

struct FaultCounts {
  int64_t in = 0;          // messages pushed
  int64_t out = 0;         // messages popped (copies included)
  int64_t dropped = 0;     // removed by the drop fault
  int64_t duplicated = 0;  // extra copies sent
  int64_t delayed = 0;     // held back
  int64_t shifted = 0;     // time stamps moved by the clock jump
  int64_t silenced = 0;    // removed by the outage (also in dropped)
  int64_t corrupted = 0;   // with a bad field
  std::map<std::string, int64_t> dropped_per_channel;
  std::map<std::string, int64_t> corrupted_per_channel;
  std::vector<std::string> corruptions;  // the first 1000 made, for the report ("type.field = v")
};

class FaultInjector {
 public:
  explicit FaultInjector(FaultOptions options);  // throws std::invalid_argument if invalid

  void Push(const std::string& channel, const std::vector<uint8_t>& data, double now_s);
  // The next message due at now_s (due time, then arrival order); false if none is due.
  bool Pop(double now_s, FaultEvent* out);
  // Everything still held, regardless of its due time (end of a run).
  void Flush();
  size_t held() const { return queue_.size(); }
  const FaultCounts& counts() const { return counts_; }
  const FaultOptions& options() const { return options_; }

 private:
  struct Held {
    double due_s;
    int64_t order;
    FaultEvent event;
  };
  bool Uniform(double fraction);
  // Seconds of `data`'s stamp after the first stamp seen; false if it has none.
  bool StampSeconds(const std::vector<uint8_t>& data, double* t);
  void Enqueue(double due_s, FaultEvent event);

  FaultOptions options_;
  std::regex channels_;
  std::mt19937_64 rng_;
  std::deque<Held> queue_;  // sorted by (due_s, order)
  int64_t order_ = 0;
  bool have_t0_ = false;
  int64_t t0_us_ = 0;
  bool flushing_ = false;
  FaultCounts counts_;
};

}  // namespace fl::bench_faults
