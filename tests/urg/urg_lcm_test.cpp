// UrgDriverNode: what fl-urg-driver publishes (LASER, STATUS_FL_URG_DRIVER) from the emulated
// URG-04LX, on an in-process LCM.
#include "fusionloc/urg/urg_lcm.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <thread>

#include "fusionloc/status_t.hpp"
#include "fusionloc/urg/urg_emulator.hpp"
#include "test_paths.hpp"

namespace fl::urg {
namespace {

TEST(UrgDriverNode, PublishesScansInMetresAndTheSensorInTheStatus) {
  test::TempDir dir;
  UrgEmulatorOptions eo;
  eo.link = dir.file("hokuyo");
  UrgEmulator emu(eo);
  ASSERT_TRUE(emu.Start().ok());
  auto lcm = MakeLcm("memq://");
  std::vector<bot_core::planar_lidar_t> scans;
  std::vector<fusionloc::status_t> statuses;
  lcm->SubscribeRaw("LASER", [&](const std::string&, const void* data, int size, Utime) {
    bot_core::planar_lidar_t m;
    ASSERT_GT(m.decode(data, 0, size), 0);
    scans.push_back(m);
  });
  lcm->SubscribeRaw("STATUS_FL_URG_DRIVER",
                    [&](const std::string&, const void* data, int size, Utime) {
                      fusionloc::status_t m;
                      ASSERT_GT(m.decode(data, 0, size), 0);
                      statuses.push_back(m);
                    });
  UrgDriverOptions o;
  o.port = eo.link;
  {
    UrgDriverNode node(o, lcm.get(), ChannelMap());
    const auto start = std::chrono::steady_clock::now();
    const auto end = start + std::chrono::milliseconds(2500);
    bool injected = false;
    while (std::chrono::steady_clock::now() < end) {
      if (!injected && std::chrono::steady_clock::now() > start + std::chrono::milliseconds(400)) {
        emu.InjectChecksumErrors(1);
        injected = true;
      }
      lcm->HandleSubscriptions(50);
      node.Poll();
      node.status().Tick();
    }
    node.Finish();
    node.status().Tick(true);
    lcm->HandleSubscriptions(0);
    EXPECT_NE(node.Summary().find("scans "), std::string::npos);
  }
  lcm->HandleSubscriptions(0);
  ASSERT_GE(scans.size(), 8u);
  const bot_core::planar_lidar_t& s = scans.back();
  EXPECT_EQ(s.nranges, 682);
  EXPECT_EQ(s.nintensities, 0);
  EXPECT_FLOAT_EQ(s.rad0, static_cast<float>(-340 * 2 * M_PI / 1024));
  EXPECT_FLOAT_EQ(s.radstep, static_cast<float>(2 * M_PI / 1024));
  EXPECT_NEAR(static_cast<double>(s.utime), static_cast<double>(NowUtime()), 3e6);
  for (float r : s.ranges) {
    EXPECT_TRUE(r == 0.0f || (r >= 0.02f && r <= 5.6f)) << r;
  }
  ASSERT_FALSE(statuses.empty());
  const fusionloc::status_t& st = statuses.back();
  EXPECT_EQ(st.process, "fl-urg-driver");
  EXPECT_NE(st.message.find("URG-04LX serial H0614967"), std::string::npos) << st.message;
  EXPECT_NE(st.message.find(eo.link), std::string::npos) << st.message;
  std::map<std::string, double> values;
  for (int i = 0; i < st.num_keys; ++i) values[st.keys[i]] = st.values[i];
  for (const char* k : {"reconnects", "checksum_errors", "residual_ms", "skew_ppm", "scans"}) {
    EXPECT_TRUE(values.count(k)) << k;
  }
  EXPECT_EQ(values["reconnects"], 0.0);
  EXPECT_EQ(values["checksum_errors"], 1.0);
  // The dropped scan shows as a warning that names it.
  bool warned = false;
  for (const auto& x : statuses) {
    if (x.level == fusionloc::status_t::LEVEL_WARN &&
        x.message.find("checksum error") != std::string::npos)
      warned = true;
  }
  EXPECT_TRUE(warned);
  EXPECT_GE(values["scans"], 8.0);
}

TEST(UrgDriverNode, AFirstConnectionFailureThrowsTheMessage) {
  auto lcm = MakeLcm("memq://");
  UrgDriverOptions o;
  o.port = "/dev/null";
  try {
    UrgDriverNode node(o, lcm.get(), ChannelMap());
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("'/dev/null': not a serial device"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace fl::urg
