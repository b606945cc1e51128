// fl-replay: byte-identical output for the same log and configuration, the whole pipeline on
// a simulator log, a laser-only log, recorded outputs replaced, and clear failures.
#include "replay.hpp"

#include <gtest/gtest.h>

#include <map>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/program.hpp"
#include "test_paths.hpp"

namespace {

using fl::test::BinDir;
using fl::test::RunCommand;
using fl::test::TempDir;

std::string SimLog(const TempDir& dir, const std::string& name, double duration_s) {
  const std::string log = dir.file(name);
  const auto r = RunCommand(BinDir() + "/fl-sim --log-level warn --duration " +
                                std::to_string(duration_s) + " --log " + log,
                            dir);
  EXPECT_EQ(r.status, 0) << r.err;
  return log;
}

std::map<std::string, int> Count(const std::string& path) {
  std::map<std::string, int> n;
  fl::LcmLogReader r(path);
  fl::LcmLogEvent ev;
  while (r.Next(&ev)) ++n[ev.channel];
  return n;
}

// Keeps only `channels` of a log.
void Filter(const std::string& in, const std::string& out, const std::set<std::string>& channels) {
  fl::LcmLogReader r(in);
  fl::LcmLogWriter w(out);
  fl::LcmLogEvent ev;
  while (r.Next(&ev)) {
    if (channels.count(ev.channel)) {
      w.Write(ev.channel, ev.data.data(), static_cast<int>(ev.data.size()), ev.utime);
    }
  }
  w.Close();
}

TEST(Replay, SameLogAndConfigGiveAByteIdenticalOutput) {
  TempDir dir;
  const std::string log = SimLog(dir, "sim.lcmlog", 12.0);
  const std::string config = fl::test::SourceDir() + "/config";
  const std::string cmd = BinDir() + "/fl-replay " + log + " --quiet --config-dir " + config;
  const auto a = RunCommand(cmd + " --out a.lcmlog", dir);
  ASSERT_EQ(a.status, 0) << a.err;
  const auto b = RunCommand(cmd + " --out b.lcmlog", dir);
  ASSERT_EQ(b.status, 0) << b.err;
  const auto cmp = RunCommand("cmp a.lcmlog b.lcmlog", dir);
  EXPECT_EQ(cmp.status, 0) << cmp.out;

  // The output holds the inputs and every stage's outputs.
  const auto in = Count(log), out = Count(dir.file("a.lcmlog"));
  for (const auto& [ch, n] : in) EXPECT_EQ(out.at(ch), n) << ch;
  EXPECT_EQ(out.at("RBPF_POSE"), in.at("LASER"));
  EXPECT_EQ(out.at("FUSED_POSE"), in.at("LASER"));
  EXPECT_GT(out.at("VO_POSE"), in.at("STEREO") / 2);
  for (const char* ch : {"RBPF_FACTORS", "VO_FACTORS", "FUSED_TRAJECTORY", "STATUS_FL_RBPF_SLAM",
                         "STATUS_FL_STEREO_VO", "STATUS_FL_FUSION"}) {
    EXPECT_GT(out.count(ch), 0u) << ch;
  }

  // Replaying that output again replaces its recorded outputs instead of doubling them.
  const auto c = RunCommand(
      BinDir() + "/fl-replay a.lcmlog --quiet --out c.lcmlog --config-dir " + config, dir);
  ASSERT_EQ(c.status, 0) << c.err;
  EXPECT_NE(c.err.find("recorded outputs replaced by this replay's: "), std::string::npos) << c.err;
  EXPECT_NE(c.err.find("FUSED_POSE (" + std::to_string(in.at("LASER")) + ")"), std::string::npos)
      << c.err;
  EXPECT_EQ(RunCommand("cmp a.lcmlog c.lcmlog", dir).status, 0);
}

// A robot without a camera: laser, odometry and the laser's mounting (LASER_TO_BASE) only.
TEST(Replay, ALaserOnlyLogRunsTheRbpfAndTheFusion) {
  TempDir dir;
  const std::string log = SimLog(dir, "sim.lcmlog", 8.0);
  Filter(log, dir.file("laser.lcmlog"), {"LASER", "ODOMETRY", "GROUND_TRUTH", "LASER_TO_BASE"});
  fl::replay::ReplayOptions o;
  o.in_path = dir.file("laser.lcmlog");
  o.out_path = dir.file("out.lcmlog");
  o.config_dir = fl::test::SourceDir() + "/config";
  testing::internal::CaptureStderr();
  const fl::replay::ReplayReport r = fl::replay::RunReplay(o);
  const std::string err = testing::internal::GetCapturedStderr();
  ASSERT_EQ(r.stages.size(), 3u);
  EXPECT_TRUE(r.stages[0].missing.empty());  // fl-rbpf-slam
  EXPECT_EQ(r.stages[1].missing,
            (std::vector<std::string>{"STEREO", "STEREO_CALIBRATION", "CAMERA_TO_BASE"}));
  EXPECT_TRUE(r.stages[2].missing.empty());  // fl-fusion, fed by the RBPF
  EXPECT_GT(r.data_s, 7.0);
  // The RBPF took the simulated robot's mounting (config/robot/sim.yaml: 0.15 m ahead).
  EXPECT_NE(err.find("T_base_laser from LASER_TO_BASE: x 0.15 y 0 yaw 0"), std::string::npos)
      << err;
  EXPECT_EQ(err.find("no LASER_TO_BASE before the first scan"), std::string::npos) << err;
  const auto out = Count(dir.file("out.lcmlog"));
  EXPECT_EQ(out.at("FUSED_POSE"), out.at("LASER"));
  EXPECT_EQ(out.count("VO_POSE"), 0u);

  // Without the mounting the laser is taken to be at the base origin, and the log says so.
  Filter(log, dir.file("bare.lcmlog"), {"LASER", "ODOMETRY", "GROUND_TRUTH"});
  o.in_path = dir.file("bare.lcmlog");
  o.out_path = dir.file("bare_out.lcmlog");
  testing::internal::CaptureStderr();
  fl::replay::RunReplay(o);
  const std::string bare = testing::internal::GetCapturedStderr();
  EXPECT_NE(bare.find("no LASER_TO_BASE before the first scan"), std::string::npos) << bare;
  EXPECT_EQ(Count(dir.file("bare_out.lcmlog")).at("FUSED_POSE"), out.at("LASER"));
}

TEST(Replay, ClearFailures) {
  TempDir dir;
  const std::string log = SimLog(dir, "sim.lcmlog", 2.0);
  Filter(log, dir.file("truth.lcmlog"), {"GROUND_TRUTH"});
  fl::replay::ReplayOptions o;
  o.in_path = dir.file("truth.lcmlog");
  testing::internal::CaptureStderr();
  try {
    fl::replay::RunReplay(o);
    ADD_FAILURE() << "a log without any stage's inputs must fail";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no stage had its inputs"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("GROUND_TRUTH ("), std::string::npos) << e.what();
  }
  o.in_path = log;
  o.stages = {"rbpf", "slam"};
  EXPECT_THROW(fl::replay::RunReplay(o), fl::UsageError);
  o.stages = {"rbpf"};
  o.config_dir = dir.path();  // no rbpf_slam.yaml there
  EXPECT_THROW(fl::replay::RunReplay(o), fl::ConfigError);
  testing::internal::GetCapturedStderr();
  const auto cli = RunCommand(BinDir() + "/fl-replay --quiet " + dir.file("none.lcmlog"),
                              dir);  // config found beside the binary
  EXPECT_EQ(cli.status, 1) << cli.err;
  EXPECT_NE(cli.err.find("cannot open LCM log"), std::string::npos) << cli.err;
}

}  // namespace
