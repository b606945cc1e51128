// fl-bench-sim end to end on a short run of the `paper` world: every estimate (RBPF alone, VO
// alone, fused) is reported beside the wheel odometry's own ATE (run <world>_odometry) and read
// against it (ate_over_odometry = its ATE over the odometry's); the error plot is written; the
// laser-aided runs (the simulator's 16-line laser) are read against the plain ones.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <utility>

#include "bench_json.hpp"
#include "test_paths.hpp"

namespace {

using fl::test::BenchMetric;
using fl::test::BinDir;
using fl::test::RunCommand;
using fl::test::SourceDir;
using fl::test::TempDir;

TEST(BenchSimMain, EveryEstimateIsReadAgainstTheWheelOdometry) {
  TempDir dir;
  const auto r = RunCommand(BinDir() + "/fl-bench-sim --worlds paper --duration 10 --config-dir " +
                                SourceDir() + "/config --json out.json --png-dir png",
                            dir);
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const std::string json = fl::test::ReadFile(dir.file("out.json"));
  const double odometry = BenchMetric(json, "paper_odometry", "ate_rmse_m");
  ASSERT_TRUE(std::isfinite(odometry) && odometry > 0) << json;
  EXPECT_GT(BenchMetric(json, "paper_odometry", "items"), 50) << json;
  EXPECT_TRUE(std::isnan(BenchMetric(json, "paper_odometry", "ate_over_odometry"))) << json;
  for (const std::string run : {"paper_rbpf_only", "paper_vo_only", "paper_fused"}) {
    const double ate = BenchMetric(json, run, "ate_rmse_m");
    ASSERT_TRUE(std::isfinite(ate)) << run << "\n" << json;
    EXPECT_NEAR(BenchMetric(json, run, "ate_over_odometry"), ate / odometry,
                1e-3 * ate / odometry + 1e-6)
        << run;
  }
  EXPECT_TRUE(std::filesystem::exists(dir.file("png/sim_paper_errors.png")));
  // The laser-aided runs: every stereo frame (10 Hz over 10 s) had its 16-line scan, and each
  // run is read against the plain one.
  EXPECT_EQ(BenchMetric(json, "paper_vo_only_lv", "laser_frames"), 101) << json;
  EXPECT_GT(BenchMetric(json, "paper_vo_only_lv", "laser_depth_features_mean"), 0) << json;
  for (const auto& [lv, plain] : {std::pair<std::string, std::string>{"paper_vo_only_lv",
                                                                      "paper_vo_only"},
                                  {"paper_fused_lv", "paper_fused"}}) {
    const double ate = BenchMetric(json, lv, "ate_rmse_m");
    const double plain_ate = BenchMetric(json, plain, "ate_rmse_m");
    ASSERT_TRUE(std::isfinite(ate)) << lv << "\n" << json;
    EXPECT_NEAR(BenchMetric(json, lv, "ate_over_plain"), ate / plain_ate,
                1e-3 * ate / plain_ate + 1e-6)
        << lv;
  }
}

// --camera-rate-hz overrides the worlds' camera rate and records a benchmark of its own; the VO
// row counts the frames it did not track.
TEST(BenchSimMain, CameraRateOverrideIsItsOwnBenchmark) {
  TempDir dir;
  const auto r = RunCommand(BinDir() + "/fl-bench-sim --worlds paper --duration 4 --config-dir " +
                                SourceDir() + "/config --camera-rate-hz 5 --json out.json " +
                                "--png-dir png",
                            dir);
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const std::string json = fl::test::ReadFile(dir.file("out.json"));
  EXPECT_NE(json.find("sim-camera-5hz"), std::string::npos) << json;
  // 4 s at 5 Hz: 21 frames (2 Hz would give 9), each with a VO pose.
  EXPECT_EQ(BenchMetric(json, "paper_vo_only", "items"), 21) << json;
  EXPECT_EQ(BenchMetric(json, "paper_vo_only", "lost_frames"), 0) << json;
  const auto bad = RunCommand(BinDir() + "/fl-bench-sim --worlds paper --camera-rate-hz -1",
                              dir);
  EXPECT_EQ(bad.status, 2);
  EXPECT_NE((bad.out + bad.err).find("--camera-rate-hz"), std::string::npos) << bad.err;
}

TEST(BenchSimMain, AMissingWorldIsAnErrorNamingItsFile) {
  TempDir dir;
  const auto r = RunCommand(BinDir() + "/fl-bench-sim --worlds nowhere --config-dir " +
                                SourceDir() + "/config --json out.json --png-dir png",
                            dir);
  EXPECT_NE(r.status, 0);
  EXPECT_NE((r.out + r.err).find("sim_nowhere.yaml"), std::string::npos) << r.out << r.err;
}

}  // namespace
