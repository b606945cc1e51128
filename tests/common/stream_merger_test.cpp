#include "fusionloc/common/stream_merger.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

namespace fl {
namespace {

TEST(StreamMerger, ReleasesInTimeOrderAcrossStreams) {
  StreamMerger<int> m(1000000);
  const int a = m.AddStream("A"), b = m.AddStream("B");
  ASSERT_TRUE(m.Push(a, 10, 1).ok());
  ASSERT_TRUE(m.Push(a, 30, 3).ok());
  StreamMerger<int>::Item it;
  EXPECT_FALSE(m.Pop(&it));  // B has said nothing yet: A@10 must wait
  ASSERT_TRUE(m.Push(b, 20, 2).ok());
  ASSERT_TRUE(m.Pop(&it));
  EXPECT_EQ(it.value, 1);
  ASSERT_TRUE(m.Pop(&it));
  EXPECT_EQ(it.value, 2);
  EXPECT_FALSE(m.Pop(&it));  // A@30 waits for B to pass 30
  ASSERT_TRUE(m.Push(b, 40, 4).ok());
  ASSERT_TRUE(m.Pop(&it));
  EXPECT_EQ(it.value, 3);
  m.Flush();
  ASSERT_TRUE(m.Pop(&it));
  EXPECT_EQ(it.value, 4);
  EXPECT_EQ(m.queued(), 0u);
}

TEST(StreamMerger, SilentStreamDoesNotStallBeyondLatency) {
  StreamMerger<int> m(100);
  const int a = m.AddStream("A");
  m.AddStream("B");
  ASSERT_TRUE(m.Push(a, 0, 0).ok());
  StreamMerger<int>::Item it;
  EXPECT_FALSE(m.Pop(&it));
  ASSERT_TRUE(m.Push(a, 150, 1).ok());
  ASSERT_TRUE(m.Pop(&it));
  EXPECT_EQ(it.value, 0);
}

TEST(StreamMerger, PlacesReorderedItemsAndRejectsLateOnes) {
  StreamMerger<int> m(100);
  const int a = m.AddStream("A"), b = m.AddStream("B");
  ASSERT_TRUE(m.Push(a, 50, 0).ok());
  ASSERT_TRUE(m.Push(a, 40, 1).ok());  // reordered by the transport: placed before 50
  ASSERT_TRUE(m.Push(a, 45, 3).ok());
  ASSERT_TRUE(m.Push(b, 60, 2).ok());
  StreamMerger<int>::Item it;
  std::vector<int> order;
  while (m.Pop(&it)) order.push_back(it.value);
  EXPECT_EQ(order, (std::vector<int>{1, 3, 0}));  // B@60 waits until A passes 60
  const Status too_late = m.Push(a, 30, 4);  // older than what was released
  EXPECT_FALSE(too_late.ok());
  EXPECT_NE(too_late.message().find("was processed"), std::string::npos) << too_late.message();
  StreamMerger<int> m2(10);
  const int c = m2.AddStream("C"), d = m2.AddStream("D");
  ASSERT_TRUE(m2.Push(c, 100, 0).ok());
  ASSERT_TRUE(m2.Push(c, 200, 1).ok());
  ASSERT_TRUE(m2.Pop(&it));  // D silent; 100 is > latency behind 200
  const Status late = m2.Push(d, 50, 9);
  EXPECT_FALSE(late.ok());
  EXPECT_NE(late.message().find("stream 'D'"), std::string::npos);
}

// A stream whose clock jumps a minute ahead is rejected while the other stream is still
// arriving, and accepted again once its stamps agree; nothing of the other stream is lost.
TEST(StreamMerger, ClockJumpingForwardIsRejectedUntilConsistent) {
  StreamMerger<int> m(300000);  // 0.3 s latency, so the lead allowed is 1.3 s
  const int laser = m.AddStream("LASER"), odom = m.AddStream("ODOMETRY");
  std::vector<int> out;
  StreamMerger<int>::Item it;
  int rejected = 0;
  for (int i = 0; i < 100; ++i) {  // 10 s at 10 Hz; the laser 60 s ahead for i in [40, 50)
    const Utime t = 100000 * i;
    ASSERT_TRUE(m.Push(odom, t, 1000 + i, /*arrival=*/t).ok());
    const Utime stamp = (i >= 40 && i < 50) ? t + 60000000 : t + 50000;
    const Status s = m.Push(laser, stamp, i, /*arrival=*/t + 50000);
    if (!s.ok()) {
      ++rejected;
      EXPECT_NE(s.message().find("clock jumped forward"), std::string::npos) << s.message();
    }
    while (m.Pop(&it)) out.push_back(it.value);
  }
  EXPECT_EQ(rejected, 10);
  m.Flush();
  while (m.Pop(&it)) out.push_back(it.value);
  int odometry = 0, scans = 0;
  for (int v : out) (v >= 1000 ? odometry : scans)++;
  EXPECT_EQ(odometry, 100);
  EXPECT_EQ(scans, 90);
  EXPECT_TRUE(std::is_sorted(out.begin(), out.end(), [](int a, int b) {
    auto time = [](int v) { return v >= 1000 ? 100000 * (v - 1000) : 100000 * v + 50000; };
    return time(a) < time(b);
  }));
}

// Without arrival times, or once the other stream has gone silent, there is nothing to
// compare with: a stream alone is never held back by the check.
TEST(StreamMerger, ClockCheckNeedsAStreamStillArriving) {
  StreamMerger<int> m(300000);
  const int a = m.AddStream("A"), b = m.AddStream("B");
  ASSERT_TRUE(m.Push(b, 0, 0, 0).ok());
  EXPECT_TRUE(m.Push(a, 60000000, 1).ok());  // no arrival given
  StreamMerger<int> n(300000);
  const int c = n.AddStream("C"), d = n.AddStream("D");
  ASSERT_TRUE(n.Push(d, 0, 0, 0).ok());
  // D last arrived 5 s ago (silent): C's stamps far ahead of D's are accepted.
  EXPECT_TRUE(n.Push(c, 5000000, 1, 5000000).ok());
  // D arriving again but behind: D is the one compared with C now, and D is not ahead.
  EXPECT_TRUE(n.Push(d, 5100000, 2, 5100000).ok());
}

// Found by fuzzing (tests/fuzz/regressions/rbpf_node/stream-merger-overflow): a stamp near
// INT64_MIN on one stream, a sane one on the other; the lead check subtracted them (signed
// overflow, undefined behaviour). The differences saturate: the sane stamp is far ahead of
// the corrupt one and is dropped as a clock jump, the corrupt one never runs ahead.
TEST(StreamMerger, StampsAtTheEndsOfInt64DoNotOverflow) {
  StreamMerger<int> m(300000);
  const int a = m.AddStream("A"), b = m.AddStream("B");
  ASSERT_TRUE(m.Push(b, INT64_MIN + 1000, 0, 0).ok());
  EXPECT_FALSE(m.Push(a, 1000000, 1, 100).ok());
  EXPECT_TRUE(m.Push(b, INT64_MIN + 2000, 2, INT64_MAX).ok());
  StreamMerger<int>::Item item;
  while (m.Pop(&item)) {
  }
  m.Flush();
  EXPECT_TRUE(m.Pop(&item));
}

}  // namespace
}  // namespace fl
