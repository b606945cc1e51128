#include "fusionloc/importers/log_info.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "importer_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::importers {
namespace {

using fl::test::TempDir;

const ChannelInfo& Find(const LogInfo& info, const std::string& channel) {
  for (const auto& c : info.channels) {
    if (c.channel == channel) return c;
  }
  throw std::runtime_error("no channel " + channel);
}

TEST(LogInfoTest, KnowsEveryProjectTypeByFingerprint) {
  const int64_t lidar = bot_core::planar_lidar_t::getHash();
  EXPECT_EQ(LcmTypeName(lidar), "bot_core.planar_lidar_t");
  EXPECT_EQ(LcmTypeName(fusionloc::wheel_odometry_t::getHash()), "fusionloc.wheel_odometry_t");
  EXPECT_EQ(LcmTypeName(0x0123456789abcdefLL), "unknown (0x0123456789abcdef)");
  EXPECT_GE(KnownLcmTypes().size(), 14u);  // every lcmtypes/*/*.lcm at the time of writing
  for (const auto& t : KnownLcmTypes()) EXPECT_EQ(FindLcmType(t.fingerprint), &t) << t.name;
}

// Found by fuzzing (tests/fuzz/regressions/lcm_log/utime-span-overflow): time stamps far apart
// (a corrupt or hostile log) made the span overflow int64 (undefined behaviour); it is the
// right, positive number of seconds.
TEST(LogInfoTest, SpanOfFarApartTimeStampsDoesNotOverflow) {
  TempDir dir;
  const std::string path = dir.file("far.lcmlog");
  {
    LcmLogWriter w(path);
    bot_core::pose_t pose{};
    w.Write("POSE", pose, -9000000000000000000LL);
    w.Write("POSE", pose, 9000000000000000000LL);
    w.Close();
  }
  const LogInfo info = InspectLcmLog(path);
  ASSERT_EQ(info.events, 2);
  EXPECT_NE(info.ToText().find("(span 18000000000000.000 s)"), std::string::npos) << info.ToText();
  EXPECT_NE(info.ToJson().find("\"span_s\": 1.8e+13"), std::string::npos) << info.ToJson();
  ASSERT_EQ(info.channels.size(), 1u);
  EXPECT_NEAR(info.channels[0].rate_hz(), 1.0 / 1.8e13, 1e-20);
}

TEST(LogInfoTest, CountsRatesTypesAndProblems) {
  TempDir dir;
  const std::string path = dir.file("a.lcmlog");
  {
    LcmLogWriter w(path);
    bot_core::planar_lidar_t scan{};
    scan.nranges = 3;
    scan.ranges = {1, 2, 3};
    for (int i = 0; i < 11; ++i) w.Write("LASER", scan, 1000000 + 100000 * i);  // 10 Hz, 1 s
    bot_core::pose_t pose{};
    w.Write("POSE", pose, 1000000);
    w.Write("POSE", pose, 3000000);
    w.Write("POSE", pose, 2000000);  // backwards on its channel and in the log
    const uint8_t unknown[12] = {0x01, 0x23, 0x45, 0x67, 0x89, 0xab, 0xcd, 0xef, 1, 2, 3, 4};
    w.Write("MYSTERY", unknown, 12, 3000000);
    // A lidar message cut short: the fingerprint says planar_lidar_t, the bytes do not decode.
    std::vector<uint8_t> bytes(static_cast<size_t>(scan.getEncodedSize()));
    scan.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
    w.Write("LASER", bytes.data(), static_cast<int>(bytes.size()) - 4, 3000000);
    w.Write("TINY", bytes.data(), 3, 3000000);
    w.Close();
  }
  const LogInfo info = InspectLcmLog(path);
  EXPECT_EQ(info.events, 11 + 3 + 1 + 1 + 1);
  EXPECT_EQ(info.first_utime, 1000000);
  EXPECT_EQ(info.last_utime, 3000000);
  EXPECT_EQ(info.time_backwards, 2);  // POSE at 1 s after LASER at 2 s; POSE 3 s -> 2 s
  EXPECT_FALSE(info.truncated);
  const ChannelInfo& laser = Find(info, "LASER");
  EXPECT_EQ(laser.type, "bot_core.planar_lidar_t");
  EXPECT_EQ(laser.count, 12);
  EXPECT_EQ(laser.decode_errors, 1);
  EXPECT_EQ(laser.other_type_count, 0);
  const ChannelInfo& pose = Find(info, "POSE");
  EXPECT_EQ(pose.type, "bot_core.pose_t");
  EXPECT_EQ(pose.time_backwards, 1);
  EXPECT_NEAR(pose.rate_hz(), 1.0, 1e-12);  // 3 messages over 2 s
  EXPECT_EQ(Find(info, "MYSTERY").type, "unknown (0x0123456789abcdef)");
  EXPECT_EQ(Find(info, "MYSTERY").decode_errors, 0);  // unknown types cannot be checked
  EXPECT_EQ(Find(info, "TINY").type, "too short (< 8 bytes)");
  EXPECT_TRUE(info.has_problems());
  const std::string text = info.ToText();
  EXPECT_NE(text.find("LASER: 1 messages carry a known fingerprint but do not decode"),
            std::string::npos)
      << text;
  const std::string json = info.ToJson();
  EXPECT_NE(json.find("\"channel\": \"MYSTERY\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"has_problems\": true"), std::string::npos) << json;
}

TEST(LogInfoTest, ReportsTruncationAndCorruptBytes) {
  TempDir dir;
  const std::string path = dir.file("b.lcmlog");
  {
    LcmLogWriter w(path);
    fusionloc::wheel_odometry_t odo{};
    for (int i = 0; i < 5; ++i) w.Write("ODOMETRY", odo, 1000 * i);
    w.Close();
  }
  std::string bytes = fl::test::ReadFileBytes(path);
  const size_t event = bytes.size() / 5;
  // Garbage between events 2 and 3, and the last event cut short.
  bytes.insert(2 * event, "garbage!");
  bytes.resize(bytes.size() - 10);
  fl::test::WriteText(path, bytes);
  const LogInfo info = InspectLcmLog(path);
  EXPECT_EQ(Find(info, "ODOMETRY").count, 4);
  EXPECT_TRUE(info.truncated);
  EXPECT_EQ(info.corrupt_bytes_skipped, 8);
  EXPECT_TRUE(info.has_problems());
  EXPECT_NE(info.ToText().find("truncated"), std::string::npos);
}

TEST(LogInfoTest, CleanLogHasNoProblemsAndMissingLogThrows) {
  TempDir dir;
  {
    LcmLogWriter w(dir.file("c.lcmlog"));
    w.Close();
  }
  const LogInfo empty = InspectLcmLog(dir.file("c.lcmlog"));
  EXPECT_EQ(empty.events, 0);
  EXPECT_FALSE(empty.has_problems());
  EXPECT_THROW(InspectLcmLog(dir.file("missing.lcmlog")), std::runtime_error);
}

}  // namespace
}  // namespace fl::importers
