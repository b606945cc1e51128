// Runs the fl-eval program on small files: help, a good run, and bad inputs.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "eval_fixtures.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/eval/trajectory.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "test_paths.hpp"

namespace fl::eval {
namespace {

struct Result {
  int exit_code = -1;
  std::string output;  // stdout and stderr
};

Result RunEval(const std::string& args) {
  const std::string cmd = fl::test::BinDir() + "/fl-eval " + args + " 2>&1";
  Result r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), pipe)) > 0) r.output.append(buf, n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

class EvalMain : public ::testing::Test {
 protected:
  void SetUp() override {
    ref_ = dir_.file("ref.tum");
    est_ = dir_.file("est.tum");
    Trajectory ref = fl::test::MakePlanarTrajectory(200, [](size_t i) {
      const double s = 0.05 * static_cast<double>(i);
      return Pose2(10 * std::sin(s), 6 * (1 - std::cos(s)), s);
    });
    Trajectory est = ref;
    for (size_t i = 0; i < est.size(); i += 2) est[i].T_world_base.translation().x() += 0.1;
    WriteTrajectoryTum(ref, ref_);
    WriteTrajectoryTum(est, est_);
  }
  fl::test::TempDir dir_;
  std::string ref_, est_;
};

TEST_F(EvalMain, Help) {
  const Result r = RunEval("--help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.output.find("--max-dt"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--kitti-lengths"), std::string::npos);
}

TEST_F(EvalMain, GoodRunPrintsTableAndWritesJsonAndPlots) {
  const Result r = RunEval(est_ + " " + ref_ + " --align none --json " + dir_.file("out.json") +
                           " --plot " + dir_.file("p"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("ATE translation [m]"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("0.0707"), std::string::npos) << r.output;  // 0.1 / sqrt(2)
  EXPECT_NE(r.output.find("KITTI segment drift"), std::string::npos);
  std::ifstream j(dir_.file("out.json"));
  const std::string json((std::istreambuf_iterator<char>(j)), std::istreambuf_iterator<char>());
  EXPECT_NE(json.find("\"ate\": {\"trans_m\": {\"rmse\": 0.070710678"), std::string::npos) << json;
  EXPECT_TRUE(std::filesystem::exists(dir_.file("p_traj.png")));
  EXPECT_TRUE(std::filesystem::exists(dir_.file("p_errors.png")));
}

TEST_F(EvalMain, MapBackgroundUnderTopView) {
  fusionloc::occupancy_grid_t g;
  g.utime = 1;
  g.resolution = 0.5;
  g.width = 40;
  g.height = 30;
  g.origin_x = -12;
  g.origin_y = -3;
  g.num_cells = g.width * g.height;
  g.cells.assign(static_cast<size_t>(g.num_cells), 0);
  {
    LcmLogWriter w(dir_.file("map.lcmlog"));
    w.Write("RBPF_MAP", g, 1);
    w.Close();
  }
  Result r = RunEval(est_ + " " + ref_ + " --plot " + dir_.file("m") + " --map-log " +
                     dir_.file("map.lcmlog"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir_.file("m_traj.png")));
  r = RunEval(est_ + " " + ref_ + " --plot " + dir_.file("m") + " --map-log " +
              dir_.file("map.lcmlog") + " --map-channel FUSED_MAP");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("map channel 'FUSED_MAP' not found"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("ATE translation"), std::string::npos) << "failed before any output";
}

TEST_F(EvalMain, RelationsWrittenFromReferenceAndEvaluated) {
  Result r = RunEval(ref_ + " " + ref_ + " --write-relations " + dir_.file("rel.txt"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunEval(est_ + " " + ref_ + " --relations " + dir_.file("rel.txt"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Every other pose is 0.1 m off in x: every relation touches one moved pose.
  EXPECT_NE(r.output.find("relations: 199 used, 0 skipped"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("relation translation [m]"), std::string::npos) << r.output;
}

TEST_F(EvalMain, BadInputsExitNonZeroWithReason) {
  std::ofstream(dir_.file("nan.txt")) << "0 0 0 0\n0.1 nan 0 0\n";
  Result r = RunEval(dir_.file("nan.txt") + " " + ref_);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("NaN"), std::string::npos) << r.output;

  Trajectory late = fl::test::MakeStraightTrajectory(20, 1.0, 500000000);
  WriteTrajectoryTum(late, dir_.file("late.tum"));
  r = RunEval(dir_.file("late.tum") + " " + ref_);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("no pair within 10 ms"), std::string::npos) << r.output;

  r = RunEval(est_ + " " + ref_ + " --format xyz");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("unknown trajectory format"), std::string::npos) << r.output;

  std::ofstream(dir_.file("empty.txt")) << "# no poses\n";
  r = RunEval(dir_.file("empty.txt") + " " + ref_);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("no poses"), std::string::npos) << r.output;

  r = RunEval(est_ + " " + ref_ + " --align affine");
  EXPECT_EQ(r.exit_code, 1);
  r = RunEval(est_);  // missing REF
  EXPECT_EQ(r.exit_code, 2);
}

}  // namespace
}  // namespace fl::eval
