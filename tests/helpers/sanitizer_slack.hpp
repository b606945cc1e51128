// Bounds on real-time behaviour in tests under the sanitizer builds.
#pragma once

namespace fl::test {

// How much more a bound on real-time behaviour (the host's scheduling jitter, not our
// arithmetic) may be widened in a sanitizer build (`fusionloc test --sanitize|--tsan`), whose
// instrumented code runs 2-15x slower: 1 in a normal build.
inline double SanitizerTimingSlack() {
#if defined(__SANITIZE_THREAD__)
  return 10.0;
#elif defined(__SANITIZE_ADDRESS__)
  return 3.0;
#else
  return 1.0;
#endif
}

}  // namespace fl::test
