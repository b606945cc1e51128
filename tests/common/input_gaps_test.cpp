#include "fusionloc/common/input_gaps.hpp"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace fl
