#include "fusionloc/common/stream_merger.hpp"

#include <gtest/gtest.h>

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

TEST(StreamMerger, RejectsTimeGoingBackwardsAndLateItems) {
  StreamMerger<int> m(100);
  const int a = m.AddStream("A"), b = m.AddStream("B");
  ASSERT_TRUE(m.Push(a, 50, 0).ok());
  const Status back = m.Push(a, 40, 1);
  EXPECT_FALSE(back.ok());
  EXPECT_NE(back.message().find("time went backwards"), std::string::npos);
  ASSERT_TRUE(m.Push(b, 60, 2).ok());
  StreamMerger<int>::Item it;
  ASSERT_TRUE(m.Pop(&it));
  EXPECT_EQ(it.value, 0);
  EXPECT_FALSE(m.Pop(&it));  // B@60 waits until A passes 60 (or the latency expires)
  StreamMerger<int> m2(10);
  const int c = m2.AddStream("C"), d = m2.AddStream("D");
  ASSERT_TRUE(m2.Push(c, 100, 0).ok());
  ASSERT_TRUE(m2.Push(c, 200, 1).ok());
  ASSERT_TRUE(m2.Pop(&it));  // D silent; 100 is > latency behind 200
  const Status late = m2.Push(d, 50, 9);
  EXPECT_FALSE(late.ok());
  EXPECT_NE(late.message().find("stream 'D'"), std::string::npos);
}

}  // namespace
}  // namespace fl
