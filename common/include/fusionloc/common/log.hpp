// Minimal leveled logging to stderr: "[W 12:03:04.123 fl-sim] message".
//
//   FL_LOG(INFO) << "started";
//   FL_LOG(WARN) << "dropped message on " << channel;
//
// Use fl::RateLimitedWarning for warnings that a bad input stream could repeat at high rate.
#pragma once

#include <cstdint>
#include <sstream>
#include <string>

namespace fl {

enum class LogLevel { DEBUG = 0, INFO = 1, WARN = 2, ERROR = 3 };

void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
// Name printed in every line; set once by each process (e.g. "fl-sim").
void SetLogProcessName(const std::string& name);
// Parses "debug", "info", "warn", "error"; returns false if unknown.
bool ParseLogLevel(const std::string& text, LogLevel* level);

class LogMessage {
 public:
  explicit LogMessage(LogLevel level) : level_(level) {}
  ~LogMessage();
  std::ostringstream& stream() { return stream_; }

 private:
  LogLevel level_;
  std::ostringstream stream_;
};

// Counts a repeated warning and prints it at most once per `interval_s`, with the count of
// suppressed repeats, so a flood of bad messages cannot flood the log but is never silent.
class RateLimitedWarning {
 public:
  explicit RateLimitedWarning(double interval_s = 5.0) : interval_s_(interval_s) {}
  void Warn(const std::string& message);
  int64_t count() const { return count_; }

 private:
  double interval_s_;
  int64_t count_ = 0;
  int64_t suppressed_ = 0;
  int64_t last_print_us_ = INT64_MIN / 2;
};

}  // namespace fl

namespace fl::internal {
// Turns the streamed expression into void so that FL_LOG works as one expression.
struct LogVoidify {
  void operator&(std::ostream&) {}
};
}  // namespace fl::internal

#define FL_LOG(level)                           \
  (::fl::LogLevel::level < ::fl::GetLogLevel()) \
      ? (void)0                                 \
      : ::fl::internal::LogVoidify() & ::fl::LogMessage(::fl::LogLevel::level).stream()
