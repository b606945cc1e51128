// fl-urg-driver and fl-urg-emulator as programs: the driver against the emulator program, and
// the exit code and message for what is not a sensor or not the right one.
#include <gtest/gtest.h>

#include <fstream>
#include <regex>

#include "test_paths.hpp"

namespace {

using fl::test::BinDir;
using fl::test::RunCommand;
using fl::test::TempDir;

TEST(UrgPrograms, DriverReadsTheEmulatorProgramAndStopsCleanly) {
  TempDir dir;
  const std::string link = dir.file("hokuyo");
  const auto r =
      RunCommand("{ (" + BinDir() + "/fl-urg-emulator --link " + link +
                     " --duration-s 5 > emu.out 2> emu.err &)"
                     "; for i in $(seq 50); do [ -e " +
                     link + " ] && break; sleep 0.1; done; " +
                     // One SIGINT: timeout(1) signals its process group too, and a
                     // second signal is the edge's "stop now" (exit 130).
                     BinDir() + "/fl-urg-driver --port " + link +
                     " --lcm-url memq:// & pid=$!; sleep 2.5; kill -INT $pid; wait $pid; }",
                 dir);
  EXPECT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("connected to URG-04LX serial H0614967"), std::string::npos) << r.err;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.err, m, std::regex("scans ([0-9]+), checksum errors 0")))
      << r.err;
  EXPECT_GE(std::stoi(m[1]), 10);
  std::ifstream out(dir.file("emu.out"));
  std::string printed;
  std::getline(out, printed);
  EXPECT_EQ(printed, link);  // the emulator prints the path to open
}

TEST(UrgPrograms, NotADeviceAndAWrongModelExitWith1AndSayWhy) {
  TempDir dir;
  std::ofstream(dir.file("file.txt")) << "x";
  for (const std::string& port : {std::string("/dev/null"), dir.file("file.txt")}) {
    const auto r = RunCommand(BinDir() + "/fl-urg-driver --lcm-url memq:// --port " + port, dir);
    EXPECT_EQ(r.status, 1) << r.err;
    EXPECT_NE(r.err.find("'" + port + "': not a serial device"), std::string::npos) << r.err;
  }
  std::ofstream(dir.file("utm.yaml")) << "product: SOKUIKI Sensor UTM-30LX\nmodel: UTM-30LX\n";
  const std::string link = dir.file("hokuyo");
  const auto r =
      RunCommand("(" + BinDir() + "/fl-urg-emulator --config utm.yaml --link " + link +
                     " --duration-s 4 > /dev/null 2>&1 &); for i in $(seq 50); do [ -e " + link +
                     " ] && break; sleep 0.1; done; " + BinDir() +
                     "/fl-urg-driver --lcm-url memq:// --port " + link,
                 dir);
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("not the configured model 'URG-04LX'"), std::string::npos) << r.err;
}

TEST(UrgPrograms, BadOptionsAreUsageErrors) {
  TempDir dir;
  std::ofstream(dir.file("bad.yaml")) << "cluster: 0\n";
  const auto r = RunCommand(BinDir() + "/fl-urg-driver --config bad.yaml", dir);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_NE(r.err.find("cluster must be 1..99"), std::string::npos) << r.err;
  const auto e = RunCommand(BinDir() + "/fl-urg-emulator --config bad.yaml", dir);
  EXPECT_EQ(e.status, 2) << e.err;
  EXPECT_NE(e.err.find("unknown key 'cluster'"), std::string::npos) << e.err;
}

// The config files document the defaults: loading them changes nothing.
TEST(UrgPrograms, ConfigFilesHoldTheDefaults) {
  TempDir dir;
  for (const char* name : {"urg-driver", "urg-emulator"}) {
    const std::string p = name;
    std::string file = p;
    file.replace(file.find('-'), 1, "_");
    const auto defaults = RunCommand(BinDir() + "/fl-" + p + " --print-config", dir);
    const auto loaded = RunCommand(BinDir() + "/fl-" + p + " --print-config --config " +
                                       fl::test::SourceDir() + "/config/" + file + ".yaml",
                                   dir);
    ASSERT_EQ(loaded.status, 0) << loaded.err;
    EXPECT_EQ(loaded.out, defaults.out) << p;
  }
}

// With no port and no USB Hokuyo (none on the build machines) it waits for one, says so once,
// and stops cleanly on SIGINT.
TEST(UrgPrograms, AutoDiscoveryWaitsForASensorAndStopsOnSigint) {
  TempDir dir;
  const auto r = RunCommand("{ " + BinDir() +
                                "/fl-urg-driver --lcm-url memq:// & pid=$!; sleep 1.5; kill -INT "
                                "$pid; for i in $(seq 50); do kill -0 $pid 2>/dev/null || break; "
                                "sleep 0.1; done; kill -KILL $pid 2>/dev/null; wait $pid; }",
                            dir);
  EXPECT_EQ(r.status, 0) << r.err;
  const size_t first = r.err.find("; waiting");
  ASSERT_NE(first, std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("; waiting", first + 1), std::string::npos) << "said more than once:\n"
                                                                   << r.err;
  EXPECT_TRUE(r.err.find("no USB Hokuyo (vendor id 15d1) found") != std::string::npos ||
              r.err.find("cannot look for a USB Hokuyo") != std::string::npos)
      << r.err;
}

}  // namespace
