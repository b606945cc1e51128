// fl-logger (tools/logger): what it records reads back whole and exactly; OUTPUT appears only
// when a recording stops cleanly; an existing OUTPUT is refused without --force; a full disk
// stops it with a clear error, leaving OUTPUT.partial only; a kill -9 leaves OUTPUT.partial
// with what was flushed.
#include "logger.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sched.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "fusionloc/common/lcm_interface.hpp"
#include "process_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::logger {
namespace {

namespace fs = std::filesystem;
using test::BinDir;
using test::RunCommand;
using test::TempDir;

struct Message {
  std::string channel;
  std::vector<uint8_t> data;
};

// Messages of varied sizes on LASER and ODOMETRY, and some on OTHER (not recorded with
// --channel 'LASER|ODOMETRY').
std::vector<Message> MakeMessages(int n, int max_size) {
  std::vector<Message> out;
  for (int i = 0; i < n; ++i) {
    Message m;
    m.channel = i % 5 == 4 ? "OTHER" : (i % 2 == 0 ? "LASER" : "ODOMETRY");
    const int size = 1 + (i * 7919) % max_size;
    for (int k = 0; k < size; ++k) m.data.push_back(static_cast<uint8_t>((i * 31 + k) % 251));
    out.push_back(std::move(m));
  }
  return out;
}

bool Recorded(const Message& m) { return m.channel != "OTHER"; }

int64_t LogBytes(const std::vector<Message>& messages) {
  int64_t bytes = 0;
  for (const Message& m : messages) {
    if (Recorded(m)) bytes += 28 + static_cast<int64_t>(m.channel.size() + m.data.size());
  }
  return bytes;
}

std::vector<LcmLogEvent> ReadLog(const std::string& path, bool* truncated = nullptr) {
  LcmLogReader r(path);
  std::vector<LcmLogEvent> events;
  LcmLogEvent e;
  while (r.Next(&e)) events.push_back(e);
  if (truncated) *truncated = r.truncated();
  EXPECT_EQ(r.corrupt_bytes_skipped(), 0) << path;
  return events;
}

// The recorded messages, in order and byte for byte, numbered from 0.
void ExpectRecorded(const std::vector<LcmLogEvent>& events, const std::vector<Message>& sent) {
  std::vector<const Message*> expected;
  for (const Message& m : sent) {
    if (Recorded(m)) expected.push_back(&m);
  }
  ASSERT_EQ(events.size(), expected.size());
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_EQ(events[i].event_number, static_cast<int64_t>(i));
    EXPECT_EQ(events[i].channel, expected[i]->channel) << i;
    EXPECT_EQ(events[i].data, expected[i]->data) << i;
  }
}

LoggerOptions Options(const std::string& output) {
  LoggerOptions o;
  o.output = output;
  o.channel_regex = "LASER|ODOMETRY";
  o.progress_interval_s = 0;
  return o;
}

// Runs until `n` events are recorded (or 10 s pass: the test then fails on the count).
std::function<bool()> Until(const Logger& logger, int64_t n) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  return [&logger, n, deadline] {
    return logger.events() >= n || std::chrono::steady_clock::now() > deadline;
  };
}

TEST(Logger, RecordsTheMatchingChannelsAndRenamesWhenStopped) {
  TempDir dir;
  const std::string out = dir.file("run.lcmlog");
  auto lcm = MakeLcm("memq://");
  Logger logger(lcm.get(), Options(out));
  const std::vector<Message> sent = MakeMessages(40, 5000);
  for (size_t i = 0; i < sent.size(); ++i) {
    lcm->PublishRaw(sent[i].channel, sent[i].data.data(), static_cast<int>(sent[i].data.size()),
                    static_cast<Utime>(i));
  }
  EXPECT_TRUE(fs::exists(out + ".partial"));
  EXPECT_FALSE(fs::exists(out));
  const LoggerReport r = logger.Run(Until(logger, 32));
  EXPECT_EQ(r.events, 32);
  EXPECT_EQ(r.bytes, LogBytes(sent));
  EXPECT_FALSE(r.input_ended);
  EXPECT_FALSE(fs::exists(out + ".partial"));
  ASSERT_TRUE(fs::exists(out));
  EXPECT_EQ(static_cast<int64_t>(fs::file_size(out)), LogBytes(sent));
  ExpectRecorded(ReadLog(out), sent);
}

