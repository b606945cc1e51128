#include "fusionloc/viewer/frame.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <thread>

namespace fl::viewer {
namespace {

TEST(Frame, EncodesHeaderAndAlignedPayload) {
  const float payload[3] = {1.5f, -2.0f, 3.25f};
  const Frame f = MakeFrame("k", "{\"type\":\"x\"}", payload, sizeof(payload));
  // 4 + 12 header bytes = 16, already aligned; then 12 payload bytes.
  EXPECT_EQ(f.bytes.size(), 16u + 12u);
  std::string header, body;
  ASSERT_TRUE(DecodeFrame(f.bytes, &header, &body));
  EXPECT_EQ(header, "{\"type\":\"x\"}");
  ASSERT_EQ(body.size(), sizeof(payload));
  float back[3];
  std::memcpy(back, body.data(), sizeof(back));
  EXPECT_EQ(back[2], 3.25f);
  const Frame g = MakeFrame("", "{}");  // 4 + 2 -> padded to 8
  EXPECT_EQ(g.bytes.size(), 8u);
  EXPECT_FALSE(DecodeFrame("ab", &header, &body));
  EXPECT_FALSE(DecodeFrame(std::string("\x40\0\0\0{}", 6), &header, &body));
}

TEST(FrameQueue, ReplacesByKeyAndDropsTheOldestWhenFull) {
  FrameQueue q(3);
  q.Push({"grid", "g1"});
  q.Push({"", "a1"});
  q.Push({"grid", "g2"});  // replaces g1 in place
  EXPECT_EQ(q.size(), 2u);
  EXPECT_EQ(q.replaced(), 1);
  q.Push({"", "a2"});
  q.Push({"", "a3"});  // full: g2 (the oldest) goes
  EXPECT_EQ(q.size(), 3u);
  EXPECT_EQ(q.dropped(), 1);
  Frame f;
  ASSERT_TRUE(q.Pop(&f, 0));
  EXPECT_EQ(f.bytes, "a1");
  ASSERT_TRUE(q.Pop(&f, 0));
  EXPECT_EQ(f.bytes, "a2");
  ASSERT_TRUE(q.Pop(&f, 0));
  EXPECT_EQ(f.bytes, "a3");
  EXPECT_FALSE(q.Pop(&f, 10));  // empty: times out
}

TEST(FrameQueue, PushNeverBlocksOnAStalledReader) {
  FrameQueue q(16);
  for (int i = 0; i < 100000; ++i) q.Push({"", std::to_string(i)});  // nobody pops
  EXPECT_EQ(q.size(), 16u);
  EXPECT_EQ(q.dropped(), 100000 - 16);
  Frame f;
  ASSERT_TRUE(q.Pop(&f, 0));
  EXPECT_EQ(f.bytes, std::to_string(100000 - 16));  // the newest 16 are kept
}

TEST(FrameQueue, CloseWakesAWaitingReader) {
  FrameQueue q(4);
  std::thread t([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    q.Close();
  });
  Frame f;
  EXPECT_FALSE(q.Pop(&f, 5000));
  EXPECT_TRUE(q.closed());
  t.join();
  q.Push({"", "late"});
  EXPECT_EQ(q.size(), 0u);
}

}  // namespace
}  // namespace fl::viewer
