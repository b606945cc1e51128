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
// Rounded to the microsecond. Saturates at the int64 range (about ±292000 years) and maps NaN
// to 0, so that a nonsense time read from a file is a nonsense value, never undefined
// behaviour (the cast of an out-of-range double).
inline Utime SecondsToUtime(double s) {
  const double us = s * 1e6 + (s >= 0 ? 0.5 : -0.5);
  if (!(us == us)) return 0;
  if (us >= 9.2233720368547748e18) return INT64_MAX;
  if (us <= -9.2233720368547758e18) return INT64_MIN;
  return static_cast<Utime>(us);
}
// b - a in seconds, without the int64 overflow of subtracting far-apart utimes.
inline double SecondsBetween(Utime a, Utime b) {
  return (static_cast<double>(b) - static_cast<double>(a)) * 1e-6;
}

// b - a in microseconds, saturated at the int64 range instead of overflowing (a corrupt stamp
// near INT64_MIN minus a sane one is undefined behaviour otherwise).
inline Utime UtimeDifference(Utime a, Utime b) {
  Utime d = 0;
  if (__builtin_sub_overflow(b, a, &d)) return b > a ? INT64_MAX : INT64_MIN;
  return d;
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
