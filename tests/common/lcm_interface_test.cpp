#include "fusionloc/common/lcm_interface.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <lcm/lcm-cpp.hpp>

#include "bot_core/planar_lidar_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "test_paths.hpp"

namespace fl {
namespace {

bot_core::planar_lidar_t MakeScan(int64_t utime, int n) {
  bot_core::planar_lidar_t m;
  m.utime = utime;
  m.nranges = n;
  m.ranges.assign(n, 1.5f);
  m.nintensities = 0;
  m.rad0 = -1.0f;
  m.radstep = 0.01f;
  return m;
}

TEST(LcmInterface, MemqPublishSubscribeTyped) {
  auto lcm = MakeLcm("memq://");
  std::vector<int64_t> got;
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER", [&](const bot_core::planar_lidar_t& m, const std::string& ch) {
        EXPECT_EQ(ch, "LASER");
        EXPECT_EQ(m.nranges, 10);
        got.push_back(m.utime);
      });
  for (int i = 0; i < 3; ++i) lcm->Publish("LASER", MakeScan(100 + i, 10));
  lcm->Publish("OTHER", MakeScan(999, 10));
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  EXPECT_EQ(got, (std::vector<int64_t>{100, 101, 102}));
  EXPECT_EQ(lcm->messages_published(), 4);
}

TEST(LcmInterface, MalformedMessageIsCountedNotDelivered) {
  auto lcm = MakeLcm("memq://");
  int delivered = 0;
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER", [&](const bot_core::planar_lidar_t&, const std::string&) { ++delivered; });
  // A wheel odometry message on the laser channel, and random bytes.
  fusionloc::wheel_odometry_t odo{};
  lcm->Publish("LASER", odo);
  const uint8_t junk[5] = {1, 2, 3, 4, 5};
  lcm->PublishRaw("LASER", junk, 5, 0);
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  EXPECT_EQ(delivered, 0);
  EXPECT_EQ(lcm->decode_errors(), 2);
}

// A decoded message with a NaN, infinite or absurd real field (message_checks.hpp) is counted
// and dropped before any handler; so the status carries lcm_invalid_values. A laser's beam
// without a return (an inf range) is not such a value.
TEST(LcmInterface, MessagesWithBadValuesAreCountedNotDelivered) {
  auto lcm = MakeLcm("memq://");
  std::vector<int64_t> got;
  lcm->Subscribe<fusionloc::wheel_odometry_t>(
      "ODOMETRY",
      [&](const fusionloc::wheel_odometry_t& m, const std::string&) { got.push_back(m.utime); });
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER",
      [&](const bot_core::planar_lidar_t& m, const std::string&) { got.push_back(m.utime); });
  fusionloc::wheel_odometry_t odo{};
  odo.utime = 1;
  lcm->Publish("ODOMETRY", odo);
  odo.utime = 2;
  odo.right_ticks = std::numeric_limits<double>::quiet_NaN();
  lcm->Publish("ODOMETRY", odo);
  odo.utime = 3;
  odo.right_ticks = 0.0;
  odo.theta = 1e30;
  lcm->Publish("ODOMETRY", odo);
  bot_core::planar_lidar_t scan = MakeScan(4, 10);
  scan.ranges[3] = std::numeric_limits<float>::infinity();
  lcm->Publish("LASER", scan);
  scan = MakeScan(5, 10);
  scan.rad0 = std::numeric_limits<float>::quiet_NaN();
  lcm->Publish("LASER", scan);
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  EXPECT_EQ(got, (std::vector<int64_t>{1, 4}));
  EXPECT_EQ(lcm->invalid_values(), 3);
  EXPECT_EQ(lcm->decode_errors(), 0);
}

// On a data-stream subscription (Duplicates::kDrop) a repeated message (the same bytes) is
// dropped and counted; a second such subscription to the channel still gets its own copy, and
// an older message identical to none of the recent ones passes. A default subscription (commands,
// orders) gets every message.
TEST(LcmInterface, DuplicateMessagesAreCountedNotDelivered) {
  auto lcm = MakeLcm("memq://");
  std::vector<int64_t> got, also, every;
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER",
      [&](const bot_core::planar_lidar_t& m, const std::string&) { got.push_back(m.utime); },
      LcmInterface::Duplicates::kDrop);
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER",
      [&](const bot_core::planar_lidar_t& m, const std::string&) { also.push_back(m.utime); },
      LcmInterface::Duplicates::kDrop);
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER",
      [&](const bot_core::planar_lidar_t& m, const std::string&) { every.push_back(m.utime); });
  lcm->Publish("LASER", MakeScan(100, 10));
  lcm->Publish("LASER", MakeScan(100, 10));  // duplicate
  lcm->Publish("LASER", MakeScan(101, 10));
  lcm->Publish("LASER", MakeScan(100, 10));  // a late duplicate
  lcm->Publish("LASER", MakeScan(100, 11));  // same stamp, other content: not a duplicate
  lcm->Publish("OTHER", MakeScan(100, 10));  // another channel: not a duplicate
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  EXPECT_EQ(got, (std::vector<int64_t>{100, 101, 100}));
  EXPECT_EQ(also, got);
  EXPECT_EQ(every, (std::vector<int64_t>{100, 100, 101, 100, 100}));
  EXPECT_EQ(lcm->duplicates_dropped(), 4);  // two per dropping subscription

  RecentMessages recent;
  const uint8_t a[3] = {1, 2, 3};
  EXPECT_FALSE(recent.SeenBefore("X", a, 3));
  EXPECT_TRUE(recent.SeenBefore("X", a, 3));
  EXPECT_FALSE(recent.SeenBefore("Y", a, 3));
  // After kKept other messages the first one is forgotten.
  for (uint8_t i = 10; i < 10 + RecentMessages::kKept; ++i) {
    const uint8_t b[3] = {i, i, i};
    EXPECT_FALSE(recent.SeenBefore("X", b, 3));
  }
  EXPECT_FALSE(recent.SeenBefore("X", a, 3));
}

