// The built programs together over live LCM (UDP multicast on this host, a port of the
// test's own): fl-procman-sheriff --lone-ranger runs a script; a separate fl-procman-deputy
// obeys a sheriff and fl-procman-ctl; a new sheriff adopts what runs; a deputy killed with
// SIGKILL leaves no process behind.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <thread>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/procman/process.hpp"
#include "process_fixtures.hpp"
#include "test_paths.hpp"

namespace {

using fl::test::BinDir;
using fl::test::RunCommand;
using fl::test::Spawn;
using fl::test::TempDir;
using fl::test::WaitFor;

std::string Url(int offset) {
  return "udpm://239.255.76.67:" + std::to_string(7300 + (getpid() * 7 + offset) % 400) + "?ttl=0";
}

bool HaveMulticast(const std::string& url) {
  try {
    fl::MakeLcm(url);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

std::string Read(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void WriteFile(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

const char* kCfg =
    // ${WHO} inside double quotes is the deputy's (--var); inside single quotes it would be sh's.
    "cmd \"hello\" { exec = \"sh -c \\\"echo hello ${WHO}; sleep 0.5\\\"\"; host = \"one\"; }\n"
    "group \"g\" {\n"
    "  cmd \"sleeper\" { exec = \"sleep 30\"; host = \"one\"; stop_signal = 15; }\n"
    "  cmd \"family\" { exec = \"sh -c 'sleep 31 & sleep 32 & wait'\"; host = \"one\"; }\n"
    "}\n"
    "script \"run\" {\n"
    "  start cmd \"hello\" wait \"running\";\n"
    "  wait cmd \"hello\" status \"stopped\";\n"
    "  start group \"g\" wait \"running\";\n"
    "  stop group \"g\" wait \"stopped\";\n"
    "}\n";

TEST(ProcmanPrograms, LoneRangerRunsAScriptAndReports) {
  const std::string url = Url(1);
  if (!HaveMulticast(url)) GTEST_SKIP() << "no UDP multicast on this machine";
  TempDir dir;
  WriteFile(dir.file("t.cfg"), kCfg);
  const auto r = RunCommand("timeout 60 " + BinDir() + "/fl-procman-sheriff --lone-ranger t.cfg " +
                                "run --quit-after-script --status-period 0 --log-dir logs " +
                                "--var WHO=world --report report.txt --lcm-url '" + url + "'",
                            dir);
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_EQ(Read(dir.file("logs/hello.log")).rfind("hello world\n", 0), 0u)
      << Read(dir.file("logs/hello.log"));
  const std::string report = Read(dir.file("report.txt"));
  EXPECT_NE(report.find("hello"), std::string::npos) << report;
  EXPECT_NE(report.find("SIGTERM"), std::string::npos) << report;  // g/sleeper's stop_signal
  EXPECT_NE(r.out.find("script run: done"), std::string::npos) << r.out;
  // A failing command fails the run (exit 1) and names it.
  WriteFile(
      dir.file("bad.cfg"),
      "cmd \"bad\" { exec = \"sh -c 'exit 5'\"; host = \"one\"; }\n"
      "script \"s\" { start cmd \"bad\"; wait ms 300; wait cmd \"bad\" status \"stopped\"; }\n");
  const auto bad = RunCommand("timeout 30 " + BinDir() + "/fl-procman-sheriff --lone-ranger " +
                                  "bad.cfg s --quit-after-script --status-period 0 --log-dir " +
                                  "logs --lcm-url '" + url + "'",
                              dir);
  EXPECT_EQ(bad.status, 1) << bad.out << bad.err;
  EXPECT_NE(bad.err.find("failed: bad"), std::string::npos) << bad.err;
  // Bad usage and a bad .cfg: exit 2 with the reason.
  const auto usage = RunCommand(BinDir() + "/fl-procman-sheriff t.cfg nope", dir);
  EXPECT_EQ(usage.status, 2);
  EXPECT_NE(usage.err.find("no script 'nope' in t.cfg (it has: run)"), std::string::npos)
      << usage.err;
  WriteFile(dir.file("broken.cfg"), "cmd \"x\" { exec = \"a\" }\n");
  const auto broken = RunCommand(BinDir() + "/fl-procman-sheriff broken.cfg", dir);
  EXPECT_EQ(broken.status, 2);
  EXPECT_NE(broken.err.find("broken.cfg:1:22: expected ';' after exec"), std::string::npos)
      << broken.err;
}

TEST(ProcmanPrograms, DeputySheriffCtlAndANewSheriffAdopts) {
  const std::string url = Url(2);
  if (!HaveMulticast(url)) GTEST_SKIP() << "no UDP multicast on this machine";
  TempDir dir;
  WriteFile(dir.file("t.cfg"), kCfg);
  const std::string bin = BinDir();
  const pid_t deputy = Spawn("cd " + dir.path() + " && exec " + bin +
                             "/fl-procman-deputy --name one --insecure --log-dir logs --lcm-url '" +
                             url + "' > deputy.out 2>&1");
  const std::string sheriff_cmd =
      "cd " + dir.path() + " && exec " + bin +
      "/fl-procman-sheriff t.cfg --insecure --status-period 0 --lcm-url '" + url + "' < /dev/null";
  pid_t sheriff = Spawn(sheriff_cmd + " > sheriff1.out 2>&1");
  const std::string ctl = bin + "/fl-procman-ctl --lcm-url '" + url + "' ";
  // The sheriff answers once it has found the deputy.
  ASSERT_TRUE(WaitFor([&] { return RunCommand(ctl + "start g", dir).status == 0; }))
      << Read(dir.file("sheriff1.out")) << Read(dir.file("deputy.out"));
  std::string status;
  ASSERT_TRUE(WaitFor([&] {
    status = RunCommand(ctl + "status", dir).out;
    return status.find("g/sleeper               running") != std::string::npos &&
           status.find("g/family                running") != std::string::npos;
  })) << status;
  EXPECT_NE(status.find("running"), std::string::npos) << status;
  // The host line: load, memory, and that this deputy obeys unsigned orders.
  ASSERT_TRUE(WaitFor([&] {
    status = RunCommand(ctl + "status", dir).out;
    return status.find("host one: load") != std::string::npos;
  })) << status;
  EXPECT_NE(status.find("INSECURE: acts on unsigned PMD_ORDERS2"), std::string::npos) << status;
  const auto nothing = RunCommand(ctl + "stop nothing", dir);
  EXPECT_EQ(nothing.status, 1);
  EXPECT_NE(nothing.out.find("no command or group 'nothing'"), std::string::npos);
  // The sheriff is killed: the deputy runs on; a new sheriff adopts the same pids.
  kill(sheriff, SIGKILL);
  waitpid(sheriff, nullptr, 0);
  const std::string before = status.substr(status.find("g/sleeper"), 40);
  sheriff = Spawn(sheriff_cmd + " > sheriff2.out 2>&1");
  ASSERT_TRUE(WaitFor([&] {
    status = RunCommand(ctl + "status", dir).out;
    return status.find("g/sleeper               running") != std::string::npos;
  })) << status;
  EXPECT_EQ(status.substr(status.find("g/sleeper"), 40), before) << status;  // same pid, run 1
  EXPECT_NE(Read(dir.file("sheriff2.out")).find("adopted g/sleeper on one (running"),
            std::string::npos)
      << Read(dir.file("sheriff2.out"));
  EXPECT_EQ(RunCommand(ctl + "stop everything", dir).status, 0);
  ASSERT_TRUE(WaitFor([&] {
    status = RunCommand(ctl + "status", dir).out;
    return status.find("running") == std::string::npos &&
           status.find("stopping") == std::string::npos;
  })) << status;
  EXPECT_NE(status.find("SIGTERM"), std::string::npos) << status;  // sleeper: stop_signal 15
  EXPECT_EQ(RunCommand(ctl + "quit", dir).status, 0);
  int ws = 0;
  waitpid(sheriff, &ws, 0);
  EXPECT_TRUE(WIFEXITED(ws) && WEXITSTATUS(ws) == 0);
  kill(deputy, SIGTERM);
  waitpid(deputy, &ws, 0);
  EXPECT_TRUE(WIFEXITED(ws) && WEXITSTATUS(ws) == 0) << Read(dir.file("deputy.out"));
}

TEST(ProcmanPrograms, DeputyKilledBySigkillLeavesNoProcess) {
  const std::string url = Url(3);
  if (!HaveMulticast(url)) GTEST_SKIP() << "no UDP multicast on this machine";
  TempDir dir;
  WriteFile(dir.file("t.cfg"), kCfg);
  const std::string bin = BinDir();
  const pid_t deputy = Spawn("cd " + dir.path() + " && exec " + bin +
                             "/fl-procman-deputy --name one --insecure --log-dir logs --lcm-url '" +
                             url + "' > deputy.out 2>&1");
  const pid_t sheriff = Spawn("cd " + dir.path() + " && exec " + bin +
                              "/fl-procman-sheriff t.cfg --insecure --status-period 0 --lcm-url '" +
                              url + "' < /dev/null > sheriff.out 2>&1");
  const std::string ctl = bin + "/fl-procman-ctl --lcm-url '" + url + "' ";
  ASSERT_TRUE(WaitFor([&] { return RunCommand(ctl + "start g", dir).status == 0; }));
  // The pids of both commands from the deputy's log lines.
  std::vector<pid_t> groups;
  ASSERT_TRUE(WaitFor([&] {
    const std::string out = Read(dir.file("deputy.out"));
    groups.clear();
    for (size_t at = 0; (at = out.find("(pid ", at)) != std::string::npos; at += 5) {
      groups.push_back(std::atoi(out.c_str() + at + 5));
    }
    return groups.size() == 2;
  })) << Read(dir.file("deputy.out"));
  ASSERT_TRUE(WaitFor([&] {
    int n = 0;
    for (const auto& [g, u] : fl::procman::ReadGroupUsage(groups)) n += u.processes;
    return n == 4;  // sleep 30; sh + sleep 31 + sleep 32
  }));
  kill(deputy, SIGKILL);
  waitpid(deputy, nullptr, 0);
  EXPECT_TRUE(WaitFor(
      [&] {
        int n = 0;
        for (const auto& [g, u] : fl::procman::ReadGroupUsage(groups)) n += u.processes;
        return n == 0;
      },
      5.0))
      << "processes of the deputy's commands survived it";
  RunCommand(ctl + "quit", dir);
  waitpid(sheriff, nullptr, 0);
}

}  // namespace

namespace {

TEST(ProcmanPrograms, KeysSignedOrdersAndTheNoKeyError) {
  const std::string url = Url(4);
  if (!HaveMulticast(url)) GTEST_SKIP() << "no UDP multicast on this machine";
  TempDir dir;
  WriteFile(dir.file("t.cfg"), kCfg);
  const std::string bin = BinDir();
  const auto made = RunCommand(bin + "/fl-procman-sheriff --new-key keys/k", dir);
  ASSERT_EQ(made.status, 0) << made.err;
  EXPECT_NE(made.out.find("new key "), std::string::npos);
  struct stat st;
  ASSERT_EQ(stat(dir.file("keys/k").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  const auto again = RunCommand(bin + "/fl-procman-sheriff --new-key keys/k", dir);
  EXPECT_EQ(again.status, 2) << again.err;
  // No key and no --insecure: the deputy says how to get one (exit 2).
  const auto nokey = RunCommand("FUSIONLOC_PROCMAN_KEY=" + dir.file("none.key") + " " + bin +
                                    "/fl-procman-deputy --name one --lcm-url '" + url + "'",
                                dir);
  EXPECT_EQ(nokey.status, 2);
  EXPECT_NE(nokey.err.find("--insecure"), std::string::npos) << nokey.err;
  EXPECT_NE(nokey.err.find("--new-key"), std::string::npos) << nokey.err;
  // A key others may read is refused.
  WriteFile(dir.file("open.key"), Read(dir.file("keys/k")));
  chmod(dir.file("open.key").c_str(), 0644);
  const auto open =
      RunCommand(bin + "/fl-procman-deputy --key open.key --lcm-url '" + url + "'", dir);
  EXPECT_EQ(open.status, 2);
  EXPECT_NE(open.err.find("chmod 600"), std::string::npos) << open.err;
  // Signed orders from a sheriff with the key act on a deputy with the key.
  const pid_t deputy = Spawn("cd " + dir.path() + " && exec " + bin +
                             "/fl-procman-deputy --name one --key keys/k --log-dir logs "
                             "--lcm-url '" +
                             url + "' > deputy.out 2>&1");
  const pid_t sheriff = Spawn("cd " + dir.path() + " && exec " + bin +
                              "/fl-procman-sheriff t.cfg --key keys/k --status-period 0 "
                              "--lcm-url '" +
                              url + "' < /dev/null > sheriff.out 2>&1");
  // A sheriff that signs takes fl-procman-ctl's orders only signed with its key: otherwise
  // anyone on the network could have it sign their orders.
  const std::string ctl = bin + "/fl-procman-ctl --key keys/k --lcm-url '" + url + "' ";
  ASSERT_TRUE(WaitFor([&] { return RunCommand(ctl + "start g/sleeper", dir).status == 0; }))
      << Read(dir.file("sheriff.out"));
  const auto plain =
      RunCommand(bin + "/fl-procman-ctl --insecure --lcm-url '" + url + "' stop g/sleeper", dir);
  EXPECT_EQ(plain.status, 1) << plain.out << plain.err;
  EXPECT_NE(plain.out.find("refused: this sheriff signs its orders"), std::string::npos)
      << plain.out;
  ASSERT_EQ(RunCommand(bin + "/fl-procman-sheriff --new-key keys/other", dir).status, 0);
  const auto other = RunCommand(
      bin + "/fl-procman-ctl --key keys/other --lcm-url '" + url + "' stop g/sleeper", dir);
  EXPECT_EQ(other.status, 1) << other.out << other.err;
  EXPECT_NE(other.out.find("refused: unknown key id"), std::string::npos) << other.out;
  EXPECT_NE(Read(dir.file("sheriff.out")).find("refused an unsigned order from ctl-"),
            std::string::npos)
      << Read(dir.file("sheriff.out"));
  EXPECT_NE(Read(dir.file("sheriff.out")).find("refused a signed order from ctl-"),
            std::string::npos)
      << Read(dir.file("sheriff.out"));
  std::string status;
  EXPECT_TRUE(WaitFor([&] {
    status = RunCommand(ctl + "status", dir).out;
    return status.find("g/sleeper               running") != std::string::npos;
  })) << status
      << Read(dir.file("deputy.out"));
  EXPECT_NE(Read(dir.file("sheriff.out")).find("orders signed with key"), std::string::npos);
  EXPECT_NE(Read(dir.file("deputy.out")).find("signed orders only"), std::string::npos);
  RunCommand(ctl + "quit", dir);
  waitpid(sheriff, nullptr, 0);
  kill(deputy, SIGTERM);
  int ws = 0;
  waitpid(deputy, &ws, 0);
  EXPECT_TRUE(WIFEXITED(ws) && WEXITSTATUS(ws) == 0);
}

}  // namespace
