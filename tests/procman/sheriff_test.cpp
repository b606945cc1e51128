// The sheriff's logic against a real in-process deputy (no LCM): scripts, text orders,
// groups, adoption of what a deputy already runs by a new sheriff, and the observer.
#include "fusionloc/procman/sheriff.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <functional>
#include <thread>

#include "test_paths.hpp"

namespace fl::procman {
namespace {

double NowS() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
int64_t NowUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

const char* kCfg =
    "cmd \"logger\" { exec = \"sleep 30\"; host = \"h\"; }\n"
    "group \"est\" {\n"
    "  cmd \"slam\" { exec = \"sleep 31\"; host = \"h\"; }\n"
    "  group \"vision\" { cmd \"vo\" { exec = \"sleep 32\"; host = \"h\"; } }\n"
    "}\n"
    "cmd \"once\" { exec = \"sh -c 'exit 4'\"; host = \"h\"; }\n"
    "script \"up\" {\n"
    "  start cmd \"logger\" wait \"running\";\n"
    "  start group \"est\" wait \"running\";\n"
    "  wait ms 50;\n"
    "  run_script \"down_vision\";\n"
    "  start cmd \"once\";\n"
    "  wait cmd \"once\" status \"stopped\";\n"
    "}\n"
    "script \"down_vision\" { stop group \"est/vision\" wait \"stopped\"; }\n";

struct Rig {
  fl::test::TempDir dir;
  Deputy deputy;
  explicit Rig() : deputy(Options(dir.path()), nullptr) {}
  static DeputyOptions Options(const std::string& log_dir) {
    DeputyOptions o;
    o.name = "h";
    o.log_dir = log_dir;
    return o;
  }
  // One round of sheriff <-> deputy, as over LCM.
  void Step(Sheriff* s) {
    for (const Orders& o : s->DueOrders(NowS(), NowUs())) deputy.HandleOrders(o, NowUs());
    deputy.Poll();
    HostStatus h;
    h.host = "h";
    h.cmds = deputy.Commands();
    s->HandleStatus(h, NowS());
    s->StepScripts(NowS());
  }
  bool RunUntil(Sheriff* s, const std::function<bool()>& done, double timeout_s = 5.0) {
    const double end = NowS() + timeout_s;
    while (NowS() < end) {
      Step(s);
      if (done()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return false;
  }
};

SheriffOptions Fast() {
  SheriffOptions o;
  o.adopt_wait_s = 0.2;
  return o;
}

TEST(Sheriff, ScriptStartsWaitsStopsAndRunsNestedScripts) {
  Rig rig;
  Sheriff s(ParseProcmanConfig(kCfg, "t.cfg"), Fast());
  std::string error;
  ASSERT_TRUE(s.RunScript("up", &error)) << error;
  ASSERT_TRUE(rig.RunUntil(&s, [&] { return !s.ScriptRunning(); }));
  // logger 0, est/slam 1, est/vision/vo 2, once 3
  EXPECT_EQ(s.State(0), ShownState::kRunning);
  EXPECT_EQ(s.State(1), ShownState::kRunning);
  EXPECT_EQ(s.State(2), ShownState::kStopped);  // down_vision
  EXPECT_EQ(s.Reported(2).starts, 1);
  EXPECT_EQ(s.State(3), ShownState::kStopped);  // ran and exited with 4
  EXPECT_EQ(WEXITSTATUS(s.Reported(3).exit_status), 4);
  const std::vector<std::string> events = s.TakeEvents();
  std::string all;
  for (const auto& e : events) all += e + "\n";
  EXPECT_NE(all.find("script up: start cmd logger, wait until running"), std::string::npos) << all;
  EXPECT_NE(all.find("script up: run_script down_vision"), std::string::npos) << all;
  EXPECT_NE(all.find("script down_vision: done"), std::string::npos) << all;
  EXPECT_NE(s.StatusTable().find("est/vision/vo"), std::string::npos);
  EXPECT_NE(s.ReportTable().find("once"), std::string::npos);
  std::string bad;
  EXPECT_FALSE(s.RunScript("nope", &bad));
  EXPECT_NE(bad.find("it has: up, down_vision"), std::string::npos) << bad;
}

TEST(Sheriff, TextOrdersByNameGroupAndEverything) {
  Rig rig;
  Sheriff s(ParseProcmanConfig(kCfg, "t.cfg"), Fast());
  bool quit = false;
  ASSERT_TRUE(rig.RunUntil(&s, [&] { return s.HostSeen("h"); }));
  rig.Step(&s);
  EXPECT_EQ(s.Execute("start est", &quit), "start: est/slam, est/vision/vo");
  ASSERT_TRUE(rig.RunUntil(&s, [&] { return s.IsRunning(1) && s.IsRunning(2); }));
  EXPECT_EQ(s.State(0), ShownState::kStopped);  // not in the group
  const pid_t slam = s.Reported(1).pid;
  EXPECT_EQ(s.Execute("restart slam", &quit), "restart: est/slam");
  ASSERT_TRUE(rig.RunUntil(&s, [&] { return s.IsRunning(1) && s.Reported(1).pid != slam; }));
  EXPECT_EQ(s.Reported(1).starts, 2);
  EXPECT_EQ(s.Execute("stop everything", &quit).rfind("stop: logger, est/slam", 0), 0u);
  ASSERT_TRUE(rig.RunUntil(&s, [&] { return s.IsStopped(1) && s.IsStopped(2); }));
  EXPECT_EQ(s.Execute("start est/vision/vo", &quit), "start: est/vision/vo");
  ASSERT_TRUE(rig.RunUntil(&s, [&] { return s.IsRunning(2); }));
  EXPECT_NE(s.Execute("status", &quit).find("running"), std::string::npos);
  EXPECT_NE(s.Execute("start nothing", &quit).find("no command or group 'nothing'"),
            std::string::npos);
  EXPECT_NE(s.Execute("launch x", &quit).find("orders: start|stop|restart"), std::string::npos);
  EXPECT_NE(s.Execute("run nope", &quit).find("no script 'nope'"), std::string::npos);
  EXPECT_FALSE(quit);
  s.Execute("quit", &quit);
  EXPECT_TRUE(quit);
}

TEST(Sheriff, ANewSheriffAdoptsWhatTheDeputyRuns) {
  Rig rig;
  pid_t logger = 0, slam = 0;
  {
    Sheriff first(ParseProcmanConfig(kCfg, "t.cfg"), Fast());
    std::string error;
    first.RunScript("up", &error);
    ASSERT_TRUE(rig.RunUntil(&first, [&] { return !first.ScriptRunning(); }));
    logger = first.Reported(0).pid;
    slam = first.Reported(1).pid;
  }  // the sheriff is gone; the deputy runs on
  Sheriff second(ParseProcmanConfig(kCfg, "t.cfg"), Fast());
  rig.RunUntil(
      &second, [] { return false; }, 0.5);
  EXPECT_EQ(second.State(0), ShownState::kRunning);
  EXPECT_EQ(second.Reported(0).pid, logger);  // not restarted
  EXPECT_EQ(second.Reported(1).pid, slam);
  EXPECT_EQ(second.Reported(1).starts, 1);
  EXPECT_EQ(second.State(2), ShownState::kStopped);  // stays stopped
  EXPECT_EQ(second.State(3), ShownState::kStopped);  // exited: not run again
  EXPECT_EQ(second.Reported(3).starts, 1);
  bool quit = false;
  second.Execute("stop logger", &quit);
  ASSERT_TRUE(rig.RunUntil(&second, [&] { return second.IsStopped(0); }));
  EXPECT_NE(kill(logger, 0), 0);
}

TEST(Sheriff, ObserverSendsNoOrders) {
  Rig rig;
  SheriffOptions o = Fast();
  o.observer = true;
  Sheriff s(ParseProcmanConfig(kCfg, "t.cfg"), o);
  std::string error;
  bool quit = false;
  EXPECT_NE(s.Execute("start logger", &quit).find("observer"), std::string::npos);
  rig.RunUntil(
      &s, [] { return false; }, 0.4);
  EXPECT_TRUE(s.DueOrders(NowS() + 10, NowUs()).empty());
  EXPECT_TRUE(rig.deputy.Commands().empty());
}

TEST(Sheriff, OrdersAHostThatNeverReportedAfterTheAdoptWait) {
  Sheriff s(ParseProcmanConfig("cmd \"a\" { exec = \"x\"; host = \"far\"; }", "t.cfg"), Fast());
  const double t0 = NowS();
  EXPECT_TRUE(s.DueOrders(t0, NowUs()).empty());
  EXPECT_TRUE(s.DueOrders(t0 + 0.1, NowUs()).empty());
  const std::vector<Orders> o = s.DueOrders(t0 + 0.3, NowUs());
  ASSERT_EQ(o.size(), 1u);
  EXPECT_EQ(o[0].host, "far");
  ASSERT_EQ(o[0].cmds.size(), 1u);
  EXPECT_EQ(o[0].cmds[0].desired_runid, 0);  // known, not started
  EXPECT_GT(o[0].cmds[0].spec.sheriff_id, 0);
  // Repeated once a second, and at once after a change.
  EXPECT_TRUE(s.DueOrders(t0 + 0.5, NowUs()).empty());
  EXPECT_EQ(s.DueOrders(t0 + 1.4, NowUs()).size(), 1u);
  s.Start({0});
  const std::vector<Orders> p = s.DueOrders(t0 + 1.5, NowUs());
  ASSERT_EQ(p.size(), 1u);
  EXPECT_EQ(p[0].cmds[0].desired_runid, 1);
}

}  // namespace
}  // namespace fl::procman
