// `./fusionloc spy` (lcm-spy through fl.spy.SpyLauncher, lcmtypes/java/) receives every message
// of a short simulated log played over live UDP multicast, full 640x480 stereo pairs included.
//
// Without the launcher's receive buffer (`--recv-buf-size 0`: the kernel default, 212992 bytes
// of kernel memory, all that LCM 1.3.1's Java side ever gets) the same run loses the pairs:
// lcm-spy counted 0 of the 21 STEREO messages, at --speed=5 and at real time alike, while every
// message of the six small channels arrived (checked by hand while writing this test).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <map>
#include <regex>
#include <sstream>
#include <string>

#include "fusionloc/common/lcm_interface.hpp"
#include "process_fixtures.hpp"
#include "test_paths.hpp"

namespace {

namespace t = fl::test;

// Stops a spawned process group when the test ends early (an assertion failed).
struct StopOnExit {
  pid_t pid = 0;
  ~StopOnExit() {
    if (pid <= 0) return;
    kill(-pid, SIGKILL);
    waitpid(pid, nullptr, 0);
  }
};

bool OnPath(const std::string& program) {
  return std::system(("command -v " + program + " > /dev/null 2>&1").c_str()) == 0;
}

TEST(SpyLauncher, LcmSpyReceivesEveryStereoPairOfALog) {
  for (const char* program : {"java", "xvfb-run", "lcm-logplayer"}) {
    if (!OnPath(program)) GTEST_SKIP() << program << " not found (./fusionloc setup)";
  }
  // A port of this test's own; the C++ side of LCM checks that multicast works here.
  const std::string url = "udpm://239.255.76.67:" + std::to_string(7800 + getpid() % 100) +
                          "?ttl=0&recv_buf_size=16777216";
  try {
    fl::MakeLcm(url);
  } catch (const std::exception& e) {
    GTEST_SKIP() << "no UDP multicast on this machine (" << e.what()
                 << "); ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo";
  }
  t::TempDir dir;
  // 10 s of the simulated robot: STEREO (bot_core.images_t, two 640x480 gray images, ~600 KB)
  // at 2 Hz besides laser, odometry, ground truth and calibration.
  const std::string log = dir.file("sim.lcmlog");
  ASSERT_EQ(t::RunCommand(t::BinDir() + "/fl-sim --log-level warn --duration 10 --log " + log, dir)
                .status,
            0);
  std::map<std::string, int64_t> in_log;
  {
    fl::LcmLogReader reader(log);
    fl::LcmLogEvent event;
    while (reader.Next(&event)) ++in_log[event.channel];
  }
  ASSERT_GE(in_log["STEREO"], 20);

  // lcm-spy counts for a fixed window; the log plays well inside it.
  const std::string out = dir.file("spy.out");
  const pid_t spy =
      t::Spawn("FL_BUILD_DIR='" + t::BinaryDir() + "' exec xvfb-run -a '" + t::SourceDir() +
               "/fusionloc' spy '" + url + "' --count-seconds 20 > '" + out + "' 2>&1");
  StopOnExit stop{spy};
  ASSERT_TRUE(t::WaitFor(
      [&] { return t::ReadFile(out).find("fl-spy: counting") != std::string::npos; }, 60.0))
      << t::ReadFile(out);
  // The launcher says what receive buffer the kernel gave (rmem_max caps it).
  EXPECT_NE(t::ReadFile(out).find("fl-spy: UDP receive buffer"), std::string::npos)
      << t::ReadFile(out);

  // Five times real time: STEREO at 10 Hz, about 6 MB/s.
  const auto played =
      t::RunCommand("lcm-logplayer --speed=5 --lcm-url='" + url + "' '" + log + "'", dir);
  EXPECT_EQ(played.status, 0) << played.err;
  int status = 0;
  ASSERT_EQ(waitpid(spy, &status, WNOHANG), 0)
      << "lcm-spy stopped counting before the log was played:\n"
      << t::ReadFile(out);
  ASSERT_TRUE(t::WaitFor([&] { return waitpid(spy, &status, WNOHANG) == spy; }, 60.0))
      << "lcm-spy did not print its counts:\n"
      << t::ReadFile(out);
  stop.pid = 0;  // reaped
  const std::string text = t::ReadFile(out);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << text;

  std::map<std::string, int64_t> received, undecodable;
  const std::regex line(R"(channel (\S+) messages (\d+) undecodable (\d+) type (\S+))");
  std::istringstream lines(text);
  for (std::string l; std::getline(lines, l);) {
    std::smatch m;
    if (!std::regex_search(l, m, line)) continue;
    received[m[1]] = std::stoll(m[2]);
    undecodable[m[1]] = std::stoll(m[3]);
    // Every channel decodes with the project's types (no "??" fingerprint).
    EXPECT_NE(m[4].str().substr(0, 2), "??") << l;
  }
  for (const auto& [channel, count] : in_log) {
    EXPECT_EQ(received[channel], count) << channel << "\n" << text;
    EXPECT_EQ(undecodable[channel], 0) << channel;
  }
}

}  // namespace