TEST(Logger, RefusesAnExistingOutputOrPartialWithoutForce) {
  TempDir dir;
  const std::string out = dir.file("run.lcmlog");
  auto lcm = MakeLcm("memq://");
  std::ofstream(out) << "an old recording";
  try {
    Logger logger(lcm.get(), Options(out));
    FAIL() << "an existing output was not refused";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("'" + out + "' exists"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--force"), std::string::npos) << e.what();
  }
  EXPECT_EQ(test::ReadFile(out), "an old recording");
  EXPECT_FALSE(fs::exists(out + ".partial"));

  fs::rename(out, out + ".partial");  // as a killed logger leaves it
  EXPECT_THROW(Logger(lcm.get(), Options(out)), std::runtime_error);
  EXPECT_EQ(test::ReadFile(out + ".partial"), "an old recording");

  // --force: the old log goes at once, so that a failed new recording is not taken for it.
  std::ofstream(out) << "an old recording";
  LoggerOptions forced = Options(out);
  forced.force = true;
  Logger logger(lcm.get(), forced);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_EQ(fs::file_size(out + ".partial"), 0u);
}

// OUTPUT.partial is a link to /dev/full: every write fails with ENOSPC, as on a full disk.
TEST(Logger, AWriteErrorStopsItNamingTheFileTheReasonAndWhatWasRecorded) {
  ASSERT_TRUE(fs::is_character_file("/dev/full")) << "this test needs /dev/full";
  TempDir dir;
  const std::string out = dir.file("run.lcmlog");
  fs::create_symlink("/dev/full", out + ".partial");
  auto lcm = MakeLcm("memq://");
  LoggerOptions o = Options(out);
  o.force = true;
  o.flush_interval_ms = 0;  // the first flush fails
  Logger logger(lcm.get(), o);
  const std::vector<Message> sent = MakeMessages(10, 100);
  for (const Message& m : sent) {
    lcm->PublishRaw(m.channel, m.data.data(), static_cast<int>(m.data.size()), 0);
  }
  try {
    logger.Run(Until(logger, 8));
    FAIL() << "a write error was not reported";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'" + out + ".partial'"), std::string::npos) << what;
    EXPECT_NE(what.find("No space left on device"), std::string::npos) << what;
    EXPECT_NE(what.find("stopped after 1 events ("), std::string::npos) << what;
    EXPECT_NE(what.find("NOT renamed to '" + out + "'"), std::string::npos) << what;
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_TRUE(fs::is_character_file("/dev/full"));
}

// ---- the program ----

// An input log of `n` messages (some on OTHER), events numbered from 0 as fl-logger numbers.
std::vector<Message> WriteInputLog(const std::string& path, int n, int max_size) {
  const std::vector<Message> sent = MakeMessages(n, max_size);
  LcmLogWriter w(path);
  for (size_t i = 0; i < sent.size(); ++i) {
    w.Write(sent[i].channel, sent[i].data.data(), static_cast<int>(sent[i].data.size()),
            1000000 + static_cast<Utime>(i) * 1000);
  }
  w.Close();
  return sent;
}

TEST(FlLogger, CopiesALogExactlyAndRefusesToOverwriteWithoutForce) {
  TempDir dir;
  const std::string logger = BinDir() + "/fl-logger";
  WriteInputLog(dir.file("in.lcmlog"), 50, 3000);
  auto r = RunCommand(logger + " --lcm-url=log:in.lcmlog out.lcmlog", dir);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("recorded 50 events"), std::string::npos) << r.err;
  EXPECT_EQ(test::ReadFile(dir.file("out.lcmlog")), test::ReadFile(dir.file("in.lcmlog")));
  EXPECT_FALSE(fs::exists(dir.file("out.lcmlog.partial")));

  r = RunCommand(logger + " --lcm-url=log:in.lcmlog --channel 'LASER|ODOMETRY' out.lcmlog", dir);
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("'out.lcmlog' exists; not overwriting it"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--force"), std::string::npos) << r.err;
  EXPECT_EQ(ReadLog(dir.file("out.lcmlog")).size(), 50u);  // untouched

  r = RunCommand(logger + " --lcm-url=log:in.lcmlog --channel 'LASER|ODOMETRY' --force out.lcmlog",
                 dir);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(ReadLog(dir.file("out.lcmlog")).size(), 40u);

  r = RunCommand(logger + " --flush-interval-ms -1 x.lcmlog", dir);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_NE(r.err.find("--flush-interval-ms must be >= 0"), std::string::npos) << r.err;
  r = RunCommand(logger + " --lcm-url=log:in.lcmlog no/such/folder/x.lcmlog", dir);
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("no/such/folder/x.lcmlog.partial"), std::string::npos) << r.err;
}

// A real full disk: a 64 KiB tmpfs in a mount namespace of its own (root only). What happened
// inside is written to files outside the tmpfs, which goes with the namespace.
TEST(FlLogger, AFullDiskStopsItWithAClearErrorAndLeavesOnlyThePartialFile) {
  if (geteuid() != 0) {
    GTEST_SKIP() << "needs root to mount a small tmpfs in a mount namespace (CI runs as root); "
                    "LcmLogWriter's and Logger's write-error paths are tested on /dev/full";
  }
  if (RunCommand("command -v unshare", TempDir()).status != 0) {
    GTEST_SKIP() << "no 'unshare' command (package util-linux)";
  }
  TempDir dir;
  const std::vector<Message> sent = WriteInputLog(dir.file("in.lcmlog"), 300, 3000);
  ASSERT_GT(LogBytes(sent), 4 * 65536);
  fs::create_directory(dir.file("small"));
  const std::string script =
      "mount -t tmpfs -o size=64k tmpfs small || exit 90; " + BinDir() +
      "/fl-logger --lcm-url=log:in.lcmlog --channel 'LASER|ODOMETRY' small/run.lcmlog "
      "2> logger.err; echo \\$? > logger.rc; ls -A small > listing.txt; "
      "cp small/run.lcmlog.partial salvaged.lcmlog 2>/dev/null; true";
  const auto r = RunCommand("unshare -m sh -c \"" + script + "\"", dir);
  if (r.status == 90 || !fs::exists(dir.file("logger.rc"))) {
    GTEST_SKIP() << "cannot mount a tmpfs in a mount namespace here: " << r.err;
  }
  const std::string err = test::ReadFile(dir.file("logger.err"));
  EXPECT_EQ(test::ReadFile(dir.file("logger.rc")), "1\n") << err;
  EXPECT_NE(err.find("write error on LCM log 'small/run.lcmlog.partial'"), std::string::npos)
      << err;
  EXPECT_NE(err.find("No space left on device"), std::string::npos) << err;
  EXPECT_NE(err.find("NOT renamed to 'small/run.lcmlog'"), std::string::npos) << err;
  EXPECT_EQ(test::ReadFile(dir.file("listing.txt")), "run.lcmlog.partial\n");
  // The partial file holds the events up to the failure: a prefix of what was sent, the
  // last one possibly cut short.
  bool truncated = false;
  const std::vector<LcmLogEvent> events = ReadLog(dir.file("salvaged.lcmlog"), &truncated);
  EXPECT_GT(events.size(), 10u);
  std::vector<Message> recorded;
  for (const Message& m : sent) {
    if (Recorded(m) && recorded.size() < events.size()) recorded.push_back(m);
  }
  ExpectRecorded(events, recorded);
  EXPECT_LE(fs::file_size(dir.file("salvaged.lcmlog")), 65536u);
}

// ---- live, over UDP multicast on loopback ----

// Puts this thread (and the programs it starts) into a new network namespace whose loopback
// carries multicast; back to the original one at destruction. Root only.
class LoopbackNetns {
 public:
  LoopbackNetns() {
    if (geteuid() != 0) {
      error_ = "needs root to create a network namespace (CI runs as root)";
      return;
    }
    original_ = open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
    if (original_ < 0 || unshare(CLONE_NEWNET) != 0) {
      error_ = std::string("cannot create a network namespace: ") + std::strerror(errno);
      return;
    }
    entered_ = true;
    if (std::system("ip link set lo up && ip link set lo multicast on && "
                    "ip route add 224.0.0.0/4 dev lo") != 0) {
      error_ = "cannot set up multicast on the namespace's loopback ('ip' failed)";
    }
  }
  ~LoopbackNetns() {
    if (entered_) setns(original_, CLONE_NEWNET);
    if (original_ >= 0) close(original_);
  }
  const std::string& error() const { return error_; }

 private:
  int original_ = -1;
  bool entered_ = false;
  std::string error_;
};

int64_t SizeOf(const std::string& path) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  return ec ? -1 : static_cast<int64_t>(size);
}

