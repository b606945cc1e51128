// The robot's launch with its three drivers against the device emulators, under one deputy
// (config/procman/emulated.cfg through fl-procman-sheriff --lone-ranger): the Hokuyo and the
// Kobuki on pseudo-terminals, the stereo camera as a folder of pairs. The robot stands still
// in front of a static scene, so the fused pose must come out and stay at the origin.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "sanitizer_slack.hpp"
#include "test_paths.hpp"

namespace {

using fl::test::ReadFile;

TEST(EmulatedRobot, ThreeDriversUnderOneDeputyGiveFusedPoses) {
  const std::string url = "udpm://239.255.76.67:" + std::to_string(7300 + getpid() % 200) +
                          "?ttl=0&recv_buf_size=16777216";
  try {
    fl::MakeLcm(url);
  } catch (const std::exception& e) {
    GTEST_SKIP() << "no UDP multicast on this machine (" << e.what() << ")";
  }
  const std::string bin = fl::test::BinDir();
  fl::test::TempDir dir;
  // The camera: 30 copies of one simulated stereo pair (a static scene), rectified.
  ASSERT_EQ(std::system((bin + "/fl-sim --log-level warn --snapshot " + dir.file("snap") +
                         " --snapshot-time 5")
                            .c_str()),
            0);
  namespace fs = std::filesystem;
  fs::create_directories(dir.file("stereo/left"));
  fs::create_directories(dir.file("stereo/right"));
  for (int i = 0; i < 30; ++i) {
    const std::string name = std::to_string(100000 + i).substr(1) + ".png";
    fs::copy_file(dir.file("snap_left.png"), dir.file("stereo/left/" + name));
    fs::copy_file(dir.file("snap_right.png"), dir.file("stereo/right/" + name));
  }
  std::ofstream(dir.file("rig.yaml"))
      << "width: 640\nheight: 480\nrectified: true\n"
         "left: {fx: 400, fy: 400, cx: 319.5, cy: 239.5}\n"
         "right: {fx: 400, fy: 400, cx: 319.5, cy: 239.5}\ntranslation: [-0.12, 0, 0]\n";
  const std::string run = dir.file("run");
  const std::string cmd =
      bin + "/fl-procman-sheriff --lone-ranger " + fl::test::SourceDir() +
      "/config/procman/emulated.cfg bringup --quit-after-script --status-period 0 --log-dir " +
      run + " --report " + dir.file("processes.txt") + " --lcm-url '" + url + "' --var BIN=" + bin +
      " --var CONFIG=" + fl::test::SourceDir() + "/config --var RUN_DIR=" + run +
      " --var STEREO_FOLDER=" + dir.file("stereo") +
      " --var STEREO_CALIBRATION=" + dir.file("rig.yaml") + " --var 'LCM_URL=" + url +
      "' < /dev/null > " + dir.file("sheriff.out") + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << ReadFile(dir.file("sheriff.out"));

  // Every process started once and ended cleanly.
  std::istringstream rows(ReadFile(dir.file("processes.txt")));
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
    EXPECT_EQ(last_exit, "0") << line;
    ++processes;
  }
  EXPECT_EQ(processes, 10) << ReadFile(dir.file("processes.txt"));

  // 8 s of driving the drivers: LASER at 10 Hz, ODOMETRY at 50 Hz, STEREO at 2 Hz.
  std::map<std::string, int> count;
  fl::LcmLogReader reader(run + "/run.lcmlog");
  fl::LcmLogEvent e;
  double max_offset_m = 0.0;
  while (reader.Next(&e)) {
    ++count[e.channel];
    if (e.channel != "FUSED_POSE") continue;
    fusionloc::fused_pose_t p;
    ASSERT_GT(p.decode(e.data.data(), 0, static_cast<int>(e.data.size())), 0);
    max_offset_m = std::max(max_offset_m, std::hypot(p.x, p.y));
  }
  EXPECT_GE(count["LASER"], 50);
  EXPECT_GE(count["ODOMETRY"], 250);
  EXPECT_GE(count["STEREO"], 8);
  EXPECT_GE(count["LASER_TO_BASE"], 5);
  // The first scans go by while the estimators and the fusion start; in a sanitizer build
  // (instrumented code, 2-15x slower) they start later, so twice the allowance.
  const int late = fl::test::SanitizerTimingSlack() > 1.0 ? 2 : 1;
  EXPECT_GE(count["RBPF_POSE"], count["LASER"] - 10 * late);
  EXPECT_GE(count["VO_POSE"], count["STEREO"] - 3 * late);
  EXPECT_GE(count["FUSED_POSE"], count["LASER"] - 15 * late);
  EXPECT_GE(count["STATUS_FL_URG_DRIVER"], 3);
  EXPECT_GE(count["STATUS_FL_BASE_DRIVER"], 3);
  EXPECT_GE(count["STATUS_FL_STEREO_DRIVER"], 3);
  // Standing still in a static scene: the fused pose stays at the start.
  EXPECT_LT(max_offset_m, 0.05);
}

}  // namespace
