// UrgSensor's command/response state machine against the emulated URG-04LX on a pty, and
// against canned bytes for malformed replies.
#include "fusionloc/urg/urg_sensor.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <deque>

#include "fusionloc/urg/urg_emulator.hpp"
#include "test_paths.hpp"

namespace fl::urg {
namespace {

struct Rig {
  explicit Rig(UrgEmulatorOptions eo = {}, SensorOptions so = {}) : emu(eo) {
    EXPECT_TRUE(emu.Start().ok());
    EXPECT_TRUE(port.Open(emu.device_path(), 115200).ok());
    sensor = std::make_unique<UrgSensor>(so, &port);
  }
  UrgEmulator emu;
  SerialPort port;
  std::unique_ptr<UrgSensor> sensor;
};

TEST(UrgSensor, ConnectReadsTheUrg04lxParameters) {
  Rig rig;
  ASSERT_TRUE(rig.sensor->Connect().ok());
  const SensorInfo& i = rig.sensor->info();
  EXPECT_EQ(i.product, "SOKUIKI Sensor URG-04LX");
  EXPECT_EQ(i.serial, "H0614967");
  EXPECT_EQ(i.protocol, "SCIP 2.0");
  EXPECT_EQ(i.dmin_mm, 20);
  EXPECT_EQ(i.dmax_mm, 5600);
  EXPECT_EQ(i.ares, 1024);
  EXPECT_EQ(i.amin, 44);
  EXPECT_EQ(i.amax, 725);
  EXPECT_EQ(i.afrt, 384);
  EXPECT_EQ(i.scan_rpm, 600);
  EXPECT_EQ(i.status.at("LASR"), "OFF");
  EXPECT_EQ(i.Describe(), "URG-04LX serial H0614967, firmware 3.1.00(18/Jan./2007)");
  EXPECT_NEAR(i.StepAngle(44), -119.53125 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(i.StepAngle(725), 119.8828125 * M_PI / 180.0, 1e-12);
}

TEST(UrgSensor, ASensorInScip11IsSwitchedToScip20) {
  UrgEmulatorOptions eo;
  eo.scip1_at_power_on = true;
  SensorOptions so;
  so.reply_timeout_s = 0.3;
  Rig rig(eo, so);
  EXPECT_FALSE(rig.emu.in_scip2());
  ASSERT_TRUE(rig.sensor->Connect().ok());
  EXPECT_TRUE(rig.emu.in_scip2());
  EXPECT_EQ(rig.sensor->info().amax, 725);
}

TEST(UrgSensor, AWrongModelIsNamedWithTheFix) {
  UrgEmulatorOptions eo;
  eo.product = "SOKUIKI Sensor UTM-30LX";
  eo.model = "UTM-30LX";
  Rig rig(eo);
  const Status s = rig.sensor->Connect();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'" + rig.emu.device_path() + "'"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("VV says product 'SOKUIKI Sensor UTM-30LX'"), std::string::npos)
      << s.message();
  EXPECT_NE(s.message().find("set model: \"\""), std::string::npos) << s.message();
  // Told to accept any model, the same sensor connects.
  SensorOptions any;
  any.model = "";
  UrgSensor sensor(any, &rig.port);
  EXPECT_TRUE(sensor.Connect().ok());
}

TEST(UrgSensor, NotScip2IsRefused) {
  UrgEmulatorOptions eo;
  eo.protocol = "SCIP 1.1";
  Rig rig(eo);
  const Status s = rig.sensor->Connect();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("this driver speaks SCIP 2.0"), std::string::npos) << s.message();
}

TEST(UrgSensor, TmRecoversTheSensorClockOffset) {
  UrgEmulatorOptions eo;
  eo.clock_start_ms = 12'345'678;
  Rig rig(eo);
  ASSERT_TRUE(rig.sensor->Connect().ok());
  ClockSync sync{ClockSyncOptions{}};
  ASSERT_TRUE(rig.sensor->SyncTime(&sync).ok());
  ASSERT_TRUE(sync.synced());
  const Utime now = NowUtime();
  // Host time of the sensor's current reading vs. now: within the TM round trip + 1 ms tick.
  EXPECT_NEAR(static_cast<double>(sync.ToHost(rig.emu.SensorMs(now))), static_cast<double>(now),
              1000.0 + 1000.0 * sync.tm_round_trip_ms());
  // TM1 outside the adjust mode is an error status, reported as such.
  scip2::Response r;
  ASSERT_TRUE(rig.sensor->Command("TM1\n", &r).ok());
  std::string status;
  ASSERT_TRUE(scip2::ParseStatus(r, &status).ok());
  EXPECT_EQ(status, "04");
}

TEST(UrgSensor, StreamsWithRemainingScansAndMs2CharEncoding) {
  Rig rig;
  ASSERT_TRUE(rig.sensor->Connect().ok());
  scip2::ScanCommand c;
  c.encoding = 2;
  c.scans = 3;
  c.cluster = 2;
  ASSERT_TRUE(rig.sensor->StartStreaming(c).ok());
  std::vector<int> remaining;
  for (int k = 0; k < 3; ++k) {
    Scan scan;
    std::string msg;
    ASSERT_EQ(rig.sensor->ReadScan(&scan, 1000, &msg), ReadResult::kScan) << msg;
    remaining.push_back(scan.remaining);
    EXPECT_EQ(scan.values.size(), 341u);
    EXPECT_EQ(scan.command.encoding, 2);
    for (uint32_t v : scan.values) EXPECT_LE(v, 4095u);
  }
  EXPECT_EQ(remaining, (std::vector<int>{2, 1, 0}));
  Scan scan;
  std::string msg;
  EXPECT_EQ(rig.sensor->ReadScan(&scan, 300, &msg), ReadResult::kTimeout);  // the stream ended
}

TEST(UrgSensor, GdNeedsTheLaserThenGivesOneScan) {
  Rig rig;
  ASSERT_TRUE(rig.sensor->Connect().ok());
  scip2::ScanCommand c;
  ASSERT_TRUE(rig.sensor->RequestScan(c).ok());
  Scan scan;
  std::string msg;
  ASSERT_EQ(rig.sensor->ReadScan(&scan, 1000, &msg), ReadResult::kDeviceError);
  EXPECT_NE(msg.find("status 10: laser is off (send BM first)"), std::string::npos) << msg;
  ASSERT_TRUE(rig.sensor->LaserOn().ok());
  ASSERT_TRUE(rig.sensor->RequestScan(c).ok());
  ASSERT_EQ(rig.sensor->ReadScan(&scan, 1000, &msg), ReadResult::kScan) << msg;
  EXPECT_EQ(scan.values.size(), 682u);
  ASSERT_TRUE(rig.sensor->Stop().ok());
}

TEST(UrgSensor, BaudChangeResetAndOutOfRangeSteps) {
  Rig rig;
  ASSERT_TRUE(rig.sensor->Connect().ok());
  EXPECT_TRUE(rig.sensor->ChangeBaud(115200).ok());
  EXPECT_TRUE(rig.sensor->ChangeBaud(115200).ok());  // 03: already at this rate
  EXPECT_FALSE(rig.sensor->ChangeBaud(9600).ok());
  EXPECT_TRUE(rig.sensor->Reset().ok());
  scip2::ScanCommand c;
  c.end_step = 800;
  const Status s = rig.sensor->StartStreaming(c);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("status 04: End Step is out of range"), std::string::npos)
      << s.message();
}

// Canned bytes: what a broken or foreign device might send.
class CannedStream : public ByteStream {
 public:
  explicit CannedStream(std::deque<std::string> replies) : replies_(std::move(replies)) {}
  Status Write(std::string_view) override {
    if (!replies_.empty()) {
      pending_ += replies_.front();
      replies_.pop_front();
    }
    return Status::Ok();
  }
  int Read(char* buffer, int size, int, std::string*) override {
    const int n = std::min<int>(size, static_cast<int>(pending_.size()));
    std::copy(pending_.begin(), pending_.begin() + n, buffer);
    pending_.erase(0, static_cast<size_t>(n));
    return n;
  }
  std::string name() const override { return "/dev/canned"; }

 private:
  std::deque<std::string> replies_;
  std::string pending_;
};

TEST(UrgSensor, AMalformedReplyIsAClearError) {
  CannedStream stream({"QT\n00P\n\n", "VV\n00P\nVEND Hokuyo\n\n"});
  UrgSensor sensor(SensorOptions{}, &stream);
  const Status s = sensor.Connect();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'/dev/canned': malformed line 'VEND Hokuyo' in the reply to VV"),
            std::string::npos)
      << s.message();
}

TEST(UrgSensor, ADeviceThatDoesNotAnswerIsNamed) {
  CannedStream stream({});
  SensorOptions o;
  o.reply_timeout_s = 0.1;
  UrgSensor sensor(o, &stream);
  const Status s = sensor.Connect();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'/dev/canned' does not answer QT or SCIP2.0"), std::string::npos)
      << s.message();
}

}  // namespace
}  // namespace fl::urg
