// The deputy's process control on real child processes: libbot2's order semantics, output
// capture, stop signal then SIGKILL, respawn back-off, and no child left when it is killed.
#include "fusionloc/procman/deputy.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <sstream>
#include <thread>

#include "test_paths.hpp"

namespace fl::procman {
namespace {

int64_t WallUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct Fixture {
  fl::test::TempDir dir;
  std::string output;
  std::vector<int32_t> output_ids;
  std::unique_ptr<Deputy> deputy;
  explicit Fixture(DeputyOptions o = DeputyOptions()) {
    o.name = "testhost";
    o.log_dir = dir.path();
    o.vars["WORD"] = "hello";
    deputy = std::make_unique<Deputy>(o, [this](int32_t id, const std::string& text) {
      output += text;
      output_ids.push_back(id);
    });
  }
  // Polls until `done` or `timeout_s` (liveness only).
  bool PollUntil(const std::function<bool()>& done, double timeout_s = 5.0) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (std::chrono::steady_clock::now() < end) {
      deputy->Poll();
      if (done()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return false;
  }
  CommandStatus Cmd(int32_t id) const {
    for (const CommandStatus& c : deputy->Commands()) {
      if (c.spec.sheriff_id == id) return c;
    }
    return CommandStatus();
  }
  bool Known(int32_t id) const {
    for (const CommandStatus& c : deputy->Commands()) {
      if (c.spec.sheriff_id == id) return true;
    }
    return false;
  }
};

CommandOrder Order(int32_t id, const std::string& exec, int32_t runid, bool force_quit = false) {
  CommandOrder o;
  o.spec.sheriff_id = id;
  o.spec.name = "cmd" + std::to_string(id);
  o.spec.exec = exec;
  o.desired_runid = runid;
  o.force_quit = force_quit;
  return o;
}

Orders For(const std::string& host, std::vector<CommandOrder> cmds, int64_t utime = WallUs()) {
  Orders o;
  o.host = host;
  o.utime_us = utime;
  o.sheriff_name = "test";
  o.cmds = std::move(cmds);
  return o;
}

bool Alive(pid_t pid) { return pid > 0 && kill(pid, 0) == 0; }

TEST(Deputy, RunidBumpStartsAndCapturesOutput) {
  Fixture f;
  // runid 0 = the command's initial actual_runid: known, not started.
  EXPECT_EQ(f.deputy->HandleOrders(For("testhost", {Order(1, "echo ${WORD} 'a  b'", 0)}), WallUs()),
            OrdersVerdict::kApplied);
  f.deputy->Poll();
  EXPECT_TRUE(f.Known(1));
  EXPECT_EQ(f.Cmd(1).starts, 0);
  f.deputy->HandleOrders(For("testhost", {Order(1, "echo ${WORD} 'a  b'", 1)}), WallUs());
  ASSERT_TRUE(f.PollUntil([&] { return f.Cmd(1).exited; }));
  const CommandStatus c = f.Cmd(1);
  EXPECT_EQ(c.starts, 1);
  EXPECT_EQ(c.actual_runid, 1);
  EXPECT_TRUE(WIFEXITED(c.exit_status));
  EXPECT_EQ(WEXITSTATUS(c.exit_status), 0);
  EXPECT_EQ(c.state, CommandState::kStopped);
  EXPECT_NE(f.output.find("hello a  b\n"), std::string::npos) << f.output;
  std::ifstream log(c.log_path);
  std::stringstream s;
  s << log.rdbuf();
  EXPECT_EQ(s.str(), "hello a  b\n");
  // The same orders again: same run id, no new start.
  f.deputy->HandleOrders(For("testhost", {Order(1, "echo ${WORD} 'a  b'", 1)}), WallUs());
  f.PollUntil([] { return false; }, 0.1);
  EXPECT_EQ(f.Cmd(1).starts, 1);
}

TEST(Deputy, IgnoresOrdersForOtherHostsAndStaleOrders) {
  Fixture f;
  EXPECT_EQ(f.deputy->HandleOrders(For("otherhost", {Order(1, "sleep 5", 1)}), WallUs()),
            OrdersVerdict::kOtherHost);
  EXPECT_EQ(f.deputy->HandleOrders(For("testhost", {Order(1, "sleep 5", 1)}, WallUs() - 61'000'000),
                                   WallUs()),
            OrdersVerdict::kStale);
  EXPECT_TRUE(f.deputy->Commands().empty());
  // 59 s old is still fresh (libbot2: a minute).
  EXPECT_EQ(f.deputy->HandleOrders(For("testhost", {Order(1, "sleep 5", 1)}, WallUs() - 59'000'000),
                                   WallUs()),
            OrdersVerdict::kApplied);
  EXPECT_EQ(f.Cmd(1).state, CommandState::kRunning);
}

TEST(Deputy, ForceQuitStopsRunidBumpRestartsMissingIsRemoved) {
  Fixture f;
  f.deputy->HandleOrders(For("testhost", {Order(1, "sleep 30", 1), Order(2, "sleep 30", 1)}),
                         WallUs());
  const pid_t first = f.Cmd(1).pid;
  ASSERT_TRUE(Alive(first));
  // A bumped run id while running: stopped, then started again with a new pid.
  f.deputy->HandleOrders(For("testhost", {Order(1, "sleep 30", 2), Order(2, "sleep 30", 1)}),
                         WallUs());
  ASSERT_TRUE(f.PollUntil([&] { return f.Cmd(1).pid > 0 && f.Cmd(1).pid != first; }));
  EXPECT_EQ(f.Cmd(1).actual_runid, 2);
  EXPECT_EQ(f.Cmd(1).starts, 2);
  EXPECT_FALSE(Alive(first));
  // force_quit: stopped by its stop signal (SIGINT by default).
  const pid_t second = f.Cmd(1).pid;
  f.deputy->HandleOrders(For("testhost", {Order(1, "sleep 30", 2, true), Order(2, "sleep 30", 1)}),
                         WallUs());
  ASSERT_TRUE(f.PollUntil([&] { return f.Cmd(1).state == CommandState::kStopped; }));
  EXPECT_TRUE(WIFSIGNALED(f.Cmd(1).exit_status));
  EXPECT_EQ(WTERMSIG(f.Cmd(1).exit_status), SIGINT);
  EXPECT_FALSE(Alive(second));
  // Command 2 missing from the orders: stopped and removed.
  const pid_t two = f.Cmd(2).pid;
  f.deputy->HandleOrders(For("testhost", {Order(1, "sleep 30", 2, true)}), WallUs());
  ASSERT_TRUE(f.PollUntil([&] { return !f.Known(2); }));
  EXPECT_FALSE(Alive(two));
  EXPECT_TRUE(f.Known(1));
}

TEST(Deputy, StopSignalThenSigkillAfterStopTimeAllowed) {
  Fixture f;
  // Ignores SIGTERM: must be SIGKILLed after stop_time_allowed.
  CommandOrder o = Order(1, "sh -c 'trap \"\" TERM; echo ready; while :; do sleep 0.05; done'", 1);
  o.spec.stop_signal = SIGTERM;
  o.spec.stop_time_allowed_s = 0.3;
  f.deputy->HandleOrders(For("testhost", {o}), WallUs());
  ASSERT_TRUE(f.PollUntil([&] { return f.output.find("ready") != std::string::npos; }));
  o.force_quit = true;
  f.deputy->HandleOrders(For("testhost", {o}), WallUs());
  f.PollUntil([] { return false; }, 0.1);
  EXPECT_EQ(f.Cmd(1).state, CommandState::kStopping);  // SIGTERM ignored
  ASSERT_TRUE(f.PollUntil([&] { return f.Cmd(1).state == CommandState::kStopped; }));
  EXPECT_TRUE(WIFSIGNALED(f.Cmd(1).exit_status));
  EXPECT_EQ(WTERMSIG(f.Cmd(1).exit_status), SIGKILL);
  EXPECT_NE(f.output.find("did not stop within"), std::string::npos);

  // A command that honours SIGTERM ends by it.
  CommandOrder p = Order(2, "sleep 30", 1);
  p.spec.stop_signal = SIGTERM;
  f.deputy->HandleOrders(For("testhost", {o, p}), WallUs());
  p.force_quit = true;
  f.deputy->HandleOrders(For("testhost", {o, p}), WallUs());
  ASSERT_TRUE(f.PollUntil([&] { return f.Cmd(2).state == CommandState::kStopped; }));
  EXPECT_EQ(WTERMSIG(f.Cmd(2).exit_status), SIGTERM);
}

TEST(Deputy, AutoRespawnWithGrowingBackoff) {
  Fixture f;
  CommandOrder o = Order(1, "sh -c 'exit 3'", 1);
  o.spec.auto_respawn = true;
  f.deputy->HandleOrders(For("testhost", {o}), WallUs());
  // Back-off 10, 20, 40, 80, 160, 320 ms: 7 starts take 630 ms of waiting, so a second sees
  // about 8 (without a back-off, 10 ms apart, about a hundred).
  f.PollUntil([] { return false; }, 1.0);
  const CommandStatus c = f.Cmd(1);
  EXPECT_GE(c.starts, 4);
  EXPECT_LE(c.starts, 11);
  EXPECT_EQ(c.respawns, c.starts - 1);
  EXPECT_EQ(WEXITSTATUS(c.exit_status), 3);
  EXPECT_EQ(c.actual_runid, 1);  // a respawn keeps the run id
  // A sheriff's stop ends the respawning.
  o.force_quit = true;
  f.deputy->HandleOrders(For("testhost", {o}), WallUs());
  const int starts = f.Cmd(1).starts;
  f.PollUntil([] { return false; }, 0.3);
  EXPECT_EQ(f.Cmd(1).starts, starts);
  EXPECT_EQ(f.Cmd(1).state, CommandState::kStopped);
}

TEST(Deputy, NoRespawnWithoutAutoRespawnAndClearErrors) {
  Fixture f;
  f.deputy->HandleOrders(
      For("testhost", {Order(1, "sh -c 'exit 3'", 1), Order(2, "/nonexistent/fl-nothing", 1),
                       Order(3, "echo 'unclosed", 1)}),
      WallUs());
  f.PollUntil([] { return false; }, 0.3);
  EXPECT_EQ(f.Cmd(1).starts, 1);
  EXPECT_EQ(f.Cmd(2).starts, 0);
  EXPECT_NE(f.Cmd(2).error.find("cannot run '/nonexistent/fl-nothing'"), std::string::npos);
  EXPECT_NE(f.Cmd(3).error.find("unterminated single quote"), std::string::npos);
  EXPECT_NE(f.output.find("cannot run"), std::string::npos);
}

TEST(Deputy, StatusHasCpuAndMemory) {
  Fixture f;
  f.deputy->HandleOrders(For("testhost", {Order(1, "sh -c 'while :; do :; done'", 1)}), WallUs());
  f.deputy->MeasureStatus(WallUs());
  f.PollUntil([] { return false; }, 0.5);
  const HostStatus h = f.deputy->MeasureStatus(WallUs());
  ASSERT_EQ(h.cmds.size(), 1u);
  EXPECT_EQ(h.host, "testhost");
  EXPECT_GT(h.cmds[0].cpu_usage, 0.2);  // a busy loop (on a shared machine: generous)
  EXPECT_LE(h.cmds[0].cpu_usage, 1.2);
  EXPECT_GT(h.cmds[0].rss_bytes, 100'000);
  EXPECT_GE(h.cmds[0].peak_rss_bytes, h.cmds[0].rss_bytes);
  EXPECT_GT(h.mem_total_bytes, h.mem_free_bytes);
  EXPECT_GT(h.mem_free_bytes, 0);
  EXPECT_GT(h.cpu_load, 0.0);
  EXPECT_LE(h.cpu_load, 1.0);
}

// Every process of process group `pgid` is gone (within a generous liveness timeout).
bool GroupGone(pid_t pgid, double timeout_s = 5.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (ReadGroupUsage({pgid}).at(pgid).processes == 0) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}

TEST(Deputy, NoChildOutlivesADeputyKilledBySigkill) {
  fl::test::TempDir dir;
  int report[2];
  ASSERT_EQ(pipe(report), 0);
  const pid_t deputy_pid = fork();
  ASSERT_GE(deputy_pid, 0);
  if (deputy_pid == 0) {
    close(report[0]);
    DeputyOptions o;
    o.name = "h";
    o.log_dir = dir.path();
    Deputy d(o, nullptr);
    // A direct child and one with children of its own (which PDEATHSIG does not cover).
    d.HandleOrders(
        For("h", {Order(1, "sleep 60", 1), Order(2, "sh -c 'sleep 61 & sleep 62 & wait'", 1)}),
        WallUs());
    const std::vector<CommandStatus> cmds = d.Commands();
    pid_t pids[2] = {cmds[0].pid, cmds[1].pid};
    (void)!write(report[1], pids, sizeof(pids));
    for (;;) {
      d.Poll();
      usleep(10000);
    }
  }
  close(report[1]);
  pid_t pids[2] = {0, 0};
  ASSERT_EQ(read(report[0], pids, sizeof(pids)), static_cast<ssize_t>(sizeof(pids)));
  close(report[0]);
  // Wait until the shell has its two sleeps (3 processes in its group).
  for (int i = 0; i < 250 && ReadGroupUsage({pids[1]}).at(pids[1]).processes < 3; ++i) {
    usleep(20000);
  }
  ASSERT_EQ(ReadGroupUsage({pids[1]}).at(pids[1]).processes, 3);
  ASSERT_EQ(ReadGroupUsage({pids[0]}).at(pids[0]).processes, 1);
  kill(deputy_pid, SIGKILL);
  int ws = 0;
  waitpid(deputy_pid, &ws, 0);
  EXPECT_TRUE(GroupGone(pids[0]));
  EXPECT_TRUE(GroupGone(pids[1])) << ReadGroupUsage({pids[1]}).at(pids[1]).processes
                                  << " processes of the shell's group survived";
}

}  // namespace
}  // namespace fl::procman
