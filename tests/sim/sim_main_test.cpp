// fl-sim program: help, errors, and writing a log.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "test_paths.hpp"

namespace {

// Runs a shell command, returns its exit status and combined output.
int RunCommand(const std::string& command, std::string* output) {
  output->clear();
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  if (p == nullptr) return -1;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) output->append(buf, n);
  const int status = pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

const std::string kSim = fl::test::BinDir() + "/fl-sim";

TEST(SimMainTest, HelpListsFlagsAndChannels) {
  std::string out;
  EXPECT_EQ(RunCommand(kSim + " --help", &out), 0);
  for (const char* s : {"--world", "--seed", "--duration", "--log", "--lcm-url", "--rate",
                        "--config", "LASER", "STEREO_CALIBRATION", "GROUND_TRUTH"}) {
    EXPECT_NE(out.find(s), std::string::npos) << s << " missing from:\n" << out;
  }
}

// Exit codes: 2 for a bad option value or options file (README "Exit codes").
TEST(SimMainTest, BadInputGivesClearErrors) {
  std::string out;
  EXPECT_EQ(RunCommand(kSim + " --world office --log /dev/null", &out), 2);
  EXPECT_NE(out.find("'paper' or 'corridor'"), std::string::npos) << out;
  EXPECT_EQ(RunCommand(kSim + " --duration -3 --seed -7 --log x", &out), 2);
  EXPECT_NE(out.find("seed"), std::string::npos) << out;
  EXPECT_EQ(RunCommand(kSim + " --config /nonexistent/sim.yaml", &out), 2);
  EXPECT_NE(out.find("/nonexistent/sim.yaml"), std::string::npos) << out;
  EXPECT_EQ(RunCommand(kSim + " --rate -1", &out), 2);
  EXPECT_NE(out.find("--rate"), std::string::npos) << out;
  EXPECT_EQ(RunCommand(kSim + " --camera-rate-hz -2 --log x", &out), 2);
  EXPECT_NE(out.find("--camera-rate-hz"), std::string::npos) << out;
  EXPECT_EQ(RunCommand(kSim + " --camera-rate-hz 3 --log x", &out), 2);  // 10 Hz steps / 3
  EXPECT_NE(out.find("rate"), std::string::npos) << out;
}

TEST(SimMainTest, WritesALogFromAConfigFile) {
  fl::test::TempDir dir;
  std::string out;
  const std::string log = dir.file("sim.lcmlog");
  ASSERT_EQ(RunCommand(kSim + " --config " + fl::test::SourceDir() +
                           "/config/sim_corridor.yaml --duration 0.5 --log " + log,
                       &out),
            0)
      << out;
  fl::LcmLogReader reader(log);
  fl::LcmLogEvent ev;
  int events = 0, stereo = 0;
  while (reader.Next(&ev)) ++events, stereo += ev.channel == "STEREO";
  // 6 steps x (truth, odometry, laser) + calibration + 6 pairs (10 Hz) + LASER_TO_BASE,
  // CAMERA_TO_BASE
  EXPECT_EQ(events, 6 * 3 + 1 + 6 + 2);
  EXPECT_EQ(stereo, 6);
  // The MSIF paper's 2 Hz camera: a pair every 5th step (steps 0 and 5).
  ASSERT_EQ(RunCommand(kSim + " --config " + fl::test::SourceDir() +
                           "/config/sim_corridor.yaml --duration 0.5 --camera-rate-hz 2 --log " +
                           dir.file("slow.lcmlog"),
                       &out),
            0)
      << out;
  fl::LcmLogReader slow(dir.file("slow.lcmlog"));
  stereo = 0;
  while (slow.Next(&ev)) stereo += ev.channel == "STEREO";
  EXPECT_EQ(stereo, 2);
}

// --channel renames in a log as it does live; a robot description moves the laser.
TEST(SimMainTest, RenamesChannelsAndTakesTheRobotDescriptionInALog) {
  fl::test::TempDir dir;
  std::string out;
  const std::string robot = dir.file("robot.yaml");
  std::ofstream(robot) << "name: moved\nlaser: {xyz_m: [0.25, 0.05, 0.2]}\n"
                          "camera: {xyz_m: [0.2, 0.06, 0.5], rpy_deg: [-90, 0, -90]}\n";
  const std::string log = dir.file("sim.lcmlog");
  ASSERT_EQ(RunCommand(kSim + " --duration 0.3 --channel LASER=FRONT_LASER --robot " + robot +
                           " --log " + log,
                       &out),
            0)
      << out;
  fl::LcmLogReader reader(log);
  fl::LcmLogEvent ev;
  int laser = 0, front = 0;
  bot_core::rigid_transform_t mount{};
  while (reader.Next(&ev)) {
    laser += ev.channel == "LASER";
    front += ev.channel == "FRONT_LASER";
    if (ev.channel == "LASER_TO_BASE") {
      ASSERT_GT(mount.decode(ev.data.data(), 0, static_cast<int>(ev.data.size())), 0);
    }
  }
  EXPECT_EQ(laser, 0);
  EXPECT_EQ(front, 4);
  EXPECT_EQ(mount.trans[0], 0.25);
  EXPECT_EQ(mount.trans[1], 0.05);
  EXPECT_EQ(mount.trans[2], 0.2);
  std::ofstream(robot) << "name: tilted\ncamera: {rpy_deg: [-90, 20, -90]}\n";
  EXPECT_EQ(RunCommand(kSim + " --duration 0.3 --robot " + robot + " --log " + log, &out), 2);
  EXPECT_NE(out.find("camera.rpy_deg must be [-90, 0, -90]"), std::string::npos) << out;
}

}  // namespace

namespace {

TEST(SimMainTest, PublishesLiveAsFastAsPossible) {
  std::string out;
  // memq:// keeps the messages inside the process: exercises the live loop and status reporting.
  EXPECT_EQ(RunCommand(kSim + " --lcm-url memq:// --rate 0 --duration 0.3", &out), 0) << out;
  EXPECT_NE(out.find("published 4 steps"), std::string::npos) << out;
}

}  // namespace
