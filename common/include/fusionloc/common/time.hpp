// One time type everywhere: int64 microseconds ("utime"), since the Unix epoch for live data
// and since an arbitrary origin for simulated data.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace fl {

using Utime = int64_t;  // [us]

constexpr Utime kUtimePerSecond = 1000000;

inline double UtimeToSeconds(Utime t) { return static_cast<double>(t) * 1e-6; }
inline Utime SecondsToUtime(double s) {
  return static_cast<Utime>(s * 1e6 + (s >= 0 ? 0.5 : -0.5));
}

// Wall-clock time now.
inline Utime NowUtime() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Monotonic clock, for measuring durations.
inline Utime MonotonicUtime() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// "12.345678 s" style, for messages.
std::string FormatUtime(Utime t);

}  // namespace fl
