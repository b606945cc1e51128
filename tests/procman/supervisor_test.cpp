#include "fusionloc/procman/supervisor.hpp"

#include <gtest/gtest.h>
#include <signal.h>

#include <fstream>
#include <sstream>

#include "test_paths.hpp"

namespace fl::procman {
namespace {

ProcessSpec Proc(const std::string& name, const std::string& command) {
  ProcessSpec p;
  p.name = name;
  p.command = command;
  p.restart_delay_s = 0.0;
  return p;
}

SupervisorOptions Quiet(const std::string& dir) {
  SupervisorOptions o;
  o.log_dir = dir;
  o.print = [](const std::string&) {};
  return o;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(ProcmanSupervisor, RestartsAFailingProcessThenGivesUpAndFailsTheRun) {
  fl::test::TempDir dir;
  LaunchFile l;
  ProcessSpec bad = Proc("bad", "sh -c \"echo attempt; exit 3\"");
  bad.max_restarts = 2;
  ProcessSpec idle = Proc("idle", "sleep 30");
  l.processes = {idle, bad};
  Supervisor s(l, Quiet(dir.path()));
  const RunResult r = s.Run();
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.reason.find("required process bad failed (exit code 3) after 2 restarts"),
            std::string::npos)
      << r.reason;
  const ProcessStatus& b = s.statuses()[1];
  EXPECT_EQ(b.starts, 3);
  EXPECT_EQ(b.restarts, 2);
  EXPECT_EQ(b.exit_code, 3);
  EXPECT_EQ(b.state, ProcessState::kFailed);
  // Every attempt appended to the one log.
  const std::string log = ReadFile(b.log_path);
  EXPECT_EQ(log, "attempt\nattempt\nattempt\n");
  // The other process was stopped, not left running.
  EXPECT_EQ(s.statuses()[0].state, ProcessState::kStopped);
  EXPECT_EQ(s.statuses()[0].pid, -1);
}

TEST(ProcmanSupervisor, StopAllProcessEndsTheRunAndStopsTheOthersInReverseOrder) {
  fl::test::TempDir dir;
  LaunchFile l;
  l.end_grace_s = 0.1;
  const std::string order = dir.path() + "/order.txt";
  // Each long-runner writes its name when it receives SIGTERM.
  ProcessSpec first = Proc("first", "sh -c \"trap 'echo first >> " + order +
                                        "; exit 0' TERM; while true; do sleep 0.05; done\"");
  ProcessSpec second = Proc("second", "sh -c \"trap 'echo second >> " + order +
                                          "; exit 0' TERM; while true; do sleep 0.05; done\"");
  ProcessSpec sim = Proc("sim", "sh -c \"sleep 0.5\"");
  sim.on_exit = "stop_all";
  sim.start_delay_s = 0.1;
  l.processes = {first, second, sim};
  Supervisor s(l, Quiet(dir.path()));
  const RunResult r = s.Run();
  EXPECT_TRUE(r.ok) << r.reason;
  EXPECT_NE(r.reason.find("sim ended (exit code 0)"), std::string::npos) << r.reason;
  EXPECT_EQ(s.statuses()[2].state, ProcessState::kExited);
  EXPECT_EQ(s.statuses()[0].state, ProcessState::kStopped);
  EXPECT_EQ(s.statuses()[1].state, ProcessState::kStopped);
  EXPECT_EQ(ReadFile(order), "second\nfirst\n");
  EXPECT_GT(s.statuses()[0].uptime_s, 0.4);
}

TEST(ProcmanSupervisor, AProcessIgnoringSigtermIsKilledAfterTheTimeout) {
  fl::test::TempDir dir;
  LaunchFile l;
  l.stop_timeout_s = 0.3;
  l.end_grace_s = 0.0;
  ProcessSpec term_ignorer = Proc("term_ignorer", "sh -c \"trap '' TERM; while true; do sleep 0.05; done\"");
  ProcessSpec end = Proc("end", "true");
  end.on_exit = "stop_all";
  end.start_delay_s = 0.2;
  l.processes = {term_ignorer, end};
  Supervisor s(l, Quiet(dir.path()));
  EXPECT_TRUE(s.Run().ok);
  EXPECT_EQ(s.statuses()[0].state, ProcessState::kStopped);
  EXPECT_EQ(s.statuses()[0].exit_signal, SIGKILL);
  EXPECT_NE(s.ReportTable().find("SIGKILL"), std::string::npos) << s.ReportTable();
}

TEST(ProcmanSupervisor, AMissingProgramIsNamedWithTheExecError) {
  fl::test::TempDir dir;
  LaunchFile l;
  l.processes = {Proc("ghost", "/nonexistent/fl-ghost --flag")};
  Supervisor s(l, Quiet(dir.path()));
  const RunResult r = s.Run();
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.reason.find("cannot run '/nonexistent/fl-ghost': No such file or directory"),
            std::string::npos)
      << r.reason;
  EXPECT_EQ(s.statuses()[0].starts, 0);
}

TEST(ProcmanSupervisor, OptionalProcessesMayEndAndTheRunEndsWhenAllHave) {
  fl::test::TempDir dir;
  LaunchFile l;
  ProcessSpec a = Proc("a", "sh -c \"echo out; echo err >&2; exit 1\"");
  a.required = false;
  a.restart = "never";
  ProcessSpec b = Proc("b", "echo ${WORD}");
  b.restart = "never";
  l.processes = {a, b};
  SupervisorOptions o = Quiet(dir.path());
  o.vars = {{"WORD", "expanded"}};
  Supervisor s(l, o);
  const RunResult r = s.Run();
  EXPECT_TRUE(r.ok) << r.reason;
  EXPECT_EQ(r.reason, "every process has ended");
  EXPECT_EQ(s.statuses()[0].state, ProcessState::kFailed);
  EXPECT_EQ(ReadFile(s.statuses()[0].log_path), "out\nerr\n");
  EXPECT_EQ(ReadFile(s.statuses()[1].log_path), "expanded\n");
}

TEST(ProcmanSupervisor, UnknownVariableIsRejectedBeforeAnythingStarts) {
  fl::test::TempDir dir;
  LaunchFile l;
  l.processes = {Proc("a", "echo ${FL_PROCMAN_SURELY_UNSET}")};
  try {
    Supervisor s(l, Quiet(dir.path()));
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("process 'a': variable ${FL_PROCMAN_SURELY_UNSET}"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace fl::procman
