// fl-logger's recorder: LCM messages into an LCM log (lcm-logger's format) that never looks
// complete unless it is. The events go to OUTPUT.partial (rosbag's `.active` convention),
// flushed to the kernel at an interval (a kill -9 keeps what was flushed), and the file is
// renamed to OUTPUT only when the recording stops cleanly. A write error (ENOSPC, EIO) stops
// the recording with an error naming the file, the reason, and what was recorded; the
// partial file keeps the events written until then and is not renamed.
//
//   auto lcm = fl::MakeLcm(url);
//   fl::logger::Logger logger(lcm.get(), options);   // refuses an existing OUTPUT
//   logger.Run([] { return fl::ShutdownRequested(); });
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"

namespace fl::logger {

struct LoggerOptions {
  // The LCM log to write (OUTPUT.partial until the recording stops cleanly). Required.
  std::string output;
  // Channels recorded: LCM's anchored regular expression (".*": all, as lcm-logger).
  std::string channel_regex = ".*";
  // Overwrite an existing OUTPUT (deleted when the recording starts, so that an old log is
  // never taken for the new one) and OUTPUT.partial. Without it both are refused.
  bool force = false;
  // [ms] What was recorded is handed to the kernel this often (0: after every message).
  int flush_interval_ms = 100;
  // [s] One progress line (events, MB, rates) on stderr this often; 0: none.
  double progress_interval_s = 10.0;
  // [s] Live LCM that keeps failing to receive this long ends the recording with an error.
  double lcm_failure_timeout_s = 2.0;

  // "" if the flags' values are valid, else what is wrong (naming the flag).
  std::string Check() const;
};

struct LoggerReport {
  int64_t events = 0;  // recorded
  int64_t bytes = 0;   // their size in the log, event headers included
  double wall_s = 0.0;
  bool input_ended = false;  // a log: input was read to its end
};

class Logger {
 public:
  // Refuses an existing OUTPUT or OUTPUT.partial unless options.force, opens OUTPUT.partial
  // and subscribes. Throws std::runtime_error naming the file and the fix.
  Logger(LcmInterface* lcm, LoggerOptions options);

  // Records until stop() is true (checked between messages, at least every 100 ms) or a
  // log: input ends; then flushes, closes and renames OUTPUT.partial to OUTPUT. Throws
  // std::runtime_error on a write error (the file, the reason, the events and bytes recorded
  // until then; OUTPUT.partial is kept and not renamed), or when live LCM keeps failing.
  LoggerReport Run(const std::function<bool()>& stop);

  int64_t events() const { return events_; }
  int64_t bytes() const { return bytes_; }
  const std::string& partial_path() const { return partial_; }

 private:
  using Clock = std::chrono::steady_clock;
  // Checks (and with force clears) OUTPUT and OUTPUT.partial; returns OUTPUT.partial.
  static std::string PrepareOutput(const LoggerOptions& options);
  void OnMessage(const std::string& channel, const void* data, int size, Utime utime);
  void Progress(Clock::time_point now);
  [[noreturn]] void FailWrite(const std::string& what);

  LcmInterface* lcm_;
  LoggerOptions options_;
  std::string partial_;
  LcmLogWriter writer_;
  std::string write_error_;  // the first write error ("" if none)
  int64_t events_ = 0;
  int64_t bytes_ = 0;
  bool unflushed_ = false;
  Clock::time_point start_;
  Clock::time_point last_progress_;
  int64_t progress_events_ = 0;
  int64_t progress_bytes_ = 0;
  RateLimitedWarning lcm_warning_;
};

}  // namespace fl::logger
