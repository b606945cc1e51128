#include "fusionloc/sim_pipeline/sim_pipeline.hpp"

#include <gtest/gtest.h>

#include <csignal>
#include <thread>

#include "test_paths.hpp"

namespace fl::bench {
namespace {

// Runs `pipeline` (Start, then Poll) until the simulator exited or `timeout_s` (liveness).
bool RunUntilSimExits(SimPipeline* pipeline, double timeout_s = 10.0) {
  auto spin = [&](double seconds) {
    const double end = NowSeconds() + seconds;
    while (NowSeconds() < end) {
      pipeline->Poll();
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  };
  pipeline->Start(spin, 0.3);
  const double end = NowSeconds() + timeout_s;
  while (!pipeline->SimExited() && NowSeconds() < end) spin(0.01);
  return pipeline->SimExited();
}

procman::DeputyOptions Options(const test::TempDir& dir) {
  procman::DeputyOptions o;
  o.name = "sim-pipeline-test";
  o.log_dir = dir.path();
  o.vars = {{"DIR", dir.path()}};
  return o;
}

TEST(SimPipeline, StartsTheSimulatorLastAndCountsCrashes) {
  test::TempDir dir;
  SimPipeline pipeline(Options(dir), {{"listener", "sh -c 'touch ${DIR}/listening; exec sleep 30'"},
                                      {"crasher", "sh -c 'sleep 0.5; kill -SEGV $$'"},
                                      {"failer", "sh -c 'sleep 0.5; exit 3'"},
                                      {"sim", "sh -c 'test -e ${DIR}/listening && sleep 1.5'"}});
  ASSERT_TRUE(RunUntilSimExits(&pipeline));
  // The simulator found the listener's file: it was started after the others.
  bool sim_clean = false;
  for (const auto& c : pipeline.Commands()) {
    if (c.spec.name == "sim")
      sim_clean = WIFEXITED(c.exit_status) && WEXITSTATUS(c.exit_status) == 0;
  }
  EXPECT_TRUE(sim_clean);
  EXPECT_EQ(pipeline.crashes(), 2) << pipeline.crash_note();
  EXPECT_NE(pipeline.crash_note().find("crasher killed by signal 11"), std::string::npos)
      << pipeline.crash_note();
  EXPECT_NE(pipeline.crash_note().find("failer exit 3"), std::string::npos)
      << pipeline.crash_note();
  pipeline.StopAll();
  pipeline.Poll();
  EXPECT_EQ(pipeline.crashes(), 2);  // a stop asked for is not a crash
}

TEST(SimPipeline, ExpectedExitsAreNotCrashesAndRespawnsAreCounted) {
  test::TempDir dir;
  SimPipeline pipeline(Options(dir), {{"respawner", "sh -c 'sleep 0.2; kill -KILL $$'", true},
                                      {"sim", "sleep 1.5"}});
  pipeline.set_expected_exit([](const procman::CommandStatus& c) {
    return WIFSIGNALED(c.exit_status) && WTERMSIG(c.exit_status) == SIGKILL;
  });
  ASSERT_TRUE(RunUntilSimExits(&pipeline));
  EXPECT_EQ(pipeline.crashes(), 0) << pipeline.crash_note();
  int respawns = 0;
  for (const auto& c : pipeline.Commands()) respawns += c.respawns;
  EXPECT_GE(respawns, 2);
}

TEST(SimPipeline, ScheduleCountsEveryChannel) {
  sim::SimOptions o = sim::DefaultOptionsForWorld("paper");
  o.duration_s = 10.0;  // 100 steps of 0.1 s: 101 frames
  const auto n = SimSchedule(o);
  EXPECT_EQ(n.at("GROUND_TRUTH"), 101);
  EXPECT_EQ(n.at("LASER"), (101 - 1) / o.PeriodSteps(o.laser.rate_hz) + 1);
  EXPECT_EQ(n.at("STEREO"), (101 - 1) / o.PeriodSteps(o.camera.rate_hz) + 1);
  EXPECT_EQ(n.at("STEREO_CALIBRATION"), 11);  // every 1 s
  o.camera.enabled = false;
  EXPECT_EQ(SimSchedule(o).at("STEREO"), 0);
}

TEST(SimPipeline, NoCommandsIsAnError) {
  test::TempDir dir;
  EXPECT_THROW(SimPipeline(Options(dir), {}), std::invalid_argument);
}

}  // namespace
}  // namespace fl::bench
