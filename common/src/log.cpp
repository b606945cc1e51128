#include "fusionloc/common/log.hpp"

#include <cstdio>
#include <ctime>
#include <mutex>

#include "fusionloc/common/time.hpp"

namespace fl {
namespace {
LogLevel g_level = LogLevel::INFO;
std::string g_process = "fusionloc";
std::mutex g_mutex;
}  // namespace

void SetLogLevel(LogLevel level) { g_level = level; }
LogLevel GetLogLevel() { return g_level; }
void SetLogProcessName(const std::string& name) { g_process = name; }

bool ParseLogLevel(const std::string& text, LogLevel* level) {
  if (text == "debug")
    *level = LogLevel::DEBUG;
  else if (text == "info")
    *level = LogLevel::INFO;
  else if (text == "warn" || text == "warning")
    *level = LogLevel::WARN;
  else if (text == "error")
    *level = LogLevel::ERROR;
  else
    return false;
  return true;
}

LogMessage::~LogMessage() {
  static const char kLetters[] = {'D', 'I', 'W', 'E'};
  const Utime now = NowUtime();
  const std::time_t secs = static_cast<std::time_t>(now / kUtimePerSecond);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char stamp[32];
  std::snprintf(stamp, sizeof(stamp), "%02d:%02d:%02d.%03d", tm.tm_hour, tm.tm_min, tm.tm_sec,
                static_cast<int>((now % kUtimePerSecond) / 1000));
  std::lock_guard<std::mutex> lock(g_mutex);
  std::fprintf(stderr, "[%c %s %s] %s\n", kLetters[static_cast<int>(level_)], stamp,
               g_process.c_str(), stream_.str().c_str());
}

void RateLimitedWarning::Warn(const std::string& message) {
  ++count_;
  const Utime now = MonotonicUtime();
  if (static_cast<double>(now - last_print_us_) * 1e-6 < interval_s_) {
    ++suppressed_;
    return;
  }
  FL_LOG(WARN) << message
               << (suppressed_ > 0 ? " (+" + std::to_string(suppressed_) + " similar suppressed)"
                                   : std::string())
               << " [total " << count_ << "]";
  suppressed_ = 0;
  last_print_us_ = now;
}

std::string FormatUtime(Utime t) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.6f s", UtimeToSeconds(t));
  return buf;
}

}  // namespace fl
