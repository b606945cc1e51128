#include "fusionloc/common/clock_jump_guard.hpp"

#include <gtest/gtest.h>

namespace fl {
namespace {

constexpr Utime kS = 1000000;

// A stream at 10 Hz whose stamps jump 60 s ahead for 5 s: the jumped items are rejected with a
// message naming the stream, the others accepted, also after the jump.
TEST(ClockJumpGuard, ForwardJumpIsRejectedUntilTheStampsAgreeAgain) {
  ClockJumpGuard guard;
  int accepted = 0, rejected = 0;
  for (int k = 0; k < 200; ++k) {
    const Utime arrival = 1000 * kS + k * kS / 10;
    const bool jumped = k >= 50 && k < 100;
    const Utime utime = arrival - 20000 + (jumped ? 60 * kS : 0);
    const Status st = guard.Check("RBPF_POSE", utime, arrival);
    if (st.ok()) guard.Accept(utime, arrival);
    EXPECT_EQ(st.ok(), !jumped) << "item " << k;
    if (!st.ok()) {
      EXPECT_NE(st.message().find("RBPF_POSE"), std::string::npos);
      EXPECT_NE(st.message().find("jumped forward"), std::string::npos);
    }
    (st.ok() ? accepted : rejected)++;
  }
  EXPECT_EQ(accepted, 150);
  EXPECT_EQ(rejected, 50);
}

// A stream that pauses (its stamps and its arrivals both advance 30 s) and one whose arrivals
// jitter by up to half a second are accepted; an item the consumer refused (a stamp of -1,
// going backwards) does not become the baseline.
TEST(ClockJumpGuard, PausesAndJitterAreAcceptedRefusedItemsChangeNothing) {
  ClockJumpGuard guard;
  auto take = [&](Utime utime, Utime arrival) {
    const Status st = guard.Check("X", utime, arrival);
    if (st.ok()) guard.Accept(utime, arrival);
    return st.ok();
  };
  EXPECT_TRUE(take(10 * kS, 100 * kS));
  EXPECT_TRUE(take(40 * kS, 130 * kS));
  EXPECT_TRUE(take(40 * kS + kS / 10, 130 * kS + kS / 2));
  EXPECT_TRUE(take(40 * kS + kS / 5, 130 * kS + kS / 2 + 1000));
  // A corrupted stamp a few hundred years ahead, then the stream goes on.
  EXPECT_FALSE(take(1000000000000 * kS, 131 * kS));
  EXPECT_TRUE(take(41 * kS, 131 * kS));
  // A stamp of -1 the consumer refuses (Check alone, no Accept): the next real one passes.
  EXPECT_TRUE(guard.Check("X", -1, 131 * kS + kS / 10).ok());
  EXPECT_TRUE(take(41 * kS + kS / 5, 131 * kS + kS / 5));
}

}  // namespace
}  // namespace fl
