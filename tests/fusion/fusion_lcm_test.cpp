// FusionNode's journal: a respawned fusion replays the inputs it had taken and goes on with
// the same graph, in the same map frame.
#include "fusionloc/fusion/fusion_lcm.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <vector>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/trajectory_merge.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "test_paths.hpp"

namespace fl::fusion {
namespace {

constexpr int kSteps = 40;  // 4 s at 10 Hz

Utime StepTime(int k, Utime offset) { return offset + 1000000 + 100000 * static_cast<Utime>(k); }

// The robot's true pose at step k: a gentle left arc.
Pose2 TruePose(int k) {
  const double s = 0.1 * k;
  return Pose2(s, 0.02 * s * s, 0.04 * s);
}

// The RBPF's pose: the truth plus a drift that grows (what a respawned fusion without its
// graph would fall back to).
Pose2 RbpfPose(int k) { return TruePose(k) * Pose2(0.01 * k, 0.005 * k, 0.004 * k); }

// The wheel odometry message of step k (exact: the true pose).
fusionloc::wheel_odometry_t OdometryMessage(int k, Utime offset = 0) {
  fusionloc::wheel_odometry_t m{};
  m.utime = StepTime(k, offset);
  m.x = TruePose(k).x;
  m.y = TruePose(k).y;
  m.theta = TruePose(k).theta;
  return m;
}

// The RBPF pose message at `utime`.
bot_core::pose_t RbpfPoseMessage(Utime utime, const Pose2& T) {
  bot_core::pose_t m{};
  m.utime = utime;
  IsometryToArrays(T.ToIsometry3(), m.pos, m.orientation);
  return m;
}

struct FusionRun {
  std::vector<fusionloc::fused_pose_t> poses;
  std::vector<fusionloc::trajectory_t> trajectories;
};

// Runs a live (memq://) FusionNode with `journal` over steps [first, last): exact wheel
// odometry and the drifting RBPF poses. With `finish` the node finishes (a clean stop);
// without, it is destroyed as a kill -9 would leave it (the journal is flushed per input).
// `offset` [us] shifts every time (another run); `snapshot_s`: the journal's snapshot period.
FusionRun RunFusion(const std::string& journal, int first, int last, bool finish,
                    Utime offset = 0, double snapshot_s = 120.0,
                    const FusionProcessConfig& config = FusionProcessConfig(),
                    size_t retired_in_memory = RetiredTrajectory::kDefaultKeepInMemory) {
  auto lcm = MakeLcm("memq://");
  FusionRun run;
  lcm->Subscribe<fusionloc::fused_pose_t>(
      channels::kFusedPose,
      [&](const fusionloc::fused_pose_t& m, const std::string&) { run.poses.push_back(m); });
  lcm->Subscribe<fusionloc::trajectory_t>(
      channels::kFusedTrajectory,
      [&](const fusionloc::trajectory_t& m, const std::string&) { run.trajectories.push_back(m); });
  FusionNodeOptions options;
  options.map_out = "";
  options.sync_full_solve = true;
  options.journal = journal;
  options.journal_snapshot_s = snapshot_s;
  options.retired_in_memory = retired_in_memory;
  FusionNode node(config, options, lcm.get(), ChannelMap());
  for (int k = first; k < last; ++k) {
    lcm->Publish(channels::kOdometry, OdometryMessage(k, offset), StepTime(k, offset));
    lcm->Publish(channels::kRbpfPose, RbpfPoseMessage(StepTime(k, offset), RbpfPose(k)),
                 StepTime(k, offset));
    while (lcm->HandleSubscriptions(0) > 0) {
    }
    node.Poll();  // as the process loop does after every batch
  }
  if (finish) {
    node.Finish();
    while (lcm->HandleSubscriptions(0) > 0) {
    }
  }
  return run;
}

// A live (memq://) FusionNode (inline solves, no map file) and the fused poses it publishes.
struct LiveFusion {
  explicit LiveFusion(const FusionProcessConfig& config = FusionProcessConfig())
      : lcm(MakeLcm("memq://")) {
    lcm->Subscribe<fusionloc::fused_pose_t>(
        channels::kFusedPose,
        [this](const fusionloc::fused_pose_t& m, const std::string&) { fused.push_back(m); });
    FusionNodeOptions options;
    options.map_out = "";
    options.sync_full_solve = true;
    node = std::make_unique<FusionNode>(config, options, lcm.get(), ChannelMap());
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

double Distance(const fusionloc::fused_pose_t& m, const Pose2& T) {
  return std::hypot(m.x - T.x, m.y - T.y);
}

// The last FUSED_TRAJECTORY of both runs: the same stamps, poses within 0.1 mm.
void ExpectSameFinalTrajectory(const FusionRun& expected, const FusionRun& actual) {
  ASSERT_FALSE(expected.trajectories.empty());
  ASSERT_FALSE(actual.trajectories.empty());
  const auto& a = expected.trajectories.back();
  const auto& b = actual.trajectories.back();
  ASSERT_EQ(a.num_poses, b.num_poses);
  for (int i = 0; i < a.num_poses; ++i) {
    EXPECT_EQ(a.utimes[i], b.utimes[i]);
    EXPECT_NEAR(a.x[i], b.x[i], 1e-4) << i;
    EXPECT_NEAR(a.y[i], b.y[i], 1e-4) << i;
    EXPECT_NEAR(a.theta[i], b.theta[i], 1e-4) << i;
  }
}

TEST(FusionNodeJournal, ARespawnedFusionGoesOnWithItsGraph) {
  test::TempDir dir;
  // Undisturbed: the fused poses follow the odometry, not the drifting RBPF.
  const FusionRun calm = RunFusion("", 0, kSteps, true);
  ASSERT_EQ(calm.poses.size(), static_cast<size_t>(kSteps));
  EXPECT_LT(Distance(calm.poses.back(), TruePose(kSteps - 1)), 1e-3);
  EXPECT_GT(Distance(calm.poses.back(), RbpfPose(kSteps - 1)), 0.3);

  // Killed after 20 steps, then started again with the same journal: the first fused pose
  // after the respawn is where the undisturbed run was, not the RBPF's drifted pose, and the
  // final trajectory is the undisturbed one.
  const std::string journal = dir.file("fusion.journal");
  const FusionRun before = RunFusion(journal, 0, 20, false);
  EXPECT_EQ(before.poses.size(), 20u);
  ASSERT_TRUE(std::filesystem::exists(journal));
  const FusionRun after = RunFusion(journal, 20, kSteps, true);
  ASSERT_EQ(after.poses.size(), static_cast<size_t>(kSteps - 20));
  EXPECT_LT(Distance(after.poses.front(), TruePose(20)), 1e-3);
  EXPECT_LT(Distance(after.poses.back(), TruePose(kSteps - 1)), 1e-3);
  EXPECT_GE(after.poses.back().num_nodes, kSteps);
  ExpectSameFinalTrajectory(calm, after);

  // Without a journal the respawned fusion starts a new graph at the RBPF's pose.
  const FusionRun fresh = RunFusion("", 20, kSteps, true);
  ASSERT_FALSE(fresh.poses.empty());
  EXPECT_LT(Distance(fresh.poses.front(), RbpfPose(20)), 1e-6);
}

TEST(FusionNodeJournal, ADamagedTailIsDroppedAndTheRestIsUsed) {
  test::TempDir dir;
  const std::string journal = dir.file("fusion.journal");
  RunFusion(journal, 0, 20, false);
  // A kill in the middle of a write: half an event at the end.
  const auto size = std::filesystem::file_size(journal);
  { std::ofstream(journal, std::ios::app) << std::string("\xED\xA1\xDA\x01\x00\x00", 6); }
  const FusionRun after = RunFusion(journal, 20, kSteps, true);
  ASSERT_FALSE(after.poses.empty());
  EXPECT_LT(Distance(after.poses.front(), TruePose(20)), 1e-3);
  // The journal was rewritten from its whole events and then appended to.
  EXPECT_GT(std::filesystem::file_size(journal), size);
  LcmLogReader reader(journal);
  LcmLogEvent e;
  int events = 0;
  while (reader.Next(&e)) ++events;
  EXPECT_EQ(reader.ProblemSummary(), "");
  EXPECT_EQ(events, 2 * kSteps);  // ODOMETRY and RBPF_POSE per step
}

TEST(FusionNodeJournal, AnOldJournalOrAnotherRunsStartsANewGraph) {
  test::TempDir dir;
  const std::string journal = dir.file("fusion.journal");
  // Yesterday's journal (older than journal_max_age_s) is not replayed.
  RunFusion(journal, 0, 20, false);
  std::filesystem::last_write_time(
      journal, std::filesystem::file_time_type::clock::now() - std::chrono::hours(1));
  FusionRun after = RunFusion(journal, 20, kSteps, true);
  ASSERT_FALSE(after.poses.empty());
  EXPECT_LT(Distance(after.poses.front(), RbpfPose(20)), 1e-6);
  EXPECT_EQ(after.poses.front().num_nodes, 1);
  // A journal whose data lies ahead of the live data (another run in the same folder) is set
  // aside at the first live pose.
  RunFusion(journal, 0, kSteps, false, /*offset=*/100000000);
  after = RunFusion(journal, 0, 10, true);
  ASSERT_FALSE(after.poses.empty());
  EXPECT_LT(Distance(after.poses.front(), RbpfPose(0)), 1e-6);
  EXPECT_EQ(after.poses.front().num_nodes, 1);
  EXPECT_EQ(after.poses.back().num_nodes, 10);
  // Not a log at all: a new graph, and the file is replaced by a journal.
  std::ofstream(journal) << "garbage";
  after = RunFusion(journal, 20, kSteps, true);
  ASSERT_FALSE(after.poses.empty());
  EXPECT_EQ(after.poses.front().num_nodes, 1);
}

// The journal's events: channels in order.
std::vector<std::string> JournalChannels(const std::string& journal) {
  LcmLogReader reader(journal);
  LcmLogEvent e;
  std::vector<std::string> channels;
  while (reader.Next(&e)) channels.push_back(e.channel);
  EXPECT_EQ(reader.ProblemSummary(), "");
  return channels;
}

TEST(FusionNodeJournal, SnapshotsBoundTheJournalAndARespawnGoesOnFromOne) {
  test::TempDir dir;
  const FusionRun calm = RunFusion("", 0, kSteps, true);
  // A snapshot every 0.5 s of data (5 steps): the journal is the last snapshot and the inputs
  // since, however long the run.
  const std::string journal = dir.file("fusion.journal");
  RunFusion(journal, 0, 20, false, 0, 0.5);
  std::vector<std::string> channels = JournalChannels(journal);
  ASSERT_FALSE(channels.empty());
  EXPECT_EQ(channels.front(), FusionNode::kJournalSnapshotChannel);
  EXPECT_LE(channels.size(), 1u + 2 * 5);
  EXPECT_EQ(std::count(channels.begin(), channels.end(), FusionNode::kJournalSnapshotChannel), 1);
  const std::string long_run = dir.file("long.journal");
  RunFusion(long_run, 0, 400, false, 0, 0.5);
  EXPECT_LE(JournalChannels(long_run).size(), 1u + 2 * 5);

  // Killed after 20 steps, respawned: it goes on from the snapshot and the inputs after it,
  // and ends with the undisturbed trajectory.
  const FusionRun after = RunFusion(journal, 20, kSteps, true, 0, 0.5);
  ASSERT_EQ(after.poses.size(), static_cast<size_t>(kSteps - 20));
  EXPECT_LT(Distance(after.poses.front(), TruePose(20)), 1e-3);
  EXPECT_GE(after.poses.back().num_nodes, kSteps);
  ExpectSameFinalTrajectory(calm, after);
}

TEST(FusionNodeJournal, TheRetiredTrajectoryIsSpilledBesideTheJournalAndRestoredFromIt) {
  // A 10 s active window, 50 s of data, 20 retired poses kept in memory: the older ones go to
  // JOURNAL.retired. Killed at 40 s and respawned, the fusion adopts that file from its
  // snapshot and ends with the undisturbed whole trajectory.
  test::TempDir dir;
  FusionProcessConfig config;
  config.graph.active_window_s = 10.0;
  constexpr int kLong = 500;
  const FusionRun calm = RunFusion("", 0, kLong, true, 0, 120.0, config);
  const std::string journal = dir.file("fusion.journal");
  RunFusion(journal, 0, 400, false, 0, 2.0, config, /*retired_in_memory=*/20);
  const std::string retired = journal + ".retired";
  ASSERT_TRUE(std::filesystem::exists(retired));
  EXPECT_GE(std::filesystem::file_size(retired),
            RetiredSpillFile::kHeaderBytes + 100 * RetiredSpillFile::kRecordBytes);
  const FusionRun after = RunFusion(journal, 400, kLong, true, 0, 2.0, config, 20);
  ASSERT_EQ(after.poses.size(), static_cast<size_t>(kLong - 400));
  EXPECT_LT(Distance(after.poses.front(), TruePose(400)), 1e-3);
  ASSERT_EQ(calm.trajectories.back().num_poses, kLong);
  ExpectSameFinalTrajectory(calm, after);
}

TEST(FusionNodeJournal, ASnapshotOfAnotherConfigOrDamagedStartsANewGraph) {
  test::TempDir dir;
  const std::string journal = dir.file("fusion.journal");
  // Made with another configuration: its state is not this fusion's.
  FusionProcessConfig other;
  other.graph.window_size = 7;
  RunFusion(journal, 0, 20, false, 0, 0.5, other);
  FusionRun after = RunFusion(journal, 20, kSteps, true, 0, 0.5);
  ASSERT_FALSE(after.poses.empty());
  EXPECT_EQ(after.poses.front().num_nodes, 1);
  EXPECT_LT(Distance(after.poses.front(), RbpfPose(20)), 1e-6);
  // A damaged snapshot (its first byte): a new graph, not the inputs after it alone.
  std::filesystem::remove(journal);
  RunFusion(journal, 0, 20, false, 0, 0.5);
  {
    std::fstream f(journal, std::ios::in | std::ios::out | std::ios::binary);
    const std::string channel = FusionNode::kJournalSnapshotChannel;
    f.seekp(static_cast<std::streamoff>(28 + channel.size()));  // the event's data
    f.put('X');
  }
  after = RunFusion(journal, 20, kSteps, true, 0, 0.5);
  ASSERT_FALSE(after.poses.empty());
  EXPECT_EQ(after.poses.front().num_nodes, 1);
}

TEST(FusionNodeInput, ALaserOutageKeepsFusedPosesFromTheOdometry) {
  // RBPF_POSE silent over steps 10 to 17 (0.8 s; shorter than the RBPF_POSE clock-jump guard's
  // 1 s, as this test's data time runs faster than its wall time) while the odometry goes on:
  // 0.3 s into it (odometry_nodes_after_s, 1 s by default) the fusion publishes a fused pose per
  // odometry node, on the odometry's track; when the laser is back, laser nodes again, each
  // stamp published once.
  FusionProcessConfig config;
  config.graph.odometry_nodes_after_s = 0.3;
  LiveFusion f(config);
  auto silent = [](int k) { return k >= 10 && k < 18; };
  for (int k = 0; k < 30; ++k) {
    f.Send(channels::kOdometry, OdometryMessage(k));
    if (!silent(k)) f.Send(channels::kRbpfPose, RbpfPoseMessage(StepTime(k, 0), RbpfPose(k)));
    f.node->Poll();
  }
  const FusionNode& node = *f.node;
  std::set<Utime> stamps;
  std::vector<int> outage_steps;
  for (const auto& p : f.fused) {
    EXPECT_TRUE(stamps.insert(p.utime).second) << "stamp " << p.utime << " published twice";
    const int k = static_cast<int>((p.utime - StepTime(0, 0)) / 100000);
    if (silent(k)) {
      outage_steps.push_back(k);
      EXPECT_LT(Distance(p, TruePose(k)), 1e-3) << "step " << k;
    }
  }
  // Steps 10 to 12 when the outage is noticed at step 12 (the first two filled in), then 13 to
  // 17 as the odometry comes: every step has its fused pose, once.
  EXPECT_EQ(outage_steps, std::vector<int>({10, 11, 12, 13, 14, 15, 16, 17}));
  EXPECT_EQ(stamps.size(), 30u);
  EXPECT_EQ(node.fusion().counters().odometry_nodes, 8);
  EXPECT_EQ(node.fusion().num_nodes(), 30);
  EXPECT_TRUE(stamps.count(StepTime(29, 0)));  // the laser's again at the end
  EXPECT_FALSE(node.fusion().newest_node_from_odometry());
  EXPECT_EQ(node.fusion().counters().rejected_total(), 0);
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
  f.Send(channels::kRbpfPose, RbpfPoseMessage(INT64_MAX - 5, Pose2(0, 0, 0)));
  fusionloc::relative_pose_factor_t factor{};
  factor.utime_i = INT64_MIN;
  factor.utime_j = 1000000;
  factor.quat[0] = 1.0;
  for (int i = 0; i < 6; ++i) factor.information[7 * i] = 1.0;
  f.Send(channels::kVoFactors, factor);
  EXPECT_EQ(f.node->status().dropped(), 3);
  EXPECT_TRUE(f.fused.empty());
  f.Send(channels::kRbpfPose, RbpfPoseMessage(1050000, Pose2(1, 0, 0)));
  ASSERT_EQ(f.fused.size(), 1u);
  EXPECT_NEAR(f.fused[0].x, 1.0, 1e-9);
  EXPECT_EQ(f.node->status().dropped(), 3);
}

// An RBPF_POSE that the network delivers after newer ones gets its FUSED_POSE, at its own stamp
// (placed on the nearest node; no node added); a repeated one gets none.
TEST(FusionNodeInput, ALateLaserPoseGetsItsFusedPoseAtItsStamp) {
  LiveFusion f;
  for (int k = 0; k < 12; ++k) {
    if (k == 5) continue;  // delayed
    f.Send(channels::kOdometry, OdometryMessage(k));
    f.Send(channels::kRbpfPose, RbpfPoseMessage(StepTime(k, 0), RbpfPose(k)));
  }
  ASSERT_EQ(f.fused.size(), 11u);
  const int64_t dropped = f.node->status().dropped();
  f.Send(channels::kRbpfPose, RbpfPoseMessage(StepTime(5, 0), RbpfPose(5)));  // 0.6 s late
  ASSERT_EQ(f.fused.size(), 12u);
  const fusionloc::fused_pose_t& late = f.fused.back();
  EXPECT_EQ(late.utime, StepTime(5, 0));
  // On the fused node one step away, through the RBPF's motion over that step (whose drift,
  // 0.011 m per step, it keeps); not the RBPF's own pose, 5 steps of drift away.
  EXPECT_LT(Distance(late, TruePose(5)), 0.015);
  EXPECT_GT(Distance(late, RbpfPose(5)), 0.04);
  EXPECT_EQ(late.num_nodes, 11);
  EXPECT_EQ(f.node->status().dropped(), dropped);
  // Stamps sent again with other content (repeats the LCM layer does not see as identical): the
  // late one already placed and one with a node get no second fused pose.
  f.Send(channels::kRbpfPose, RbpfPoseMessage(StepTime(5, 0), RbpfPose(5) * Pose2(0.01, 0, 0)));
  f.Send(channels::kRbpfPose, RbpfPoseMessage(StepTime(7, 0), RbpfPose(7) * Pose2(0.01, 0, 0)));
  EXPECT_EQ(f.fused.size(), 12u);
  EXPECT_EQ(f.node->status().dropped(), dropped + 2);
}

// With a bounded graph, FUSED_TRAJECTORY carries the active window and trajectory_overlap_s of
// final poses before it; the last message is the whole trajectory. Merged in order (the
// consumers' rule, trajectory_merge.hpp), the periodic messages give every scan, and the final
// poses they carry are those of the whole trajectory at the end.
TEST(FusionNodeTrajectory, PeriodicMessagesCarryTheLatestPartAndTheLastOneAll) {
  constexpr int kLongSteps = 900;  // 90 s at 10 Hz
  FusionProcessConfig config;
  config.graph.active_window_s = 20.0;
  config.trajectory_overlap_s = 5.0;
  auto lcm = MakeLcm("memq://");
  std::vector<fusionloc::trajectory_t> messages;
  lcm->Subscribe<fusionloc::trajectory_t>(
      channels::kFusedTrajectory,
      [&](const fusionloc::trajectory_t& m, const std::string&) { messages.push_back(m); });
  FusionNodeOptions options;
  options.map_out = "";
  options.sync_full_solve = true;
  FusionNode node(config, options, lcm.get(), ChannelMap());
  for (int k = 0; k < kLongSteps; ++k) {
    lcm->Publish(channels::kOdometry, OdometryMessage(k), StepTime(k, 0));
    lcm->Publish(channels::kRbpfPose, RbpfPoseMessage(StepTime(k, 0), RbpfPose(k)), 0);
    while (lcm->HandleSubscriptions(0) > 0) {
    }
  }
  const size_t periodic = messages.size();
  node.Finish();
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  ASSERT_GT(periodic, 50u);
  ASSERT_EQ(messages.size(), periodic + 1);
  const fusionloc::trajectory_t& whole = messages.back();
  ASSERT_EQ(whole.num_poses, kLongSteps);
  EXPECT_EQ(whole.utimes.front(), StepTime(0, 0));

  struct P {
    Utime utime;
    double x, y, theta;
  };
  auto poses = [](const fusionloc::trajectory_t& m) {
    std::vector<P> v;
    for (int i = 0; i < m.num_poses; ++i) v.push_back({m.utimes[i], m.x[i], m.y[i], m.theta[i]});
    return v;
  };
  std::vector<P> merged;
  int partial = 0, largest = 0;
  for (size_t i = 0; i < periodic; ++i) {
    partial += messages[i].utimes.front() > StepTime(0, 0) ? 1 : 0;
    largest = std::max(largest, messages[i].num_poses);
    MergeTrajectoryTail(&merged, poses(messages[i]), [](const P& p) { return p.utime; });
  }
  EXPECT_GT(partial, 20) << "once nodes retire, the messages start after the first scan";
  // Bounded: window (20 s, retired in 10 s batches, at least max_window_nodes) + 5 s overlap.
  EXPECT_LE(largest, config.graph.max_window_nodes + 160) << "of " << kLongSteps;
  // Every scan up to the last periodic message, in order, none missing.
  ASSERT_EQ(merged.size(), static_cast<size_t>(kLongSteps));
  for (int k = 0; k < kLongSteps; ++k) ASSERT_EQ(merged[k].utime, StepTime(k, 0)) << k;
  // The first half was final long before the end: the same poses as the whole trajectory.
  for (int k = 0; k < kLongSteps / 2; ++k) {
    EXPECT_EQ(merged[k].x, whole.x[k]) << k;
    EXPECT_EQ(merged[k].y, whole.y[k]) << k;
    EXPECT_EQ(merged[k].theta, whole.theta[k]) << k;
  }
}

}  // namespace
}  // namespace fl::fusion
