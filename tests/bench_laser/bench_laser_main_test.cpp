// fl-bench-laser end to end on a tiny synthetic CARMEN log: a log with a NAME.relations file
// beside it gets the Kuemmerle relation columns (final trajectory and online pose) on each run
// and on the mean row; one without gets none.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <regex>
#include <string>

#include "importer_fixtures.hpp"
#include "test_paths.hpp"

namespace {

using fl::test::BinDir;
using fl::test::ReadFile;
using fl::test::RunCommand;
using fl::test::TempDir;

// The value of `key` in the metrics of the run named `run` in a bench JSON (NaN if absent).
double Metric(const std::string& json, const std::string& run, const std::string& key) {
  const size_t at = json.find("{\"name\": \"" + run + "\"");
  if (at == std::string::npos) return std::nan("");
  const size_t end = json.find("\n", at);
  const std::string row = json.substr(at, end - at);
  std::smatch m;
  if (!std::regex_search(row, m, std::regex("\"" + key + "\": ([-0-9.e+]+)"))) return std::nan("");
  return std::stod(m[1]);
}

TEST(BenchLaserMain, RelationsBesideALogAreScoredOnEveryRunAndTheMean) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("laser"));
  fl::test::WriteText(dir.file("laser/arc-corrected.log"), fl::test::CarmenArcLog(60));
  fl::test::WriteText(dir.file("laser/other-corrected.log"), fl::test::CarmenArcLog(40));
  // Four relations on scans (t = 100.0 + 0.1 k) and one whose time falls on none.
  fl::test::WriteText(dir.file("laser/arc-corrected.relations"),
                      "# t1 t2 x y z roll pitch yaw\n"
                      "100.0 100.5 0.5 0 0 0 0 0.1\n"
                      "101.0 101.5 0.5 0 0 0 0 0.1\n"
                      "102.0 102.5 0.5 0 0 0 0 0.1\n"
                      "103.0 104.0 1.0 0 0 0 0 0.2\n"
                      "103.0 250.0 1.0 0 0 0 0 0.2\n");
  const auto r = RunCommand(BinDir() + "/fl-bench-laser --data " + dir.path() +
                                " --seeds 1,2 --json out.json --png-dir png --refit=false --sim-worlds=",
                            dir);
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const std::string json = ReadFile(dir.file("out.json"));
  for (const std::string run : {"arc-corrected/s1", "arc-corrected/s2", "arc-corrected mean"}) {
    EXPECT_EQ(Metric(json, run, "relations_total"), 5) << run << "\n" << json;
    EXPECT_EQ(Metric(json, run, "relations_used"), 4) << run;
    for (const char* key : {"relation_trans_mean_m", "relation_trans_std_m",
                            "relation_rot_mean_deg", "relation_rot_std_deg",
                            "online_relation_trans_mean_m", "online_relation_rot_mean_deg"}) {
      const double v = Metric(json, run, key);
      EXPECT_TRUE(std::isfinite(v) && v >= 0) << run << " " << key << " = " << v;
    }
  }
  // No relations file: no relation columns.
  EXPECT_TRUE(std::isnan(Metric(json, "other-corrected/s1", "relations_used"))) << json;
  EXPECT_TRUE(std::isfinite(Metric(json, "other-corrected/s1", "ate_rmse_m"))) << json;
  // The odometry the SLAM started from, scored the same way, on every run.
  for (const std::string run : {"arc-corrected/s1", "other-corrected/s2", "other-corrected mean"}) {
    const double odo = Metric(json, run, "odometry_ate_rmse_m");
    EXPECT_TRUE(std::isfinite(odo) && odo > 0) << run << " " << odo;
    if (run.find("mean") != std::string::npos) continue;  // a mean of ratios, not a ratio
    EXPECT_NEAR(Metric(json, run, "ate_over_odometry"), Metric(json, run, "ate_rmse_m") / odo,
                1e-3 * Metric(json, run, "ate_over_odometry") + 1e-6)
        << run;
  }
}

TEST(BenchLaserMain, AMissingSimulatedWorldIsAUsageErrorNamingTheFile) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("laser"));
  fl::test::WriteText(dir.file("laser/arc-corrected.log"), fl::test::CarmenArcLog(20));
  const auto r = RunCommand(BinDir() + "/fl-bench-laser --data " + dir.path() +
                                " --seeds 1 --json out.json --png-dir png --refit=false",
                            dir);
  EXPECT_EQ(r.status, 2) << r.out << r.err;
  EXPECT_NE(r.err.find("config/sim_paper.yaml not found"), std::string::npos) << r.err;
}

}  // namespace