// Starts fl-logger on `url` into dir/name and waits until it has subscribed.
pid_t StartLogger(const TempDir& dir, const std::string& url, const std::string& name) {
  const std::string err = dir.file(name + ".err");
  const pid_t pid = test::Spawn("exec " + BinDir() + "/fl-logger --lcm-url='" + url +
                                "' --channel 'LASER|ODOMETRY' --flush-interval-ms 50 "
                                "--progress-interval-s 0.2 " +
                                dir.file(name) + " 2> " + err);
  EXPECT_TRUE(test::WaitFor([&] {
    return test::ReadFile(err).find("recording") != std::string::npos;
  })) << test::ReadFile(err);
  return pid;
}

int WaitExit(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  if (WIFSIGNALED(status)) return 1000 + WTERMSIG(status);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(FlLogger, LiveRecordingIsRenamedOnSigtermAndAKillLeavesOnlyThePartialFile) {
  LoopbackNetns netns;
  if (!netns.error().empty()) GTEST_SKIP() << netns.error();
  const std::string url = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=16777216";
  TempDir dir;
  auto lcm = MakeLcm(url);
  const std::vector<Message> sent = MakeMessages(60, 20000);
  auto publish = [&] {
    for (const Message& m : sent) {
      lcm->PublishRaw(m.channel, m.data.data(), static_cast<int>(m.data.size()), 0);
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  };

  // Stopped the way procman stops it.
  pid_t pid = StartLogger(dir, url, "run.lcmlog");
  publish();
  EXPECT_TRUE(test::WaitFor([&] {
    return SizeOf(dir.file("run.lcmlog.partial")) == LogBytes(sent);
  })) << SizeOf(dir.file("run.lcmlog.partial"))
      << " of " << LogBytes(sent) << " bytes flushed";
  EXPECT_FALSE(fs::exists(dir.file("run.lcmlog")));
  kill(pid, SIGTERM);
  EXPECT_EQ(WaitExit(pid), 0) << test::ReadFile(dir.file("run.lcmlog.err"));
  EXPECT_FALSE(fs::exists(dir.file("run.lcmlog.partial")));
  ExpectRecorded(ReadLog(dir.file("run.lcmlog")), sent);
  const std::string err = test::ReadFile(dir.file("run.lcmlog.err"));
  EXPECT_NE(err.find("events/s"), std::string::npos) << err;  // the progress line
  EXPECT_NE(err.find("recorded 48 events"), std::string::npos) << err;

  // Killed: OUTPUT.partial only, holding what was flushed.
  pid = StartLogger(dir, url, "killed.lcmlog");
  publish();
  EXPECT_TRUE(
      test::WaitFor([&] { return SizeOf(dir.file("killed.lcmlog.partial")) == LogBytes(sent); }));
  kill(pid, SIGKILL);
  EXPECT_EQ(WaitExit(pid), 1000 + SIGKILL);
  EXPECT_FALSE(fs::exists(dir.file("killed.lcmlog")));
  ExpectRecorded(ReadLog(dir.file("killed.lcmlog.partial")), sent);
  // A new logger on the same output does not overwrite that recording.
  const auto again = RunCommand(BinDir() + "/fl-logger --lcm-url='" + url + "' killed.lcmlog", dir);
  EXPECT_EQ(again.status, 1) << again.err;
  EXPECT_NE(again.err.find("'killed.lcmlog.partial' exists: an unfinished recording"),
            std::string::npos)
      << again.err;
}

}  // namespace
}  // namespace fl::logger
