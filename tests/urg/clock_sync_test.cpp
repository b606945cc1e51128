// The 24-bit timestamp's wrap and the TM + drift-filter clock synchronisation on synthetic
// clocks with a known offset and skew.
#include "fusionloc/urg/clock_sync.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace fl::urg {
namespace {

constexpr int64_t kWrap = int64_t{1} << 24;

TEST(TimestampUnwrapper, CountsOnAcrossTheWrap) {
  TimestampUnwrapper u;
  EXPECT_EQ(u.Unwrap(kWrap - 100), kWrap - 100);
  EXPECT_EQ(u.Unwrap(kWrap - 1), kWrap - 1);
  EXPECT_EQ(u.Unwrap(5), kWrap + 5);  // wrapped
  EXPECT_EQ(u.Unwrap(3), kWrap + 3);  // a small step back is a step back, not a wrap
  EXPECT_EQ(u.Unwrap(kWrap - 10), kWrap - 10);
  // Three whole wraps of 100 ms steps (13.98 h of sensor time).
  TimestampUnwrapper v;
  int64_t t = kWrap - 250;
  v.Unwrap(static_cast<uint32_t>(t % kWrap));
  for (int i = 0; i < 3 * kWrap / 100; ++i) {
    t += 100;
    ASSERT_EQ(v.Unwrap(static_cast<uint32_t>(t % kWrap)), t);
  }
}

// The sensor's clock: sensor_ms = floor(start + (host - host0) * (1 + skew)) mod 2^24.
struct SensorClock {
  double start_ms, skew;
  Utime host0;
  double Ms(Utime host) const { return start_ms + (host - host0) * 1e-3 * (1.0 + skew); }
  uint32_t Raw(Utime host) const {
    return static_cast<uint32_t>(static_cast<int64_t>(std::floor(Ms(host))) % kWrap);
  }
};

TEST(ClockSync, TmAndScanArrivalsRecoverOffsetAndSkewAcrossTheWrap) {
  for (double skew_ppm : {-150.0, 0.0, 80.0, 2000.0}) {
    const Utime host0 = 1'700'000'000'000'000;
    const SensorClock clock{static_cast<double>(kWrap) - 60'000.0, skew_ppm * 1e-6, host0};
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> jitter(0.0, 1500.0);  // [us] read delays
    ClockSyncOptions o;
    ClockSync sync(o);
    TimestampUnwrapper unwrap;
    // TM: 10 requests of ~2 ms round trip.
    Utime host = host0 + 1000;
    for (int i = 0; i < 10; ++i) {
      const Utime before = host;
      const Utime reading = before + 800 + static_cast<Utime>(jitter(rng) * 0.2);
      const Utime after = reading + 800 + static_cast<Utime>(jitter(rng) * 0.2);
      sync.AddTmSample(unwrap.Unwrap(clock.Raw(reading)), before, after);
      host = after + 3000;
    }
    ASSERT_TRUE(sync.FinishTm());
    // Scans at 10 Hz for 10 minutes (crossing the wrap after 1 minute); each arrives 72 ms
    // after its step 0 plus jitter, and now and then one very late.
    Utime step0 = host + 50'000;
    double worst_us = 0.0;
    for (int k = 0; k < 6000; ++k, step0 += 100'000) {
      const uint32_t raw = clock.Raw(step0);
      const int64_t sensor_ms = unwrap.Unwrap(raw);
      const Utime arrival =
          step0 + 72'000 + static_cast<Utime>(jitter(rng)) + (k % 97 == 5 ? 80'000 : 0);
      sync.AddArrival(sensor_ms, arrival);
      if (k >= 600) {
        // The host time of the tick `raw` shows: step0 less the fraction of a millisecond
        // the floor dropped. Compare the middle of that millisecond.
        const double err =
            static_cast<double>(sync.ToHost(sensor_ms + 0.5)) -
            (static_cast<double>(step0) -
             (clock.Ms(step0) - std::floor(clock.Ms(step0)) - 0.5) * 1000.0 / (1.0 + clock.skew));
        worst_us = std::max(worst_us, std::fabs(err));
      }
    }
    EXPECT_NEAR(sync.skew_ppm(), skew_ppm, 5.0) << skew_ppm;
    EXPECT_LT(worst_us, 2500.0) << skew_ppm;         // within the TM round trip and the jitter
    EXPECT_LT(sync.residual_ms(), 2.0) << skew_ppm;  // jitter 0..1.5 ms and the 1 ms tick
    EXPECT_GT(sync.residual_ms(), 0.1) << skew_ppm;  // the jitter is there
    // 72 ms: the least delayed arrivals, from the start of the millisecond the stamp shows.
    EXPECT_NEAR(sync.latency_ms(), 72.5, 0.6) << skew_ppm;  // + a fraction of the tick
  }
}

TEST(ClockSync, WithoutTmTheArrivalsGiveTheStamps) {
  ClockSync sync(ClockSyncOptions{});
  EXPECT_FALSE(sync.FinishTm());
  sync.AddArrival(1000, 5'000'000);
  EXPECT_TRUE(sync.synced());
  EXPECT_EQ(sync.ToHost(1000), 5'000'000);
  EXPECT_EQ(sync.ToHost(1100), 5'100'000);
}

TEST(ClockSync, OptionsAreValidated) {
  ClockSyncOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.window = 3;
  EXPECT_FALSE(o.Validate().ok());
}

}  // namespace
}  // namespace fl::urg
