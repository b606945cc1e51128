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
// jitter by up to half a second are accepted.
TEST(ClockJumpGuard, PausesAndJitterAreAccepted) {
  ClockJumpGuard guard;
  EXPECT_TRUE(guard.Check("X", 10 * kS, 100 * kS).ok());
  EXPECT_TRUE(guard.Check("X", 40 * kS, 130 * kS).ok());
  EXPECT_TRUE(guard.Check("X", 40 * kS + kS / 10, 130 * kS + kS / 2).ok());
  EXPECT_TRUE(guard.Check("X", 40 * kS + kS / 5, 130 * kS + kS / 2 + 1000).ok());
  // A corrupted stamp a few hundred years ahead, then the stream goes on.
  EXPECT_FALSE(guard.Check("X", 1000000000000 * kS, 131 * kS).ok());
  EXPECT_TRUE(guard.Check("X", 41 * kS, 131 * kS).ok());
}

}  // namespace
}  // namespace fl
