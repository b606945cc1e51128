// The demo launch file end to end: fl-procman runs the real processes over live LCM (UDP
// multicast) for a short simulated drive; the recorded log must hold the fused output and
// every process must have ended cleanly.
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
  const std::string cmd = bin + "/fl-procman " + fl::test::SourceDir() +
                          "/config/launch/sim_demo.yaml --status-period 0 --log-dir " +
                          dir.path() + " --report " + dir.file("processes.txt") +
                          " --vars 'BIN=" + bin + ",CONFIG=" + fl::test::SourceDir() +
                          "/config,WORLD=paper,RATE=2,DURATION=6,LCM_URL=" + url + "' > " +
                          dir.file("procman.out") + " 2>&1";
  const int rc = std::system(cmd.c_str());
  ASSERT_EQ(rc, 0) << ReadFile(dir.file("procman.out")) << ReadFile(dir.file("rbpf_slam.log"))
                   << ReadFile(dir.file("stereo_vo.log")) << ReadFile(dir.file("fusion.log"));
  const std::string table = ReadFile(dir.file("processes.txt"));
  EXPECT_NE(table.find("run ended: sim ended (exit code 0)"), std::string::npos) << table;
  // Everyone but the simulator was stopped by SIGTERM and exited 0 (no SIGKILL, no restart).
  EXPECT_EQ(table.find("SIGKILL"), std::string::npos) << table;
  EXPECT_EQ(table.find("failed"), std::string::npos) << table;

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
  // The fusion saved its 3D map when procman stopped it.
  EXPECT_TRUE(std::filesystem::exists(dir.file("map.pcd")));
}

}  // namespace
