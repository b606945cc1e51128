// Publishes a process's fusionloc.status_t about once per second on STATUS_<NAME>, where NAME
// is the program name upper-cased with '-' as '_' (fl-rbpf-slam -> STATUS_FL_RBPF_SLAM).
// The period and the stamps are on the LCM interface's clock (data time when replaying a log).
// When replaying, wall-clock timings (AddItemTime, SetTiming) are left out of the message so
// that the same log gives the same bytes; live they are published.
//
//   fl::StatusReporter status(lcm.get(), "fl-rbpf-slam");
//   status.CountIn(); ... status.CountOut(); status.CountDropped("time went backwards");
//   status.Set("particles", 30);
//   status.Tick();   // call often; publishes when the period has passed
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include "fusionloc/common/input_gaps.hpp"
#include "fusionloc/common/lcm_interface.hpp"

namespace fl {

// The status channel of a program: STATUS_ + its name upper-cased, '-' as '_'.
std::string StatusChannel(const std::string& program);

class StatusReporter {
 public:
  StatusReporter(LcmInterface* lcm, std::string process, double period_s = 1.0);

  void CountIn() { ++in_; }
  // Counts an input and watches its channel's stamps for gaps (InputGaps): the status then has
  // gaps_<CHANNEL> (intervals of more than 1.8 periods) and missing_<CHANNEL> (messages the
  // gaps held, estimated) for every channel counted this way.
  void CountIn(const std::string& channel, Utime utime);
  void CountOut() { ++out_; }
  // Counts a rejected input and keeps the reason as the status message (level WARN).
  void CountDropped(const std::string& reason);
  // Adds processing time of one item, for the cpu_ms_per_item field.
  void AddItemTime(double ms);
  void Set(const std::string& key, double value) { values_[key] = value; }
  // A wall-clock measurement [ms] (published live only, see the file comment).
  void SetTiming(const std::string& key, double ms);
  // level: fusionloc::status_t::LEVEL_*; message shown in lcm-spy.
  void SetState(int level, const std::string& message);

  // Publishes if `period_s` has passed since the last report, if the state has just become
  // LEVEL_ERROR (an error is reported at the next tick, not up to a period later), or if force.
  void Tick(bool force = false);
  std::string channel() const { return channel_; }
  const std::string& process() const { return process_; }
  int level() const { return level_; }
  const std::string& message() const { return message_; }
  int64_t dropped() const { return dropped_; }

 private:
  LcmInterface* lcm_;
  std::string process_;
  std::string channel_;
  double period_s_;
  int64_t in_ = 0, out_ = 0, dropped_ = 0;
  double item_ms_sum_ = 0.0;
  int64_t item_count_ = 0;
  int level_ = 3;  // STARTING
  std::string message_ = "starting";
  std::map<std::string, double> values_;
  InputGaps gaps_;
  Utime last_publish_ = 0;
  bool error_pending_ = false;  // the level became LEVEL_ERROR since the last report
};

}  // namespace fl
