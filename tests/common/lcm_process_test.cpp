// The LCM process edge: nodes in a pipeline over a log (loopback delivery, data time, finish
// order), time-stamp ordering, the silent-input watch, and LcmProcess' log-mode checks.
#include "fusionloc/common/lcm_process.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <thread>

#include "fusionloc/common/process_memory.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "test_paths.hpp"

namespace fl {
namespace {

fusionloc::wheel_odometry_t Odom(Utime t, double x) {
  fusionloc::wheel_odometry_t m{};
  m.utime = t;
  m.x = x;
  return m;
}

// Doubles x of every IN message and publishes it on OUT; at Finish publishes one more.
class Doubler : public LcmNode {
 public:
  Doubler(LcmInterface* lcm, std::string in, std::string out, const char* name)
      : lcm_(lcm), in_(std::move(in)), out_(std::move(out)), status_(lcm, name) {
    lcm_->Subscribe<fusionloc::wheel_odometry_t>(
        in_, [this](const fusionloc::wheel_odometry_t& m, const std::string&) {
          seen.push_back(m.utime);
          seen_now.push_back(lcm_->Now());
          status_.CountIn();
          lcm_->Publish(out_, Odom(m.utime, 2 * m.x));
        });
  }
  StatusReporter& status() override { return status_; }
  std::vector<std::string> RequiredInputs() const override { return {in_}; }
  void Finish() override {
    finished = true;
    lcm_->Publish(out_, Odom(last_in(), -1));
  }
  Utime last_in() const { return seen.empty() ? 0 : seen.back(); }
  std::vector<Utime> seen, seen_now;
  bool finished = false;