TEST(LcmInterface, RegexSubscription) {
  auto lcm = MakeLcm("memq://");
  int n = 0;
  lcm->SubscribeRaw("STATUS_.*", [&](const std::string&, const void*, int, Utime) { ++n; });
  const uint8_t b = 0;
  lcm->PublishRaw("STATUS_SIM", &b, 1, 0);
  lcm->PublishRaw("STATUS_VO", &b, 1, 0);
  lcm->PublishRaw("XSTATUS_VO", &b, 1, 0);
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  EXPECT_EQ(n, 2);
}

TEST(LcmInterface, BadUrlIsAClearError) {
  try {
    MakeLcm("tcp://nowhere");
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("unsupported LCM URL 'tcp://nowhere'"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(MakeLcm("log:/no/such/file.lcmlog"), std::runtime_error);
}

TEST(LcmLog, WriteReadRoundTripAndLcmCompatibility) {
  test::TempDir dir;
  const std::string path = dir.file("a.lcmlog");
  {
    LcmLogWriter w(path);
    for (int i = 0; i < 5; ++i) w.Write("LASER", MakeScan(i * 100000, 20), i * 100000);
    // Until closed the log is written beside its final name, never passed off as whole.
    EXPECT_FALSE(std::filesystem::exists(path));
    w.Close();
  }
  ASSERT_TRUE(std::filesystem::exists(path));

  LcmLogReader r(path);
  LcmLogEvent e;
  int n = 0;
  while (r.Next(&e)) {
    EXPECT_EQ(e.channel, "LASER");
    EXPECT_EQ(e.utime, n * 100000);
    bot_core::planar_lidar_t m;
    EXPECT_EQ(m.decode(e.data.data(), 0, e.data.size()), static_cast<int>(e.data.size()));
    ++n;
  }
  EXPECT_EQ(n, 5);
  EXPECT_TRUE(r.ProblemSummary().empty());

  // LCM's own reader (the one lcm-logplayer uses) reads the same file.
  lcm::LogFile lf(path, "r");
  ASSERT_TRUE(lf.good());
  int m = 0;
  while (const lcm::LogEvent* ev = lf.readNextEvent()) {
    EXPECT_EQ(ev->channel, "LASER");
    ++m;
  }
  EXPECT_EQ(m, 5);
}

TEST(LcmLog, TruncatedAndCorruptLogsAreReported) {
  test::TempDir dir;
  const std::string path = dir.file("b.lcmlog");
  {
    LcmLogWriter w(path);
    for (int i = 0; i < 3; ++i) w.Write("LASER", MakeScan(i, 50), i);
  }
  const auto size = std::filesystem::file_size(path);
  // Corrupt: insert junk between events 1 and 2; truncate: cut the last event short.
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const size_t event_size = size / 3;
  std::string damaged = bytes.substr(0, event_size) + "JUNKJUNK" + bytes.substr(event_size);
  damaged.resize(damaged.size() - 10);
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << damaged;
  }
  LcmLogReader r(path);
  LcmLogEvent e;
  int n = 0;
  while (r.Next(&e)) ++n;
  EXPECT_EQ(n, 2);
  EXPECT_EQ(r.corrupt_bytes_skipped(), 8);
  EXPECT_TRUE(r.truncated());
  EXPECT_NE(r.ProblemSummary().find("truncated"), std::string::npos);
}

namespace {
std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
void WriteBytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
}
// Writes n equal-sized LASER events and returns the size of one.
size_t WriteScans(const std::string& path, int n) {
  {
    LcmLogWriter w(path);
    for (int i = 0; i < n; ++i) w.Write("LASER", MakeScan(i, 50), i);
  }
  return std::filesystem::file_size(path) / static_cast<size_t>(n);
}
std::vector<int64_t> ReadUtimes(LcmLogReader* r) {
  std::vector<int64_t> utimes;
  LcmLogEvent e;
  while (r->Next(&e)) utimes.push_back(e.utime);
  return utimes;
}
}  // namespace

