// The peer's output conversion (tools/bench_laser/peers/mrpt_rbpf.hpp), without MRPT: the steps
// file, MRPT's path / pose / time logs, a pose for every scan from the most likely particle's
// path, and the run's ini.
#include "peers/mrpt_rbpf.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <string>

#include "test_paths.hpp"

namespace {

using fl::Pose2;
using fl::peers::MrptStep;
using fl::test::TempDir;

void Write(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

Pose2 PoseOf(const fl::eval::StampedPose& p) { return Pose2::FromIsometry3(p.T_world_base); }

void ExpectPose(const Pose2& a, const Pose2& b, const std::string& what) {
  EXPECT_NEAR(a.x, b.x, 1e-12) << what;
  EXPECT_NEAR(a.y, b.y, 1e-12) << what;
  EXPECT_NEAR(a.theta, b.theta, 1e-12) << what;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(MrptRbpf, StepsFileRoundTripsExactly) {
  TempDir dir;
  std::vector<MrptStep> steps(3);
  steps[0] = {1134864629895182, Pose2(), true};
  steps[1] = {1134864630105179, Pose2(0.1 / 3.0, -2.1763146840214631e-13, 0.7), false};
  steps[2] = {1134864630325184, Pose2(1e-300, 5.0, -3.1), true};
  fl::peers::WriteMrptSteps(steps, dir.file("a.steps"));
  const std::vector<MrptStep> back = fl::peers::ReadMrptSteps(dir.file("a.steps"));
  ASSERT_EQ(back.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(back[i].utime, steps[i].utime);
    EXPECT_EQ(back[i].filter, steps[i].filter);
    EXPECT_EQ(back[i].increment.x, steps[i].increment.x);
    EXPECT_EQ(back[i].increment.y, steps[i].increment.y);
    EXPECT_EQ(back[i].increment.theta, steps[i].increment.theta);
  }
}

TEST(MrptRbpf, BadStepsFilesNameTheLine) {
  TempDir dir;
  Write(dir.file("order.steps"), "# h\n0 10 1 0 0 0\n2 20 0 0 0 0\n");
  EXPECT_NE(ErrorOf([&] { fl::peers::ReadMrptSteps(dir.file("order.steps")); })
                .find("order.steps:3: step 2 where step 1 was expected"),
            std::string::npos);
  Write(dir.file("time.steps"), "0 10 1 0 0 0\n1 10 0 0 0 0\n");
  EXPECT_NE(ErrorOf([&] { fl::peers::ReadMrptSteps(dir.file("time.steps")); })
                .find("time.steps:2: time does not increase"),
            std::string::npos);
  Write(dir.file("flag.steps"), "0 10 2 0 0 0\n");
  EXPECT_NE(ErrorOf([&] { fl::peers::ReadMrptSteps(dir.file("flag.steps")); })
                .find("flag.steps:1: filter must be 0 or 1"),
            std::string::npos);
  Write(dir.file("short.steps"), "0 10 1 0 0\n");
  EXPECT_NE(ErrorOf([&] { fl::peers::ReadMrptSteps(dir.file("short.steps")); })
                .find("short.steps:1: expected index utime_us filter dx dy dtheta"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { fl::peers::ReadMrptSteps(dir.file("missing.steps")); })
                .find("cannot open"),
            std::string::npos);
}

// A pose for every scan: filter steps take the path's next pose, the steps between them the last
// path pose composed with the odometry since.
TEST(MrptRbpf, FinalTrajectoryHasAPoseForEveryScan) {
  const Pose2 a(0.1, 0.2, 0.3), b(1.0, 2.0, -0.5);
  const Pose2 u1(0.05, 0.01, 0.02), u2(0.07, -0.02, 0.1), u4(0.3, 0.0, -0.2);
  std::vector<MrptStep> steps = {{100, Pose2(), true},
                                 {200, u1, false},
                                 {300, u2, false},
                                 {400, Pose2(0.2, 0, 0), true},
                                 {500, u4, false}};
  const std::vector<Pose2> path = {Pose2(), a, b};  // the start, then one per filter step
  const fl::eval::Trajectory t = fl::peers::MrptFinalTrajectory(steps, path);
  ASSERT_EQ(t.size(), 5u);
  const fl::Utime times[] = {100, 200, 300, 400, 500};
  for (size_t i = 0; i < 5; ++i) EXPECT_EQ(t[i].utime, times[i]);
  ExpectPose(PoseOf(t[0]), a, "filter step 0: path pose 1");
  ExpectPose(PoseOf(t[1]), a * u1, "step 1: path pose 1 and one increment");
  ExpectPose(PoseOf(t[2]), a * u1 * u2, "step 2: path pose 1 and two increments");
  ExpectPose(PoseOf(t[3]), b, "filter step 3: path pose 2 (its own increment is in it)");
  ExpectPose(PoseOf(t[4]), b * u4, "step 4");
}

TEST(MrptRbpf, FinalTrajectoryRejectsAPathThatDoesNotMatchTheSteps) {
  std::vector<MrptStep> steps = {{100, Pose2(), true}, {200, Pose2(), true}};
  const std::string e = ErrorOf(
      [&] { fl::peers::MrptFinalTrajectory(steps, {Pose2(), Pose2(), Pose2(), Pose2()}); });
  EXPECT_NE(e.find("most likely path has 4 poses"), std::string::npos) << e;
  EXPECT_NE(e.find("2 particle-filter updates (expected 3 poses"), std::string::npos) << e;
  steps[0].filter = false;
  EXPECT_NE(ErrorOf([&] { fl::peers::MrptFinalTrajectory(steps, {Pose2(), Pose2()}); })
                .find("first rawlog step must be a particle-filter step"),
            std::string::npos);
}

// The three files rbpf-slam (MRPT 2.5.8) writes, in its own formats.
TEST(MrptRbpf, ReadsRbpfSlamsLogs) {
  TempDir dir;
  Write(dir.file("most_likely_path.txt"), "0.000 0.000 0.000\n-0.001 0.001 -0.001\n1.5 -2 3.1\n");
  Write(dir.file("log_estimated_path.txt"),
        "0 0.000091 -0.000754 0.000000 -0.000148 -0.000000 0.000000 1134864629.895182\n"
        "1 0.5 0.25 0.000000 1.25 -0.000000 0.000000 1134864630.105179\n");
  Write(dir.file("log_times.txt"),
        "% time_step  execution_time(ms)  map_size(#frames)  frame_inserted? \n"
        "%-------------------------------------------------------------------\n"
        "0 61.819489 1 1\n1 0.002 1 0\n2 80.5 2 1\n");
  const std::vector<Pose2> path = fl::peers::ReadMrptPath(dir.file("most_likely_path.txt"));
  ASSERT_EQ(path.size(), 3u);
  ExpectPose(path[2], Pose2(1.5, -2, 3.1), "path pose 2");
  const std::vector<Pose2> online = fl::peers::ReadMrptStepPoses(dir.file("log_estimated_path.txt"));
  ASSERT_EQ(online.size(), 2u);
  ExpectPose(online[1], Pose2(0.5, 0.25, 1.25), "x y and yaw (not z)");
  const std::vector<double> ms = fl::peers::ReadMrptStepTimes(dir.file("log_times.txt"));
  ASSERT_EQ(ms.size(), 3u);
  EXPECT_DOUBLE_EQ(ms[0], 61.819489);
  EXPECT_DOUBLE_EQ(ms[2], 80.5);

  // The online trajectory takes each step's time from the steps file; counts must agree.
  const std::vector<MrptStep> steps = {{7, Pose2(), true}, {9, Pose2(), false}};
  const fl::eval::Trajectory t = fl::peers::MrptOnlineTrajectory(steps, online);
  ASSERT_EQ(t.size(), 2u);
  EXPECT_EQ(t[1].utime, 9);
  EXPECT_NE(ErrorOf([&] { fl::peers::MrptOnlineTrajectory(steps, path); })
                .find("per-step pose log has 3 steps, the rawlog 2"),
            std::string::npos);

  Write(dir.file("bad_times.txt"), "% h\n0 1.0 1 1\n0 2.0 1 1\n");
  EXPECT_NE(ErrorOf([&] { fl::peers::ReadMrptStepTimes(dir.file("bad_times.txt")); })
                .find("bad_times.txt:3: step 0 where step 1 was expected"),
            std::string::npos);
  Write(dir.file("bad_path.txt"), "0 0 nan\n");
  EXPECT_NE(ErrorOf([&] { fl::peers::ReadMrptPath(dir.file("bad_path.txt")); })
                .find("bad_path.txt:1: 'nan' is not a finite number"),
            std::string::npos);
}

TEST(MrptRbpf, RunIniGetsTheOutputFolderAndRejectsWhatTheBenchSets) {
  const std::string ini =
      "# c\n[MappingApplication]\nsampleSize=30\n[Other]\nlogOutput_dir=elsewhere\n";
  const std::string out = fl::peers::MrptRunIni(ini, "/tmp/x/out");
  EXPECT_NE(out.find("[MappingApplication]\n# added by fl-bench-laser --peers:\n"
                     "logOutput_dir=/tmp/x/out\nsampleSize=30\n"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("[Other]\nlogOutput_dir=elsewhere\n"), std::string::npos) << out;
  EXPECT_NE(ErrorOf([] { fl::peers::MrptRunIni("[MappingApplication]\nlogOutput_dir = a\n", "b"); })
                .find("line 2: [MappingApplication] logOutput_dir is set by fl-bench-laser"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { fl::peers::MrptRunIni("[MappingApplication]\nrawlog_file=a\n", "b"); })
                .find("rawlog_file is set by fl-bench-laser"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { fl::peers::MrptRunIni("[Other]\nx=1\n", "b"); })
                .find("no [MappingApplication] section"),
            std::string::npos);
  // The repository's ini leaves both to the bench.
  const std::string repo = fl::test::ReadFile(fl::test::SourceDir() +
                                              "/config/peers/mrpt_rbpf_slam.ini");
  EXPECT_NO_THROW(fl::peers::MrptRunIni(repo, "/tmp/out"));
}

}  // namespace
