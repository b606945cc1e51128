// The demo end to end: fl-procman-sheriff --lone-ranger runs config/procman/sim.cfg's demo
// script with the real processes over live LCM (UDP multicast) for a short simulated drive;
// the recorded log must hold the fused output and every process must have ended cleanly.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "fusionloc/common/lcm_interface.hpp"
#include "test_paths.hpp"

namespace {

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

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
  EXPECT_GE(count["VO_FACTORS"], 8);  // 2 Hz stereo
  EXPECT_GE(count["FUSED_TRAJECTORY"], 1);
  EXPECT_GE(count["STATUS_FL_FUSION"], 1);
  // The fusion saved its 3D map when the deputy stopped it.
  EXPECT_TRUE(std::filesystem::exists(dir.file("map.pcd")));
}

}  // namespace
