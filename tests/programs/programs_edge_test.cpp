// Every fl-* program stands on the same edge (fusionloc/common/program.hpp): --help and
// --print-config exit 0, a bad option exits 2; the LCM processes follow one exit-code policy on
// a bad config, a missing file and a garbage log; what they publish in log mode carries data
// time; a live process says when an input it needs is silent.
#include <gtest/gtest.h>
#include <signal.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <set>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/status_t.hpp"
#include "test_paths.hpp"

namespace {

namespace fs = std::filesystem;
using fl::test::BinDir;
using fl::test::RunCommand;
using fl::test::TempDir;

std::vector<std::string> Programs() {
  std::vector<std::string> out;
  if (!fs::exists(BinDir())) return out;
  for (const auto& e : fs::directory_iterator(BinDir())) {
    const std::string name = e.path().filename().string();
    if (name.rfind("fl-", 0) == 0) out.push_back(name);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(ProgramsEdge, EveryProgramAnswersHelpPrintConfigAndRejectsABadOption) {
  TempDir dir;
  const std::vector<std::string> programs = Programs();
  ASSERT_GE(programs.size(), 11u) << "build the programs first (" << BinDir() << ")";
  // Programs that must be there (a program missing from the build is not silently skipped).
  for (const char* p : {"fl-urg-driver", "fl-urg-emulator"}) {
    EXPECT_NE(std::find(programs.begin(), programs.end(), p), programs.end()) << p << " not built";
  }
  for (const auto& p : programs) {
    const std::string bin = BinDir() + "/" + p;
    const auto help = RunCommand(bin + " --help", dir);
    EXPECT_EQ(help.status, 0) << p << ": " << help.err;
    EXPECT_NE(help.out.find("Usage: " + p), std::string::npos) << p;
    EXPECT_NE(help.out.find("--print-config"), std::string::npos) << p;
    EXPECT_NE(help.out.find("--log-level"), std::string::npos) << p;
    const auto config = RunCommand(bin + " --print-config", dir);
    EXPECT_EQ(config.status, 0) << p << ": " << config.err;
    EXPECT_FALSE(config.out.empty()) << p;
    // 0.2 prints as 0.2, not 0.20000000000000001 (or 0.19999999999999998).
    EXPECT_FALSE(std::regex_search(config.out, std::regex("[0-9]\\.[0-9]*(0{7,}|9{7,})[1-9]")))
        << p << " prints a float with 17 digits:\n"
        << config.out;
    const auto bad = RunCommand(bin + " --no-such-option", dir);
    EXPECT_EQ(bad.status, 2) << p << ": " << bad.err;
    EXPECT_NE(bad.err.find("unknown option '--no-such-option'"), std::string::npos) << p;
  }
}

const char* kProcesses[] = {"fl-rbpf-slam", "fl-stereo-vo", "fl-fusion"};

TEST(ProgramsEdge, LcmProcessesShareOneExitCodePolicy) {
  TempDir dir;
  {
    std::ofstream bad(dir.file("bad.yaml"));
    bad << "no_such_key: 1\n";
    std::ofstream garbage(dir.file("garbage.lcmlog"), std::ios::binary);
    for (int64_t i = 0; i < 300000; ++i) garbage.put(static_cast<char>((i * 7919) % 251));
  }
  for (const char* p : kProcesses) {
    const std::string bin = BinDir() + "/" + p;
    const auto cfg = RunCommand(bin + " --config bad.yaml", dir);
    EXPECT_EQ(cfg.status, 2) << p << ": " << cfg.err;
    EXPECT_NE(cfg.err.find("bad.yaml:1:1: unknown key 'no_such_key'"), std::string::npos)
        << p << ": " << cfg.err;
    const auto missing = RunCommand(bin + " --lcm-url log:missing.lcmlog", dir);
    EXPECT_EQ(missing.status, 1) << p << ": " << missing.err;
    EXPECT_NE(missing.err.find("cannot open LCM log 'missing.lcmlog'"), std::string::npos)
        << p << ": " << missing.err;
    const auto garbage = RunCommand(bin + " --lcm-url log:garbage.lcmlog,out.lcmlog", dir);
    EXPECT_EQ(garbage.status, 1) << p << ": " << garbage.err;
    EXPECT_NE(garbage.err.find("holds no LCM event"), std::string::npos) << p << garbage.err;
    const auto url = RunCommand(bin + " --lcm-url tcp://robot:7667", dir);
    EXPECT_EQ(url.status, 2) << p << ": " << url.err;
    const auto channel = RunCommand(bin + " --channel NOPE=X", dir);
    EXPECT_EQ(channel.status, 2) << p << ": " << channel.err;
  }
}

// The device drivers need no input; they share the exit codes for a bad options file, a bad
// LCM URL or channel rename (2), and a device that is not there (1).
struct Driver {
  const char* name;
  std::string args;     // what it needs besides the device
  std::string missing;  // options naming a device that is not there
};

TEST(ProgramsEdge, DriversShareOneExitCodePolicy) {
  TempDir dir;
  {
    std::ofstream bad(dir.file("bad.yaml"));
    bad << "no_such_key: 1\n";
    std::ofstream cal(dir.file("rig.yaml"));
    cal << "width: 640\nheight: 480\nrectified: true\nleft: {fx: 500, fy: 500, cx: 320, cy: "
           "240}\nright: {fx: 500, fy: 500, cx: 320, cy: 240}\ntranslation: [-0.1, 0, 0]\n";
  }
  const std::vector<Driver> drivers{
      {"fl-base-driver", "--robot " + fl::test::SourceDir() + "/config/robot/turtlebot2.yaml",
       "--port " + dir.file("nothing")},
      {"fl-stereo-driver", "--calibration rig.yaml", "--device " + dir.file("nothing")}};
  for (const Driver& d : drivers) {
    const std::string bin = BinDir() + "/" + d.name + " " + d.args;
    const auto cfg = RunCommand(bin + " --config bad.yaml", dir);
    EXPECT_EQ(cfg.status, 2) << d.name << ": " << cfg.err;
    EXPECT_NE(cfg.err.find("bad.yaml:1:1: unknown key 'no_such_key'"), std::string::npos)
        << d.name << ": " << cfg.err;
    const auto url = RunCommand(bin + " --lcm-url tcp://robot:7667", dir);
    EXPECT_EQ(url.status, 2) << d.name << ": " << url.err;
    const auto channel = RunCommand(bin + " --channel NOPE=X", dir);
    EXPECT_EQ(channel.status, 2) << d.name << ": " << channel.err;
    const auto missing = RunCommand(bin + " --lcm-url memq:// " + d.missing, dir);
    EXPECT_EQ(missing.status, 1) << d.name << ": " << missing.err;
    EXPECT_NE(missing.err.find("nothing"), std::string::npos) << d.name << ": " << missing.err;
  }
}

// A small simulator log (laser, odometry, stereo, calibration, ground truth).
std::string SimLog(const TempDir& dir, double duration_s) {
  const std::string log = dir.file("sim.lcmlog");
  const auto r = RunCommand(BinDir() + "/fl-sim --duration " + std::to_string(duration_s) +
                                " --log " + log + " --log-level warn",
                            dir);
  EXPECT_EQ(r.status, 0) << r.err;
  return log;
}

TEST(ProgramsEdge, LogModeNeedsItsChannelsAndStampsEverythingWithDataTime) {
  TempDir dir;
  const std::string log = SimLog(dir, 6.0);
  // The fusion needs the estimators' outputs, which a sensor log does not have.
  const auto fusion = RunCommand(BinDir() + "/fl-fusion --map-out '' --lcm-url log:" + log, dir);
  EXPECT_EQ(fusion.status, 1) << fusion.err;
  EXPECT_NE(fusion.err.find("has no RBPF_POSE, which fl-fusion needs; it holds"), std::string::npos)
      << fusion.err;
  EXPECT_NE(fusion.err.find("LASER ("), std::string::npos) << fusion.err;
  EXPECT_NE(fusion.err.find("fl-replay"), std::string::npos) << fusion.err;

  const auto rbpf = RunCommand(
      BinDir() + "/fl-rbpf-slam --lcm-url log:" + log + "," + dir.file("out.lcmlog"), dir);
  ASSERT_EQ(rbpf.status, 0) << rbpf.err;
  fl::Utime first = INT64_MAX, last = INT64_MIN;
  {
    fl::LcmLogReader in(log);
    fl::LcmLogEvent ev;
    while (in.Next(&ev)) {
      first = std::min(first, ev.utime);
      last = std::max(last, ev.utime);
    }
  }
  fl::LcmLogReader out(dir.file("out.lcmlog"));
  fl::LcmLogEvent ev;
  int statuses = 0;
  std::set<std::string> channels;
  while (out.Next(&ev)) {
    channels.insert(ev.channel);
    EXPECT_GE(ev.utime, first) << ev.channel;
    EXPECT_LE(ev.utime, last) << ev.channel;
    if (ev.channel == "STATUS_FL_RBPF_SLAM") {
      fusionloc::status_t st;
      ASSERT_GT(st.decode(ev.data.data(), 0, static_cast<int>(ev.data.size())), 0);
      EXPECT_EQ(st.process, "fl-rbpf-slam");
      EXPECT_EQ(st.utime, ev.utime);       // data time, not the wall clock
      EXPECT_EQ(st.cpu_ms_per_item, 0.0);  // no wall-clock timing in what a replay publishes
      ++statuses;
    }
  }
  EXPECT_GE(statuses, 5);  // about once a second of data time, and at the end
  EXPECT_TRUE(channels.count("RBPF_POSE"));
}

TEST(ProgramsEdge, ALiveProcessSaysWhenItsInputIsSilent) {
  TempDir dir;
  // memq:// is in-process: nothing ever arrives. The three run side by side and get SIGINT
  // after 4 s (room for a loaded machine); a clean stop is exit 0.
  std::string cmd;
  for (const char* p : kProcesses) {
    const std::string extra = std::string(p) == "fl-fusion" ? " --map-out ''" : "";
    cmd += "(timeout --foreground --preserve-status -s INT 4 " + BinDir() + "/" + p +
           " --lcm-url memq:// --input-timeout-s 0.3" + extra + " 2> " + p + ".err; echo $? > " +
           p + ".rc) & ";
  }
  const auto r = RunCommand("{ " + cmd + "wait; }", dir);
  ASSERT_EQ(r.status, 0);
  for (const char* p : kProcesses) {
    std::ifstream err_file(dir.file(std::string(p) + ".err")),
        rc_file(dir.file(std::string(p) + ".rc"));
    const std::string err((std::istreambuf_iterator<char>(err_file)),
                          std::istreambuf_iterator<char>());
    int rc = -1;
    rc_file >> rc;
    const std::string expect = std::string(p) == "fl-fusion"      ? "no RBPF_POSE on memq://"
                               : std::string(p) == "fl-stereo-vo" ? "no STEREO on memq://"
                                                                  : "no LASER on memq://";
    EXPECT_NE(err.find(expect + " for 0.3 s: is the driver"), std::string::npos)
        << p << ": " << err;
    EXPECT_EQ(rc, 0) << p << ": " << err;
  }
}

}  // namespace