TEST(LcmLog, DamageIsReportedWithItsByteOffset) {
  test::TempDir dir;
  const std::string path = dir.file("d.lcmlog");
  const size_t event = WriteScans(path, 5);
  std::string bytes = ReadBytes(path);
  // Overwrite the header of event 2 (its sync word and time) with junk.
  for (size_t i = 0; i < 12; ++i) bytes[2 * event + i] = 'X';
  WriteBytes(path, bytes);
  LcmLogReader r(path);
  EXPECT_EQ(ReadUtimes(&r), (std::vector<int64_t>{0, 1, 3, 4}));
  ASSERT_EQ(r.damage().size(), 1u);
  EXPECT_EQ(r.damage()[0].offset, static_cast<int64_t>(2 * event));
  EXPECT_EQ(r.damage()[0].bytes, static_cast<int64_t>(event));
  EXPECT_FALSE(r.truncated());
  EXPECT_NE(r.ProblemSummary().find("byte offset " + std::to_string(2 * event)),
            std::string::npos)
      << r.ProblemSummary();
}

TEST(LcmLog, DamagedLengthDoesNotSwallowTheFollowingEvents) {
  test::TempDir dir;
  const std::string path = dir.file("l.lcmlog");
  const size_t event = WriteScans(path, 5);
  std::string bytes = ReadBytes(path);
  // Event 1 claims three events' worth of data (its data length field, bytes 24..27).
  const uint32_t claimed = static_cast<uint32_t>(3 * event);
  for (int k = 0; k < 4; ++k) {
    bytes[event + 24 + static_cast<size_t>(k)] = static_cast<char>((claimed >> (24 - 8 * k)) & 0xff);
  }
  WriteBytes(path, bytes);
  LcmLogReader r(path);
  EXPECT_EQ(ReadUtimes(&r), (std::vector<int64_t>{0, 2, 3, 4}));
  ASSERT_EQ(r.damage().size(), 1u);
  EXPECT_EQ(r.damage()[0].offset, static_cast<int64_t>(event));
}

TEST(LcmLog, TruncationIsReportedWhereTheLastEventStarts) {
  test::TempDir dir;
  const std::string path = dir.file("t.lcmlog");
  const size_t event = WriteScans(path, 4);
  for (const size_t cut : {size_t{3}, size_t{20}, event / 2, event - 1}) {
    const std::string whole = ReadBytes(path);
    const std::string cut_path = dir.file("cut.lcmlog");
    WriteBytes(cut_path, whole.substr(0, 3 * event + cut));
    LcmLogReader r(cut_path);
    EXPECT_EQ(ReadUtimes(&r), (std::vector<int64_t>{0, 1, 2})) << "cut " << cut;
    EXPECT_TRUE(r.truncated()) << "cut " << cut;
    EXPECT_EQ(r.truncated_at(), static_cast<int64_t>(3 * event)) << "cut " << cut;
    EXPECT_EQ(r.corrupt_bytes_skipped(), 0) << "cut " << cut;
    EXPECT_TRUE(r.damage().empty()) << "cut " << cut;
    EXPECT_NE(r.ProblemSummary().find("truncated at byte offset " + std::to_string(3 * event)),
              std::string::npos)
        << r.ProblemSummary();
  }
}

TEST(LcmLog, ReplayDispatchesAndWritesOutputsWithLogTime) {
  test::TempDir dir;
  const std::string in = dir.file("in.lcmlog"), out = dir.file("out.lcmlog");
  {
    LcmLogWriter w(in);
    for (int i = 0; i < 4; ++i) w.Write("LASER", MakeScan(1000 + i, 5), 1000 + i);
    w.Write("ODOM", fusionloc::wheel_odometry_t{}, 2000);
  }
  {
    auto lcm = MakeLcm("log:" + in + "," + out);
    int scans = 0;
    lcm->Subscribe<bot_core::planar_lidar_t>(
        "LASER", [&](const bot_core::planar_lidar_t& m, const std::string&) {
          ++scans;
          fusionloc::wheel_odometry_t echo{};
          echo.utime = m.utime;
          lcm->Publish("ECHO", echo, 0);
        });
    while (lcm->HandleSubscriptions(0) >= 0) {
    }
    EXPECT_EQ(scans, 4);
    EXPECT_EQ(lcm->messages_received(), 5);
  }
  LcmLogReader r(out);
  LcmLogEvent e;
  std::vector<Utime> times;
  while (r.Next(&e)) {
    EXPECT_EQ(e.channel, "ECHO");
    times.push_back(e.utime);
  }
  EXPECT_EQ(times, (std::vector<Utime>{1000, 1001, 1002, 1003}));
}

TEST(LcmLog, AbandonLeavesNoFile) {
  test::TempDir dir;
  const std::string path = dir.file("c.lcmlog");
  LcmLogWriter w(path);
  w.Write("X", "abc", 3, 0);
  w.Abandon();
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
}

}  // namespace
}  // namespace fl
