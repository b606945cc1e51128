#include "fusionloc/common/time.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace fl {
namespace {

TEST(TimeTest, SecondsToUtimeRounds) {
  EXPECT_EQ(SecondsToUtime(1.0000004), 1000000);
  EXPECT_EQ(SecondsToUtime(1.0000006), 1000001);
  EXPECT_EQ(SecondsToUtime(-1.0000006), -1000001);
}

// A time read from a bad file (1e300 s, inf, nan) is a nonsense value, not undefined
// behaviour: it saturates, and NaN is 0.
TEST(TimeTest, SecondsToUtimeSaturates) {
  EXPECT_EQ(SecondsToUtime(1e300), std::numeric_limits<Utime>::max());
  EXPECT_EQ(SecondsToUtime(-1e300), std::numeric_limits<Utime>::min());
  EXPECT_EQ(SecondsToUtime(INFINITY), std::numeric_limits<Utime>::max());
  EXPECT_EQ(SecondsToUtime(NAN), 0);
  EXPECT_EQ(SecondsToUtime(9.2e12), 9200000000000000000LL);
}

TEST(TimeTest, SecondsBetweenFarApartTimes) {
  EXPECT_DOUBLE_EQ(SecondsBetween(1000000, 3500000), 2.5);
  EXPECT_DOUBLE_EQ(SecondsBetween(std::numeric_limits<Utime>::min(), std::numeric_limits<Utime>::max()),
                   18446744073709.551615);
}

}  // namespace
TEST(TimeTest, UtimeDifferenceSaturates) {
  EXPECT_EQ(UtimeDifference(1000, 3000), 2000);
  EXPECT_EQ(UtimeDifference(INT64_MIN + 10, 1000000), INT64_MAX);
  EXPECT_EQ(UtimeDifference(1000000, INT64_MIN + 10), INT64_MIN);
  EXPECT_EQ(UtimeDifference(INT64_MAX, INT64_MIN), INT64_MIN);
}

}  // namespace fl
