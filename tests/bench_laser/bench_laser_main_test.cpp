// fl-bench-laser end to end on a tiny synthetic CARMEN log: a log with a NAME.relations file
// beside it gets the Kuemmerle relation columns (final trajectory and online pose) on each run
// and on the mean row; one without gets none. --peers with stand-ins for MRPT's programs: the
// peer is scored by the same code, its table recorded in its own section.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "bench_json.hpp"
#include "fusionloc/common/geometry.hpp"
#include "importer_fixtures.hpp"
#include "test_paths.hpp"

namespace {

using fl::test::BinDir;
using fl::test::ReadFile;
using fl::test::RunCommand;
using fl::test::TempDir;

double Metric(const std::string& json, const std::string& run, const std::string& key) {
  return fl::test::BenchMetric(json, run, key);
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

// --sim-duration-s: the world simulated that long (its route looped), --only selecting the world
// by its run name; the table goes to its own section and the full laser one stays as it was.
TEST(BenchLaserMain, ALongSimulatedRunIsRecordedInItsOwnSection) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("laser"));
  fl::test::WriteText(dir.file("laser/arc-corrected.log"), fl::test::CarmenArcLog(20));
  const std::string laser_section =
      "<!-- bench:laser:begin -->\nthe full run's table\n<!-- bench:laser:end -->\n";
  fl::test::WriteText(dir.file("bench.md"), "# Benchmarks\n\n" + laser_section);
  const std::string common = BinDir() + "/fl-bench-laser --data " + dir.path() +
                             " --config-dir " + fl::test::SourceDir() +
                             "/config --json out.json --png-dir png --refit=false";
  const auto r = RunCommand(common + " --only sim-paper --sim-worlds paper --sim-duration-s 130"
                                     " --seeds 1 --record bench.md",
                            dir);
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const std::string json = ReadFile(dir.file("out.json"));
  // 130 s at the laser's 10 Hz (the world's own duration is 100 s); the log left out.
  EXPECT_EQ(Metric(json, "sim-paper", "items"), 1301) << json;
  EXPECT_TRUE(std::isnan(Metric(json, "arc-corrected", "items"))) << json;
  const std::string md = ReadFile(dir.file("bench.md"));
  EXPECT_NE(md.find(laser_section), std::string::npos) << md;
  EXPECT_NE(md.find("<!-- bench:laser-long:begin -->"), std::string::npos) << md;
  EXPECT_NE(md.find("| sim-paper |"), std::string::npos) << md;

  // Bad values and a duration with no world to apply it to are usage errors.
  const auto negative = RunCommand(common + " --sim-duration-s -5", dir);
  EXPECT_EQ(negative.status, 2) << negative.err;
  EXPECT_NE(negative.err.find("--sim-duration-s -5"), std::string::npos) << negative.err;
  const auto too_long = RunCommand(common + " --sim-duration-s 100000", dir);
  EXPECT_EQ(too_long.status, 2) << too_long.err;
  EXPECT_NE(too_long.err.find("held in memory"), std::string::npos) << too_long.err;
  const auto no_world = RunCommand(common + " --sim-duration-s 60 --sim-worlds=", dir);
  EXPECT_EQ(no_world.status, 2) << no_world.err;
  EXPECT_NE(no_world.err.find("none is selected"), std::string::npos) << no_world.err;
}

// The poses of fl::test::CarmenArcLog's scans (its defaults).
std::vector<fl::Pose2> ArcPoses(int scans) {
  std::vector<fl::Pose2> out;
  double x = 0, y = 0, th = 0;
  for (int k = 0; k < scans; ++k) {
    out.emplace_back(x, y, th);
    x += 0.1 * std::cos(th);
    y += 0.1 * std::sin(th);
    th += 0.02;
  }
  return out;
}

void WriteGz(const std::string& path, const std::string& text) {
  gzFile f = gzopen(path.c_str(), "wb");
  ASSERT_NE(f, nullptr) << path;
  ASSERT_EQ(gzwrite(f, text.data(), static_cast<unsigned>(text.size())),
            static_cast<int>(text.size()));
  gzclose(f);
}

std::string Num(double v) {
  char b[40];
  std::snprintf(b, sizeof(b), "%.17g", v);
  return b;
}

