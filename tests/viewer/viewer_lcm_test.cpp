#include "fusionloc/viewer/viewer_lcm.hpp"

#include <gtest/gtest.h>

#include "bot_core/pose_t.hpp"
#include "bot_procman/info2_t.hpp"
#include "test_paths.hpp"
#include "viewer_fixtures.hpp"

namespace fl::viewer {
namespace {

template <class Msg>
std::vector<uint8_t> Encode(const Msg& m) {
  std::vector<uint8_t> b(static_cast<size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

std::string Header(const Frame& f) {
  std::string h, p;
  EXPECT_TRUE(DecodeFrame(f.bytes, &h, &p));
  return h;
}
const Frame* FindType(const std::vector<Frame>& frames, const std::string& type) {
  for (const Frame& f : frames) {
    if (Header(f).find("\"type\":\"" + type + "\"") != std::string::npos) return &f;
  }
  return nullptr;
}

TEST(MessageDecoder, DecodesEachChannelIntoTheSceneHonouringRenames) {
  ChannelMap channels;
  ASSERT_EQ(channels.Add("RBPF_MAP=FRONT_MAP"), "");
  MessageDecoder decoder(channels);
  Scene scene{SceneOptions{}};
  const auto grid = Encode(test::ViewerGridMsg(1000));
  decoder.Dispatch(&scene, "RBPF_MAP", grid.data(), static_cast<int>(grid.size()), 1000);
  EXPECT_FALSE(scene.has_grid());  // renamed away
  decoder.Dispatch(&scene, "FRONT_MAP", grid.data(), static_cast<int>(grid.size()), 1000);
  EXPECT_TRUE(scene.has_grid());

  bot_core::pose_t pose{};
  pose.utime = 2000;
  pose.pos[0] = 1.5;
  pose.orientation[0] = 1;
  const auto p = Encode(pose);
  decoder.Dispatch(&scene, "RBPF_POSE", p.data(), static_cast<int>(p.size()), 2000);
  EXPECT_EQ(scene.trail_size("RBPF_POSE"), 1u);

  bot_procman::info2_t info{};
  info.host = "robot";
  info.ncmds = 1;
  info.cmds.resize(1);
  info.cmds[0].cmd.command_name = "fusion";
  info.cmds[0].pid = 77;
  const auto i = Encode(info);
  decoder.Dispatch(&scene, "PMD_INFO2", i.data(), static_cast<int>(i.size()), 3000);
  const auto st = Encode(test::ViewerStatusMsg(3000, "fl-fusion"));
  decoder.Dispatch(&scene, "STATUS_FL_FUSION", st.data(), static_cast<int>(st.size()), 3000);
  // A status channel with bytes that are not a status_t: counted, not shown.
  decoder.Dispatch(&scene, "STATUS_BROKEN", grid.data(), 7, 3000);
  EXPECT_EQ(decoder.decode_errors(), 1);
  const std::vector<Frame> f = scene.TakeChanges(1.0);
  const Frame* pr = FindType(f, "processes");
  ASSERT_NE(pr, nullptr);
  EXPECT_NE(Header(*pr).find("\"process\":\"fl-fusion\""), std::string::npos);
  EXPECT_NE(Header(*pr).find("\"pid\":77"), std::string::npos);
  EXPECT_EQ(Header(*pr).find("STATUS_BROKEN"), std::string::npos);
  const Frame* r = FindType(f, "rates");
  ASSERT_NE(r, nullptr);
  EXPECT_NE(Header(*r).find("\"name\":\"STATUS_BROKEN\""), std::string::npos);  // still counted
}

TEST(LogViewer, SeeksRebuildTheViewAtTheSliderTime) {
  test::TempDir dir;
  const std::string log = dir.path() + "/drive.lcmlog";
  test::WriteViewerDriveLog(log);
  const test::ViewerDriveFixture drive;
  LogViewer viewer(ViewerOptions{}, log, ChannelMap{}, 1.0, false);
  EXPECT_EQ(viewer.clock().start(), drive.start);
  EXPECT_EQ(viewer.clock().end(), drive.start + SecondsToUtime(drive.duration_s));
  // The first step builds the view at the start: a reset, the grid, the robot at x = 0.
  std::vector<Frame> f = viewer.Step(0.0, 100.0);
  ASSERT_NE(FindType(f, "reset"), nullptr);
  ASSERT_NE(FindType(f, "grid"), nullptr);
  const Frame* poses = FindType(f, "poses");
  ASSERT_NE(poses, nullptr);
  EXPECT_NE(Header(*poses).find("\"FUSED_POSE\":[0,"), std::string::npos) << Header(*poses);
  // Paused: time does not move.
  f = viewer.Step(1.0, 101.0);
  EXPECT_EQ(viewer.clock().now(), drive.start);
  // Seek to 6.5 s: the robot is at x = 6.5.
  viewer.Command("seek 6.5");
  f = viewer.Step(0.0, 102.0);
  ASSERT_NE(FindType(f, "reset"), nullptr);
  poses = FindType(f, "poses");
  ASSERT_NE(poses, nullptr);
  EXPECT_NE(Header(*poses).find("\"FUSED_POSE\":[6.5,"), std::string::npos) << Header(*poses);
  const Frame* clock = FindType(f, "clock");
  ASSERT_NE(clock, nullptr);
  EXPECT_NE(Header(*clock).find("\"utime\":" + std::to_string(drive.start + 6500000)),
            std::string::npos);
  // Play at 2x for 1 s of wall time: 2 s of log on, no reset.
  viewer.Command("speed 2");
  viewer.Command("play");
  f = viewer.Step(1.0, 103.0);
  EXPECT_EQ(FindType(f, "reset"), nullptr);
  EXPECT_EQ(viewer.clock().now(), drive.start + 8500000);
  poses = FindType(f, "poses");
  ASSERT_NE(poses, nullptr);
  EXPECT_NE(Header(*poses).find("\"FUSED_POSE\":[8.5,"), std::string::npos) << Header(*poses);
  // A bad command changes nothing.
  viewer.Command("speed fast");
  viewer.Step(0.0, 104.0);
  EXPECT_DOUBLE_EQ(viewer.clock().speed(), 2.0);
  // A new browser gets hello, the view and the clock.
  const std::vector<Frame> snap = viewer.Snapshot();
  ASSERT_FALSE(snap.empty());
  EXPECT_NE(Header(snap.front()).find("\"mode\":\"log\""), std::string::npos);
  EXPECT_NE(FindType(snap, "clock"), nullptr);
  EXPECT_NE(FindType(snap, "grid"), nullptr);
}

TEST(LogViewer, AFileThatIsNotALogIsAClearError) {
  test::TempDir dir;
  const std::string path = dir.path() + "/not.lcmlog";
  { std::ofstream(path) << "hello"; }
  try {
    LogViewer viewer(ViewerOptions{}, path, ChannelMap{}, 1.0, true);
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("holds no LCM event"), std::string::npos) << e.what();
  }
  EXPECT_THROW(LogViewer(ViewerOptions{}, dir.path() + "/missing.lcmlog", ChannelMap{}, 1, true),
               std::runtime_error);
}

}  // namespace
}  // namespace fl::viewer
