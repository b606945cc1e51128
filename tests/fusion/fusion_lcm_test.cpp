// FusionNode's state file: a respawned fusion goes on in the map frame it had.
#include "fusionloc/fusion/fusion_lcm.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <vector>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "test_paths.hpp"

namespace fl::fusion {
namespace {

bot_core::pose_t RbpfPose(Utime utime, const Pose2& T) {
  bot_core::pose_t m{};
  m.utime = utime;
  IsometryToArrays(T.ToIsometry3(), m.pos, m.orientation);
  return m;
}

// A live (memq://) FusionNode (inline solves, no map file) and the fused poses it publishes.
struct LiveFusion {
  explicit LiveFusion(const std::string& state_file = "") : lcm(MakeLcm("memq://")) {
    lcm->Subscribe<fusionloc::fused_pose_t>(
        channels::kFusedPose,
        [this](const fusionloc::fused_pose_t& m, const std::string&) { fused.push_back(m); });
    FusionNodeOptions options;
    options.map_out = "";
    options.sync_full_solve = true;
    options.state_file = state_file;
    node = std::make_unique<FusionNode>(FusionProcessConfig(), options, lcm.get(), ChannelMap());
  }
  template <class Msg>
  void Send(const std::string& channel, const Msg& msg) {
    lcm->Publish(channel, msg, 0);
    while (lcm->HandleSubscriptions(0) > 0) {
    }
  }
  std::unique_ptr<LcmInterface> lcm;
  std::vector<fusionloc::fused_pose_t> fused;
  std::unique_ptr<FusionNode> node;
};

// Runs a LiveFusion with `state_file` over RBPF poses; returns its fused poses.
std::vector<fusionloc::fused_pose_t> RunFusion(const std::string& state_file,
                                               const std::vector<Pose2>& rbpf) {
  LiveFusion f(state_file);
  for (size_t k = 0; k < rbpf.size(); ++k) {
    f.Send(channels::kRbpfPose, RbpfPose(1000000 + 1000000 * static_cast<Utime>(k), rbpf[k]));
  }
  return f.fused;
}

TEST(FusionNodeState, FormatAndParse) {
  Utime utime = 0;
  Pose2 T;
  std::string error;
  ASSERT_TRUE(ParseFusionState(FormatFusionState(42, Pose2(1.5, -2, 0.25)), &utime, &T, &error));
  EXPECT_EQ(utime, 42);
  EXPECT_EQ(T.x, 1.5);
  EXPECT_EQ(T.y, -2);
  EXPECT_EQ(T.theta, 0.25);
  EXPECT_FALSE(ParseFusionState("hello", &utime, &T, &error));
  EXPECT_NE(error.find("not a fusion state file"), std::string::npos);
  EXPECT_FALSE(ParseFusionState("fusionloc-fusion-state 1\nutime 3\nT_map_rbpf 1 nan 0\n", &utime,
                                &T, &error));
  EXPECT_NE(error.find("finite"), std::string::npos);
}

TEST(FusionNodeState, ARespawnedFusionGoesOnInItsMapFrame) {
  test::TempDir dir;
  const std::string state = dir.file("fusion.state");
  const std::vector<Pose2> rbpf = {Pose2(0, 0, 0), Pose2(1, 0, 0), Pose2(2, 0, 0.1)};
  // A first start: no state, the map frame is the RBPF's world; the state is written.
  std::vector<fusionloc::fused_pose_t> fused = RunFusion(state, rbpf);
  ASSERT_EQ(fused.size(), 3u);
  EXPECT_NEAR(fused.back().x, 2.0, 1e-9);
  ASSERT_TRUE(std::filesystem::exists(state));

  // A respawn finds a state whose map frame is 1 m ahead and turned by 0.5 rad.
  std::ofstream(state) << FormatFusionState(1000000, Pose2(1, 0, 0.5));
  fused = RunFusion(state, {Pose2(2, 0, 0)});
  ASSERT_EQ(fused.size(), 1u);
  EXPECT_NEAR(fused[0].x, 1 + 2 * std::cos(0.5), 1e-9);
  EXPECT_NEAR(fused[0].y, 2 * std::sin(0.5), 1e-9);
  EXPECT_NEAR(fused[0].theta, 0.5, 1e-9);

  // A state older than state_max_age_s (yesterday's run) is not used; nor is a malformed one.
  std::ofstream(state) << FormatFusionState(1000000, Pose2(1, 0, 0.5));
  std::filesystem::last_write_time(
      state, std::filesystem::file_time_type::clock::now() - std::chrono::hours(1));
  fused = RunFusion(state, {Pose2(2, 0, 0)});
  ASSERT_EQ(fused.size(), 1u);
  EXPECT_NEAR(fused[0].x, 2.0, 1e-9);
  std::ofstream(state) << "garbage";
  fused = RunFusion(state, {Pose2(2, 0, 0)});
  ASSERT_EQ(fused.size(), 1u);
  EXPECT_NEAR(fused[0].x, 2.0, 1e-9);
}

// Found by fuzzing (tests/fuzz/regressions/fusion_node/odometry-utime-overflow): odometry,
// poses, factors or points stamped near the ends of int64 made the fusion's time differences
// overflow (undefined behaviour). They are refused and counted; the good ones still fuse.
TEST(FusionNodeInput, TimeStampsOutOfRangeAreDroppedAndCounted) {
  LiveFusion f;
  fusionloc::wheel_odometry_t odo{};
  for (const Utime t : {Utime{1000000}, Utime{1100000}, INT64_MIN + 1000000}) {
    odo.utime = t;
    f.Send(channels::kOdometry, odo);
  }
  f.Send(channels::kRbpfPose, RbpfPose(INT64_MAX - 5, Pose2(0, 0, 0)));
  fusionloc::relative_pose_factor_t factor{};
  factor.utime_i = INT64_MIN;
  factor.utime_j = 1000000;
  factor.quat[0] = 1.0;
  for (int i = 0; i < 6; ++i) factor.information[7 * i] = 1.0;
  f.Send(channels::kVoFactors, factor);
  EXPECT_EQ(f.node->status().dropped(), 3);
  EXPECT_TRUE(f.fused.empty());
  f.Send(channels::kRbpfPose, RbpfPose(1050000, Pose2(1, 0, 0)));
  ASSERT_EQ(f.fused.size(), 1u);
  EXPECT_NEAR(f.fused[0].x, 1.0, 1e-9);
  EXPECT_EQ(f.node->status().dropped(), 3);
}

}  // namespace
}  // namespace fl::fusion
