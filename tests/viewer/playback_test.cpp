#include "fusionloc/viewer/playback.hpp"

#include <gtest/gtest.h>

namespace fl::viewer {
namespace {

TEST(PlaybackCommand, ParsesTheFourCommandsAndRejectsTheRest) {
  PlaybackCommand c;
  std::string e;
  ASSERT_TRUE(ParsePlaybackCommand("play", &c, &e));
  EXPECT_EQ(c.kind, PlaybackCommand::kPlay);
  ASSERT_TRUE(ParsePlaybackCommand("seek 12.5", &c, &e));
  EXPECT_EQ(c.kind, PlaybackCommand::kSeek);
  EXPECT_DOUBLE_EQ(c.value, 12.5);
  ASSERT_TRUE(ParsePlaybackCommand("speed 2", &c, &e));
  EXPECT_DOUBLE_EQ(c.value, 2.0);
  EXPECT_FALSE(ParsePlaybackCommand("speed 0", &c, &e));
  EXPECT_FALSE(ParsePlaybackCommand("seek", &c, &e));
  EXPECT_NE(e.find("seek needs a number"), std::string::npos);
  EXPECT_FALSE(ParsePlaybackCommand("rm -rf", &c, &e));
  EXPECT_NE(e.find("unknown command"), std::string::npos);
}

TEST(PlaybackClock, PlaysAtItsSpeedStopsAtTheEndAndSeeksWithinTheLog) {
  PlaybackClock clock(1000000, 11000000, 1.0, true);
  EXPECT_TRUE(clock.TakeSeek());  // the first view is built at the start
  EXPECT_FALSE(clock.TakeSeek());
  clock.Advance(2.0);
  EXPECT_EQ(clock.now(), 3000000);
  clock.Apply({PlaybackCommand::kSpeed, 4.0});
  clock.Advance(1.0);
  EXPECT_EQ(clock.now(), 7000000);
  clock.Apply({PlaybackCommand::kPause, 0});
  clock.Advance(5.0);
  EXPECT_EQ(clock.now(), 7000000);
  clock.Apply({PlaybackCommand::kSeek, 2.5});
  EXPECT_EQ(clock.now(), 3500000);
  EXPECT_TRUE(clock.TakeSeek());
  clock.Apply({PlaybackCommand::kSeek, 99});  // clamped
  EXPECT_EQ(clock.now(), 11000000);
  clock.Apply({PlaybackCommand::kPlay, 0});  // from the end: again from the start
  EXPECT_EQ(clock.now(), 1000000);
  EXPECT_TRUE(clock.playing());
  clock.Advance(100.0);
  EXPECT_EQ(clock.now(), 11000000);
  EXPECT_FALSE(clock.playing());
  EXPECT_NE(clock.Json().find("\"playing\":false"), std::string::npos);
}

}  // namespace
}  // namespace fl::viewer
