// The demo end to end: fl-procman-sheriff --lone-ranger runs config/procman/sim.cfg's demo
// script with the real processes over live LCM (UDP multicast) for a short simulated drive;
// the recorded log must hold the fused output and every process must have ended cleanly.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <regex>
#include <sstream>
#include <thread>

#include "fusionloc/common/lcm_interface.hpp"
#include "test_paths.hpp"

namespace {

using fl::test::ReadFile;

TEST(ProcmanSimDemo, RealProcessesOverLiveLcmProduceFusedPoses) {
  const std::string url = "udpm://239.255.76.67:" + std::to_string(7500 + getpid() % 200) +
                          "?ttl=0&recv_buf_size=16777216";
  try {
    fl::MakeLcm(url);
  } catch (const std::exception& e) {
    GTEST_SKIP() << "no UDP multicast on this machine (" << e.what() << ")";
  }
  fl::test::TempDir dir;
  const std::string bin = fl::test::BinDir();
  const std::string cmd = bin + "/fl-procman-sheriff --lone-ranger " + fl::test::SourceDir() +
                          "/config/procman/sim.cfg demo --quit-after-script --status-period 0 " +
                          "--log-dir " + dir.path() + " --report " + dir.file("processes.txt") +
                          " --lcm-url '" + url + "' --var BIN=" + bin +
                          " --var CONFIG=" + fl::test::SourceDir() +
                          "/config --var RUN_DIR=" + dir.path() +
                          " --var WORLD=paper --var RATE=2 --var DURATION=6 --var 'LCM_URL=" + url +
                          "' < /dev/null > " + dir.file("sheriff.out") + " 2>&1";
  const int rc = std::system(cmd.c_str());
  ASSERT_EQ(rc, 0) << ReadFile(dir.file("sheriff.out")) << ReadFile(dir.file("rbpf_slam.log"))
                   << ReadFile(dir.file("stereo_vo.log")) << ReadFile(dir.file("fusion.log"));
  const std::string table = ReadFile(dir.file("processes.txt"));
  EXPECT_NE(ReadFile(dir.file("sheriff.out")).find("script demo: done"), std::string::npos);
  // Every process ran once and exited 0 (the simulator at the end of its route, the others
  // on their SIGTERM: no SIGKILL, no restart).
  std::istringstream rows(table);
  std::string line;
  std::getline(rows, line);  // header
  int processes = 0;
  while (std::getline(rows, line)) {
    std::istringstream f(line);
    std::string name, host, last_exit;
    int starts = 0, restarts = 0;
    f >> name >> host >> starts >> restarts >> last_exit;
    if (name == "viewer") {  // optional: no script starts it
      EXPECT_EQ(starts, 0) << line;
      continue;
    }
    EXPECT_EQ(starts, 1) << line;
    EXPECT_EQ(restarts, 0) << line;
    EXPECT_EQ(last_exit, "0") << line;
    ++processes;
  }
  EXPECT_EQ(processes, 5) << table;

  std::map<std::string, int> count;
  fl::LcmLogReader reader(dir.file("run.lcmlog"));
  fl::LcmLogEvent e;
  while (reader.Next(&e)) ++count[e.channel];
  // 6 s at 10 Hz laser: nearly every scan gets an RBPF pose and a fused pose.
  EXPECT_GE(count["LASER"], 55);
  EXPECT_GE(count["RBPF_POSE"], count["LASER"] - 3);
  EXPECT_GE(count["FUSED_POSE"], count["LASER"] - 3);
  // 2 Hz stereo, a keyframe factor at least every 2 s (keyframe_max_interval_s), more in turns.
  EXPECT_GE(count["VO_FACTORS"], 3);
  EXPECT_GE(count["FUSED_TRAJECTORY"], 1);
  EXPECT_GE(count["STATUS_FL_FUSION"], 1);
  // The fusion saved its 3D map when the deputy stopped it.
  EXPECT_TRUE(std::filesystem::exists(dir.file("map.pcd")));
}

// The demo's command line for `dir`, `duration_s` of simulated drive at twice real time.
std::string DemoCommand(const fl::test::TempDir& dir, const std::string& url, int duration_s) {
  const std::string bin = fl::test::BinDir();
  return bin + "/fl-procman-sheriff --lone-ranger " + fl::test::SourceDir() +
         "/config/procman/sim.cfg demo --quit-after-script --status-period 0 --log-dir " +
         dir.path() + " --report " + dir.file("processes.txt") + " --lcm-url '" + url +
         "' --var BIN=" + bin + " --var CONFIG=" + fl::test::SourceDir() +
         "/config --var RUN_DIR=" + dir.path() +
         " --var WORLD=paper --var RATE=2 --var DURATION=" + std::to_string(duration_s) +
         " --var 'LCM_URL=" + url + "' < /dev/null > " + dir.file("sheriff.out") + " 2>&1";
}

// ATE [m] (rmse after SE(2) alignment) of FUSED_POSE against GROUND_TRUTH in a run's log.
double FusedAte(const fl::test::TempDir& dir) {
  const auto r = fl::test::RunCommand(
      fl::test::BinDir() + "/fl-eval run.lcmlog run.lcmlog --est-channel FUSED_POSE " +
          "--ref-channel GROUND_TRUTH --align se2 --kitti-lengths none --max-dt 0.02",
      dir);
  std::smatch m;
  const std::regex ate("ATE translation \\[m\\] +([0-9.]+)");
  if (r.status != 0 || !std::regex_search(r.out, m, ate)) {
    ADD_FAILURE() << "fl-eval: " << r.out << r.err;
    return 1e9;
  }
  return std::stod(m[1]);
}

// [s] of the day of a deputy log line "[I 01:48:15.620 ...] TEXT".
double LineTime(const std::string& log, const std::string& text) {
  const size_t at = log.find(text);
  if (at == std::string::npos) return -1.0;
  const size_t open = log.rfind("[I ", at);
  if (open == std::string::npos) return -1.0;
  int h = 0, mi = 0;
  double sec = 0;
  if (std::sscanf(log.c_str() + open + 3, "%d:%d:%lf", &h, &mi, &sec) != 3) return -1.0;
  return h * 3600.0 + mi * 60.0 + sec;
}

// kill -9 of each estimator and of the fusion in turn while the simulated robot drives
// (issue #23): the deputy starts each again within 2 s; the RBPF-SLAM waits for the mounting
// (LASER_TO_BASE, sent every second) and starts a new map, the VO a new keyframe chain, and the
// fusion replays its journal and goes on with its graph. The fused trajectory against ground
// truth stays within 1.5x of the same run undisturbed, and fused poses come out to the end.
TEST(ProcmanSimDemo, KillMinus9OfEachEstimatorAndOfTheFusionKeepsTheFusedAccuracy) {
  const std::string url = "udpm://239.255.76.67:" + std::to_string(7100 + getpid() % 200) +
                          "?ttl=0&recv_buf_size=16777216";
  try {
    fl::MakeLcm(url);
  } catch (const std::exception& e) {
    GTEST_SKIP() << "no UDP multicast on this machine (" << e.what() << ")";
  }
  constexpr int kDuration = 24;  // [s] simulated (12 s of wall time)
  fl::test::TempDir calm;
  ASSERT_EQ(std::system(DemoCommand(calm, url, kDuration).c_str()), 0)
      << ReadFile(calm.file("sheriff.out"));
  const double calm_ate = FusedAte(calm);

  fl::test::TempDir hit;
  const pid_t sheriff = fork();
  if (sheriff == 0) {
    execl("/bin/sh", "sh", "-c", DemoCommand(hit, url, kDuration).c_str(),
          static_cast<char*>(nullptr));
    _exit(127);
  }
  const std::regex sim("started sim \\(pid");
  std::string out;
  for (int i = 0; i < 400; ++i) {
    out = ReadFile(hit.file("sheriff.out"));
    if (std::regex_search(out, sim)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_TRUE(std::regex_search(out, sim)) << out;
  // 2, 4 and 6 s of wall time into the drive (4, 8, 12 s of data), one process each.
  const std::vector<std::string> victims = {"rbpf_slam", "stereo_vo", "fusion"};
  for (const std::string& name : victims) {
    std::this_thread::sleep_for(std::chrono::seconds(2));
    out = ReadFile(hit.file("sheriff.out"));
    std::smatch m;
    const std::regex started("started " + name + " \\(pid ([0-9]+)");
    ASSERT_TRUE(std::regex_search(out, m, started)) << out;
    ASSERT_EQ(kill(std::stoi(m[1]), SIGKILL), 0) << name;
  }
  int ws = 0;
  waitpid(sheriff, &ws, 0);
  out = ReadFile(hit.file("sheriff.out"));
  ASSERT_TRUE(WIFEXITED(ws) && WEXITSTATUS(ws) == 0) << out;
  const std::string table = ReadFile(hit.file("processes.txt"));
  for (const std::string& name : victims) {
    const std::string ended = name + " ended (killed by SIGKILL)";
    const double died = LineTime(out, ended);
    ASSERT_GT(died, 0) << out;
    const double again = LineTime(out.substr(out.find(ended)), "started " + name + " (pid");
    ASSERT_GT(again, 0) << out;
    EXPECT_LT(again - died, 2.0) << name << "\n" << out;  // the back-off starts at 10 ms
    // Started twice, restarted once, and the second run ended cleanly.
    EXPECT_TRUE(std::regex_search(table + "\n",
                                  std::regex("(^|\\n)([a-z_]+/)?" + name + " +localhost +2 +1 +0[ \\n]")))
        << table;
  }
  const double hit_ate = FusedAte(hit);
  std::cout << "fused ATE: undisturbed " << calm_ate << " m, estimators and fusion killed "
            << hit_ate << " m (" << hit_ate / calm_ate << "x)\n";
  // Issue 27's bound for lost data (bench faults: <= 2x the undisturbed run). Three kills cost
  // 1.09-1.25x when the undisturbed run was 0.05 m; since the RBPF publishes its noisy-scan
  // factors it is 0.036 m, and on a loaded machine (the whole suite on two cores) the same kills
  // cost up to 1.76x (0.063 m).
  EXPECT_LE(hit_ate, 2.0 * calm_ate) << ReadFile(hit.file("fusion.log"));
  const std::string fusion_log = ReadFile(hit.file("fusion.log"));
  EXPECT_NE(fusion_log.find("restored from the journal"), std::string::npos) << fusion_log;
  const std::string rbpf_log = ReadFile(hit.file("rbpf_slam.log"));
  EXPECT_EQ(rbpf_log.find("identity"), std::string::npos)
      << "the respawned RBPF-SLAM did not wait for LASER_TO_BASE:\n" << rbpf_log;
  // Fused poses went on to the end of the drive, and the final trajectory was published.
  std::map<std::string, int> count;
  fl::LcmLogReader reader(hit.file("run.lcmlog"));
  fl::LcmLogEvent e;
  while (reader.Next(&e)) ++count[e.channel];
  EXPECT_GE(count["FUSED_POSE"], count["LASER"] - 40);  // about 1 s of scans missed per kill
  EXPECT_GE(count["FUSED_TRAJECTORY"], 1);
}

}  // namespace
