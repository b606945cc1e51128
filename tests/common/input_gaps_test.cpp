#include "fusionloc/common/input_gaps.hpp"

#include <gtest/gtest.h>

#include <limits>

namespace fl {
namespace {

TEST(InputGaps, CountsMissingMessagesOnceThePeriodIsKnown) {
  InputGaps g;
  Utime t = 0;
  for (int i = 0; i < 20; ++i, t += 100000) EXPECT_FALSE(g.Add("LASER", t));
  EXPECT_EQ(g.period("LASER"), 100000);
  t += 200000;  // two scans missing
  EXPECT_TRUE(g.Add("LASER", t));
  t += 100000;
  EXPECT_FALSE(g.Add("LASER", t));
  t += 200000;  // one missing
  EXPECT_TRUE(g.Add("LASER", t));
  EXPECT_EQ(g.gaps("LASER"), 2);
  EXPECT_EQ(g.missing("LASER"), 3);
  EXPECT_EQ(g.period("LASER"), 100000);  // the gaps stay out of the period
  EXPECT_EQ(g.gaps("ODOMETRY"), 0);
}

TEST(InputGaps, JitterRepeatsAndTheStartAreNotGaps) {
  InputGaps g;
  // A long pause before the period is known is not counted (nothing to compare with).
  EXPECT_FALSE(g.Add("ODOMETRY", 0));
  EXPECT_FALSE(g.Add("ODOMETRY", 5000000));
  Utime t = 5000000;
  for (int i = 0; i < 40; ++i) {
    t += (i % 2 == 0) ? 8000 : 12000;  // 100 Hz with jitter
    EXPECT_FALSE(g.Add("ODOMETRY", t));
    EXPECT_FALSE(g.Add("ODOMETRY", t));        // repeated stamp
    EXPECT_FALSE(g.Add("ODOMETRY", t - 500));  // out of order
  }
  EXPECT_EQ(g.gaps("ODOMETRY"), 0);
  EXPECT_FALSE(g.Add("ODOMETRY", t + 13000));  // 1.1-1.6 periods: jitter, not a gap
  EXPECT_TRUE(g.Add("ODOMETRY", t + 13000 + 30000));
}

TEST(InputGaps, ClockJumpsAndCorruptStampsAreNotGaps) {
  // Found by the fusion_node fuzzer: a stamp near INT64_MIN then a sane one overflowed the
  // interval (undefined behaviour) and would have counted ~1e13 missing messages.
  InputGaps g;
  EXPECT_FALSE(g.Add("LASER", std::numeric_limits<Utime>::min() + 1000000));
  EXPECT_FALSE(g.Add("LASER", 1200000));
  Utime t = 1200000;
  for (int i = 0; i < 10; ++i) EXPECT_FALSE(g.Add("LASER", t += 100000));
  EXPECT_FALSE(g.Add("LASER", t += 3600LL * 1000000));  // an hour forward: a clock jump
  EXPECT_EQ(g.gaps("LASER"), 0);
  EXPECT_EQ(g.missing("LASER"), 0);
  EXPECT_TRUE(g.Add("LASER", t += 500000));  // 5 periods on the new clock: a gap
  EXPECT_EQ(g.missing("LASER"), 4);
}

}  // namespace
}  // namespace fl