// --peers with stand-ins for fl-mrpt-rawlog and rbpf-slam (scripts that copy what the test
// prepared in MRPT's formats): the stand-in peer's path is the reference itself, so the same
// scoring must give it zero relation error; every other scan is a step without a filter update
// (its pose comes from the odometry increments). With --peers --only the laser section of the
// record is left alone and the peers' table gets its own.
TEST(BenchLaserMain, PeersRunBesideOursAndAreScoredByTheSameCode) {
  TempDir dir;
  namespace fs = std::filesystem;
  fs::create_directories(dir.file("laser"));
  fs::create_directories(dir.file("mrpt_out"));
  const int n = 40;
  const std::string log = fl::test::CarmenArcLog(n);
  fl::test::WriteText(dir.file("laser/mit-csail.clf"), log);  // the raw log
  WriteGz(dir.file("laser/csail-corrected.log.gz"), log);     // its reference: the same poses
  const std::vector<fl::Pose2> pose = ArcPoses(n);
  std::string relations = "# t1 t2 x y z roll pitch yaw\n";
  int relation_count = 0;
  for (int k = 0; k + 5 < n; k += 3, ++relation_count) {
    const fl::Pose2 d = pose[k].between(pose[k + 5]);
    relations += Num(100.0 + 0.1 * k) + " " + Num(100.0 + 0.1 * (k + 5)) + " " + Num(d.x) + " " +
                 Num(d.y) + " 0 0 0 " + Num(d.theta) + "\n";
  }
  fl::test::WriteText(dir.file("laser/mit-csail.relations"), relations);
  // What MRPT would write: steps (filter on even steps), the most likely path (the start and
  // the filter steps' poses), the per-step mean pose and per-step times of 5 ms.
  std::string steps = "# steps\n", path = "0 0 0\n", online, times = "% time_step ms\n%---\n";
  for (int k = 0; k < n; ++k) {
    const fl::Pose2 inc = k == 0 ? fl::Pose2() : pose[k - 1].between(pose[k]);
    const bool filter = k % 2 == 0;
    steps += std::to_string(k) + " " + std::to_string(100000000 + 100000 * k) + " " +
             (filter ? "1 " : "0 ") + Num(inc.x) + " " + Num(inc.y) + " " + Num(inc.theta) + "\n";
    if (filter) path += Num(pose[k].x) + " " + Num(pose[k].y) + " " + Num(pose[k].theta) + "\n";
    online += std::to_string(k) + " " + Num(pose[k].x) + " " + Num(pose[k].y) + " 0 " +
              Num(pose[k].theta) + " 0 0 " + Num(100.0 + 0.1 * k) + "\n";
    times += std::to_string(k) + " 5.0 1 " + (filter ? "1" : "0") + "\n";
  }
  fl::test::WriteText(dir.file("prepared.steps"), steps);
  fl::test::WriteText(dir.file("mrpt_out/most_likely_path.txt"), path);
  fl::test::WriteText(dir.file("mrpt_out/log_estimated_path.txt"), online);
  fl::test::WriteText(dir.file("mrpt_out/log_times.txt"), times);
  fl::test::WriteText(dir.file("fake-rawlog.sh"),
                      "#!/bin/sh\nwhile [ $# -gt 0 ]; do case \"$1\" in\n"
                      "  --rawlog) r=\"$2\"; shift 2 ;; --steps) s=\"$2\"; shift 2 ;;\n"
                      "  --ini) shift 2 ;; *) shift ;; esac; done\n"
                      "cp " + dir.file("prepared.steps") + " \"$s\" && : > \"$r\"\n");
  fl::test::WriteText(dir.file("fake-rbpf-slam.sh"),
                      "#!/bin/sh\nout=$(sed -n 's/^logOutput_dir=//p' \"$1\")\n"
                      "[ -f \"$2\" ] || exit 3\n"
                      "mkdir -p \"$out\" && cp " + dir.file("mrpt_out") + "/* \"$out\"/\n");
  fs::permissions(dir.file("fake-rawlog.sh"), fs::perms::owner_all);
  fs::permissions(dir.file("fake-rbpf-slam.sh"), fs::perms::owner_all);
  fl::test::WriteText(dir.file("rec.md"),
                      "# B\n<!-- bench:laser:begin -->\nTHE FULL TABLE\n<!-- bench:laser:end -->\n");
  const std::string ini = fl::test::SourceDir() + "/config/peers/mrpt_rbpf_slam.ini";
  const auto r = RunCommand(
      BinDir() + "/fl-bench-laser --data " + dir.path() +
          " --seeds 1 --only mit-csail --json out.json --record rec.md --png-dir png "
          "--refit=false --sim-worlds= --peers --peers-config " + ini +
          " --peers-rawlog-tool " + dir.file("fake-rawlog.sh") + " --peers-rbpf-slam " +
          dir.file("fake-rbpf-slam.sh"),
      dir);
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const std::string json = ReadFile(dir.file("out-peers.json"));
  const std::string peer = "mit-csail-raw/mrpt-rbpf";
  EXPECT_EQ(Metric(json, peer, "relations_used"), relation_count) << json;
  EXPECT_LT(Metric(json, peer, "relation_trans_mean_m"), 1e-9) << json;
  EXPECT_LT(Metric(json, peer, "relation_rot_mean_deg"), 1e-6) << json;
  EXPECT_LT(Metric(json, peer, "online_relation_trans_mean_m"), 1e-9) << json;
  EXPECT_LT(Metric(json, peer, "ate_rmse_m"), 1e-9) << json;
  EXPECT_EQ(Metric(json, peer, "ms_per_item_mean"), 5.0) << json;
  EXPECT_EQ(Metric(json, peer, "items"), n);
  EXPECT_EQ(Metric(json, peer, "processed"), n / 2);
  EXPECT_GT(Metric(json, peer, "peak_rss_mb"), 0.0);
  // Ours beside it, from the same run, and peer over ours.
  const double ours_ms = Metric(json, "mit-csail-raw", "ms_per_item_mean");
  const double ours_rel = Metric(json, "mit-csail-raw", "relation_trans_mean_m");
  ASSERT_GT(ours_ms, 0.0) << json;
  EXPECT_EQ(Metric(json, "mit-csail-raw", "relations_used"), relation_count);
  EXPECT_NEAR(Metric(json, "mit-csail-raw mrpt-rbpf/ours", "ms_per_item_mean"), 5.0 / ours_ms,
              1e-6 * 5.0 / ours_ms)
      << json;
  if (ours_rel > 0) {
    EXPECT_LT(Metric(json, "mit-csail-raw mrpt-rbpf/ours", "relation_trans_mean_m"), 1e-6);
  }
  // The laser section is the full run's; the peers' table is recorded in its own section.
  const std::string md = ReadFile(dir.file("rec.md"));
  EXPECT_NE(md.find("THE FULL TABLE"), std::string::npos) << md;
  EXPECT_NE(md.find("<!-- bench:laser-peers:begin -->"), std::string::npos) << md;
  EXPECT_NE(md.find("| mit-csail-raw/mrpt-rbpf |"), std::string::npos) << md;
  EXPECT_NE(r.err.find("--only mit-csail: not recording the laser section"),
            std::string::npos)
      << r.err;
}

TEST(BenchLaserMain, PeersWithoutTheRawlogToolIsAUsageErrorSayingHowToGetIt) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("laser"));
  fl::test::WriteText(dir.file("laser/arc-corrected.log"), fl::test::CarmenArcLog(20));
  const std::string ini = fl::test::SourceDir() + "/config/peers/mrpt_rbpf_slam.ini";
  auto r = RunCommand(BinDir() + "/fl-bench-laser --data " + dir.path() +
                          " --seeds 1 --sim-worlds= --peers --peers-config " + ini +
                          " --peers-rawlog-tool " + dir.file("no-such-tool"),
                      dir);
  EXPECT_EQ(r.status, 2) << r.out << r.err;
  EXPECT_NE(r.err.find("built only when CMake finds MRPT; `./fusionloc bench laser --peers` "
                       "installs libmrpt-obs-dev and mrpt-apps"),
            std::string::npos)
      << r.err;
  r = RunCommand(BinDir() + "/fl-bench-laser --data " + dir.path() +
                     " --seeds 1 --sim-worlds= --peers --peers-config " + dir.file("none.ini"),
                 dir);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_NE(r.err.find("--peers-config " + dir.file("none.ini") + " not found"),
            std::string::npos)
      << r.err;
}

}  // namespace