 private:
  LcmInterface* lcm_;
  std::string in_, out_;
  StatusReporter status_;
};

void WriteLog(const std::string& path, const std::vector<std::pair<std::string, Utime>>& events) {
  LcmLogWriter w(path);
  for (const auto& [ch, t] : events) w.Write(ch, Odom(t, 1.0), t);
  w.Close();
}

TEST(LcmProcess, APipelineInOneProcessSeesDataTimeAndDrainsInOrder) {
  test::TempDir dir;
  // Out of order by 0.1 s (as lcm-logger may record), plus a recorded old output to replace.
  WriteLog(dir.file("in.lcmlog"),
           {{"A", 1000000}, {"A", 3000000}, {"A", 2900000}, {"B", 1500000}, {"A", 4000000}});
  LogReplayOptions o;
  o.in_path = dir.file("in.lcmlog");
  o.out_path = dir.file("out.lcmlog");
  o.copy_inputs = true;
  o.reorder_window_s = 0.5;
  o.drop_channels = {"B"};
  auto lcm = MakeLogReplay(o);
  Doubler first(lcm.get(), "A", "B", "fl-first");
  Doubler second(lcm.get(), "B", "C", "fl-second");
  InputWatch watch(lcm.get(), 0.0);
  watch.Watch("A", &first);
  watch.Watch("B", &second);
  SpinNodes(lcm.get(), {&first, &second}, &watch);
  // Time order; the recorded B was left out; B came from `first` only, before the next A.
  EXPECT_EQ(first.seen, (std::vector<Utime>{1000000, 2900000, 3000000, 4000000}));
  EXPECT_EQ(second.seen, (std::vector<Utime>{1000000, 2900000, 3000000, 4000000, 4000000}));
  EXPECT_EQ(second.seen_now, second.seen);  // Now() is the data time of what is handled
  EXPECT_TRUE(first.finished && second.finished);
  EXPECT_EQ(watch.received("B"), 5);
  EXPECT_EQ(lcm->LogChannelCounts().at("B"), 1);
  lcm.reset();

  LcmLogReader r(dir.file("out.lcmlog"));
  LcmLogEvent ev;
  std::vector<std::string> order;
  Utime prev = 0;
  while (r.Next(&ev)) {
    EXPECT_GE(ev.utime, prev) << ev.channel;  // stamps never go back: data time throughout
    EXPECT_LE(ev.utime, 4000000) << ev.channel;
    prev = ev.utime;
    if (ev.channel.rfind("STATUS_", 0) == 0) {
      fusionloc::status_t st;
      ASSERT_GT(st.decode(ev.data.data(), 0, static_cast<int>(ev.data.size())), 0);
      EXPECT_EQ(st.utime, ev.utime);
      for (const std::string& key : st.keys) EXPECT_NE(key, "heap_mb");  // live only
      continue;
    }
    order.push_back(ev.channel);
  }
  EXPECT_EQ(order, (std::vector<std::string>{"A", "B", "C", "A", "B", "C", "A", "B", "C", "A", "B",
                                             "C", "B", "C", "C"}));
}

TEST(LcmProcess, ASilentInputIsReportedLiveInTheStatus) {
  const int kWarn = fusionloc::status_t::LEVEL_WARN;  // lcm-gen constants have no definition
  auto lcm = MakeLcm("memq://");
  Doubler node(lcm.get(), "A", "B", "fl-node");
  InputWatch watch(lcm.get(), 0.05);
  watch.Watch("A", &node);
  testing::internal::CaptureStderr();
  watch.Poll();
  EXPECT_NE(node.status().level(), kWarn);
  std::this_thread::sleep_for(std::chrono::milliseconds(80));
  watch.Poll();
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(node.status().level(), kWarn);
  EXPECT_NE(node.status().message().find("no A on memq:// for 0.05 s"), std::string::npos)
      << node.status().message();
  EXPECT_NE(err.find("is the driver (or the process that publishes it) running?"),
            std::string::npos)
      << err;
  EXPECT_EQ(watch.Silent(), std::vector<std::string>{"A"});
  lcm->Publish("A", Odom(1, 1.0));
  lcm->HandleSubscriptions(100);
  EXPECT_EQ(watch.received("A"), 1);
  EXPECT_TRUE(watch.Silent().empty());
}

// Live, every process reports its heap in use (once a minute, the first at the start).
TEST(LcmProcess, TheStatusCarriesTheHeapLive) {
  if (!ReadHeapUsage().supported) GTEST_SKIP() << "not glibc's allocator (a sanitizer build)";
  auto lcm = MakeLcm("memq://");
  Doubler node(lcm.get(), "A", "B", "fl-node");
  double heap_mb = -1.0;
  lcm->Subscribe<fusionloc::status_t>("STATUS_FL_NODE",
                                      [&](const fusionloc::status_t& st, const std::string&) {
                                        for (size_t k = 0; k < st.keys.size(); ++k) {
                                          if (st.keys[k] == "heap_mb") heap_mb = st.values[k];
                                        }
                                      });
  ResetShutdownForTest();
  std::thread stop([] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    RequestShutdown();
  });
  SpinNodes(lcm.get(), {&node}, nullptr);
  stop.join();
  ResetShutdownForTest();
  lcm->HandleSubscriptions(0);
  EXPECT_GT(heap_mb, 0.0);
  EXPECT_LT(heap_mb, 10000.0);
}

// Runs a Doubler through LcmProcess::Run as a main would, returning the exit code.
int RunDoubler(std::vector<std::string> args) {
  Program program("fl-doubler", "test");
  LcmProcess process(&program, {{"A", "fusionloc.wheel_odometry_t", "in"}},
                     {{"B", "fusionloc.wheel_odometry_t", "out"}});
  args.insert(args.begin(), "fl-doubler");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  if (!program.Parse(static_cast<int>(argv.size()), argv.data())) return program.exit_code();
  return program.Run([&] {
    return process.Run([](LcmInterface* lcm, const ChannelMap& ch) {
      return std::make_unique<Doubler>(lcm, ch("A"), ch("B"), "fl-doubler");
    });
  });
}

TEST(LcmProcess, LogModeFailsOnAMissingChannelOrAFileThatIsNoLog) {
  test::TempDir dir;
  WriteLog(dir.file("odd.lcmlog"), {{"X", 1}, {"X", 2}});
  {
    std::ofstream f(dir.file("garbage.bin"), std::ios::binary);
    for (int i = 0; i < 100000; ++i) f.put(static_cast<char>((i * 7919) % 251));
  }
  testing::internal::CaptureStderr();
  EXPECT_EQ(RunDoubler({"--lcm-url", "log:" + dir.file("odd.lcmlog")}), kExitFailure);
  EXPECT_EQ(RunDoubler({"--lcm-url", "log:" + dir.file("odd.lcmlog"), "--channel", "A=X"}),
            kExitOk);
  EXPECT_EQ(RunDoubler({"--lcm-url", "log:" + dir.file("garbage.bin")}), kExitFailure);
  EXPECT_EQ(RunDoubler({"--lcm-url", "log:" + dir.file("none.lcmlog")}), kExitFailure);
  EXPECT_EQ(RunDoubler({"--lcm-url", "tcp://x"}), kExitUsage);
  EXPECT_EQ(RunDoubler({"--channel", "Q=R"}), kExitUsage);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("has no A, which fl-doubler needs; it holds X (2)"), std::string::npos) << err;
  EXPECT_NE(err.find("holds no LCM event"), std::string::npos) << err;
  EXPECT_NE(err.find("corrupt bytes"), std::string::npos) << err;
  EXPECT_NE(err.find("cannot open LCM log"), std::string::npos) << err;
  EXPECT_NE(err.find("unsupported LCM URL 'tcp://x'"), std::string::npos) << err;
  ResetShutdownForTest();
}

}  // namespace
}  // namespace fl
