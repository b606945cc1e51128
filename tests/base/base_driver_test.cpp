// The base driver against the emulated Kobuki on a pseudo-terminal: odometry against the
// emulated motion through injected checksum errors and noise, the watchdog stopping the
// wheels, reconnecting after the device vanishes, the LCM node, and bad ports.
#include "fusionloc/base/base_driver.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

#include "fusionloc/base/base_driver_lcm.hpp"
#include "fusionloc/base/kobuki_emulator.hpp"
#include "fusionloc/serial/pty.hpp"
#include "fusionloc/serial/serial_port.hpp"
#include "test_paths.hpp"

namespace fl::base {
namespace {

using fl::test::BinDir;
using fl::test::RunCommand;
using fl::test::TempDir;

const BaseGeometry kKobuki{0.035, 0.230, 2578.33};

// Spins the driver for `seconds`, commanding (v, omega) every 50 ms if `command`.
void SpinFor(BaseDriver* driver, double seconds, bool command, double v, double omega,
             std::vector<OdometrySample>* out) {
  const Utime end = MonotonicUtime() + SecondsToUtime(seconds);
  Utime next_command = 0;
  while (MonotonicUtime() < end) {
    if (command && MonotonicUtime() >= next_command) {
      driver->Command(MonotonicUtime(), v, omega);
      next_command = MonotonicUtime() + 50000;
    }
    driver->Spin(5, out);
  }
}

TEST(BaseDriver, OdometryMatchesTheEmulatedMotionThroughFaults) {
  KobukiEmulatorOptions eo;
  eo.checksum_error_rate = 0.05;
  eo.noise_rate = 0.05;
  KobukiEmulator emulator(eo);
  BaseDriverOptions o;
  o.port = emulator.device();
  BaseDriver driver(o, kKobuki);
  std::vector<OdometrySample> samples;
  SpinFor(&driver, 0.3, false, 0, 0, &samples);  // at rest: the odometry frame = start frame
  const Pose2 start = emulator.pose();
  EXPECT_EQ(start.x, 0.0);
  SpinFor(&driver, 2.5, true, 0.25, 0.8, &samples);  // an arc of R = 0.3125 m
  SpinFor(&driver, 0.5, true, 0.0, 0.0, &samples);   // stop, and let the last packets in
  ASSERT_FALSE(samples.empty());
  const Pose2 truth = emulator.pose();
  const OdometrySample& last = samples.back();
  EXPECT_GT(std::hypot(truth.x, truth.y), 0.4);  // it did move
  EXPECT_NEAR(last.x, truth.x, 1e-3);
  EXPECT_NEAR(last.y, truth.y, 1e-3);
  EXPECT_NEAR(last.theta, truth.theta, 2e-3);
  const BaseDriverStats& st = driver.stats();
  EXPECT_GT(st.bad_checksums, 0);  // the injected errors were seen and dropped
  EXPECT_GT(st.skipped_bytes, 0);
  EXPECT_GE(st.packets + st.bad_checksums + st.malformed, emulator.packets_sent() * 9 / 10);
  // About 50 Hz of odometry over 3.3 s, less the corrupted packets.
  EXPECT_GT(samples.size(), 120u);
  EXPECT_LT(samples.size(), 180u);
  std::cout << "final pose error: dx " << (last.x - truth.x) * 1e3 << " mm, dy "
            << (last.y - truth.y) * 1e3 << " mm, dtheta " << (last.theta - truth.theta)
            << " rad; bad checksums " << st.bad_checksums << " of " << emulator.packets_sent()
            << " packets\n";
}

TEST(BaseDriver, WatchdogStopsTheWheelsWhenCommandsStop) {
  KobukiEmulator emulator(KobukiEmulatorOptions{});
  BaseDriverOptions o;
  o.port = emulator.device();
  o.command_timeout_s = 0.5;
  BaseDriver driver(o, kKobuki);
  std::vector<OdometrySample> samples;
  SpinFor(&driver, 0.6, true, 0.3, 0.0, &samples);
  EXPECT_NEAR(emulator.wheels().left, 0.3, 1e-9);  // driving
  const double t_last_command = emulator.time_s();
  SpinFor(&driver, 1.2, false, 0, 0, &samples);  // commands stop; the driver keeps running
  EXPECT_EQ(emulator.wheels().left, 0.0);
  EXPECT_EQ(emulator.wheels().right, 0.0);
  const double stop_delay = emulator.last_stop_time_s() - t_last_command;
  // Timeout 0.5 s, plus up to one command period (50 ms), the last command's age (< 50 ms)
  // and scheduling slack.
  EXPECT_GT(stop_delay, 0.4);
  EXPECT_LT(stop_delay, 0.75);
  EXPECT_EQ(driver.stats().watchdog_stops, 1);
  EXPECT_LT(std::abs(samples.back().v), 1e-9);  // the odometry says stopped too
  std::cout << "wheels stopped " << stop_delay << " s after the last command\n";
}

TEST(BaseDriver, ReconnectsWhenTheDeviceComesBack) {
  TempDir dir;
  const std::string link = dir.file("kobuki");
  auto emulator = std::make_unique<KobukiEmulator>(KobukiEmulatorOptions{});
  std::filesystem::create_symlink(emulator->device(), link);
  BaseDriverOptions o;
  o.port = link;
  o.reconnect_interval_s = 0.2;
  BaseDriver driver(o, kKobuki);
  std::vector<OdometrySample> samples;
  SpinFor(&driver, 0.3, false, 0, 0, &samples);
  EXPECT_TRUE(driver.stats().connected);
  emulator.reset();  // the device vanishes
  std::filesystem::remove(link);
  SpinFor(&driver, 0.3, false, 0, 0, &samples);
  EXPECT_FALSE(driver.stats().connected);
  EXPECT_NE(driver.problem().find(link), std::string::npos) << driver.problem();
  emulator = std::make_unique<KobukiEmulator>(KobukiEmulatorOptions{});  // and comes back
  std::filesystem::create_symlink(emulator->device(), link);
  samples.clear();
  SpinFor(&driver, 0.8, false, 0, 0, &samples);
  EXPECT_TRUE(driver.stats().connected);
  EXPECT_EQ(driver.stats().reconnects, 1);
  EXPECT_GT(samples.size(), 5u);  // odometry flows again
}

TEST(BaseDriver, NodePublishesOdometryAndTakesCommandsOverLcm) {
  KobukiEmulator emulator(KobukiEmulatorOptions{});
  auto lcm = fl::MakeLcm("memq://");
  BaseDriverOptions o;
  o.port = emulator.device();
  BaseDriverNode node(o, kKobuki, lcm.get(), ChannelMap());
  std::vector<fusionloc::wheel_odometry_t> odometry;
  lcm->Subscribe<fusionloc::wheel_odometry_t>(
      "ODOMETRY",
      [&](const fusionloc::wheel_odometry_t& m, const std::string&) { odometry.push_back(m); });
  auto drive = [&](double seconds, double v) {
    const Utime end = MonotonicUtime() + SecondsToUtime(seconds);
    while (MonotonicUtime() < end) {
      fusionloc::base_command_t cmd{};
      cmd.v = v;
      cmd.omega = 0.0;
      lcm->Publish("BASE_COMMAND", cmd);
      node.Step(5);
    }
  };
  drive(0.3, 0.0);  // at rest first: the odometry frame is the pose at the first reading
  drive(1.0, 0.2);
  ASSERT_GT(odometry.size(), 30u);
  EXPECT_NEAR(odometry.back().v, 0.2, 0.01);
  drive(0.3, 0.0);
  EXPECT_GT(odometry.back().x, 0.15);
  EXPECT_GT(odometry.back().utime, odometry.front().utime);
  EXPECT_NEAR(odometry.back().x, emulator.pose().x, 2e-3);
  EXPECT_EQ(node.published(), static_cast<int64_t>(odometry.size()));
}

TEST(BaseDriver, AnotherDeviceOnThePortIsNamed) {
  fl::serial::Pty pty;  // speaks SCIP text (a Hokuyo), not the Kobuki protocol
  BaseDriverOptions o;
  o.port = pty.slave_path();
  auto lcm = fl::MakeLcm("memq://");
  BaseDriverNode node(o, kKobuki, lcm.get(), ChannelMap());
  const std::string scip = "VV\n00P\nVEND:Hokuyo Automatic Co.,Ltd.;[\nPROD:URG-04LX;[\n\n";
  const Utime end = MonotonicUtime() + 500000;
  while (MonotonicUtime() < end) {
    pty.Write(reinterpret_cast<const uint8_t*>(scip.data()), scip.size());
    node.Step(5);
  }
  EXPECT_EQ(node.driver().stats().packets, 0);
  EXPECT_TRUE(node.driver().stats().not_a_kobuki);
  EXPECT_NE(node.status().message().find("none is a Kobuki packet"), std::string::npos)
      << node.status().message();
  EXPECT_EQ(node.published(), 0);
}

TEST(SerialPort, ClearErrorsForBadPorts) {
  TempDir dir;
  try {
    fl::serial::SerialPort p(dir.file("no_such_tty"), 115200);
    FAIL() << "opened a missing port";
  } catch (const fl::serial::SerialError& e) {
    EXPECT_NE(std::string(e.what()).find("no such device"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no_such_tty"), std::string::npos) << e.what();
  }
  std::ofstream(dir.file("plain")) << "x";
  try {
    fl::serial::SerialPort p(dir.file("plain"), 115200);
    FAIL() << "opened a regular file";
  } catch (const fl::serial::SerialError& e) {
    EXPECT_NE(std::string(e.what()).find("not a serial port (not a tty)"), std::string::npos)
        << e.what();
  }
  KobukiEmulator emulator(KobukiEmulatorOptions{});
  EXPECT_THROW(fl::serial::SerialPort(emulator.device(), 12345), fl::serial::SerialError);
  // Permission denied names the group and the udev rule (provoked for real when not root).
  const std::string denied = fl::serial::OpenErrorMessage("/dev/kobuki", EACCES);
  EXPECT_NE(denied.find("dialout"), std::string::npos);
  EXPECT_NE(denied.find("config/udev/"), std::string::npos);
  if (geteuid() != 0) {
    std::ofstream(dir.file("locked")) << "x";
    std::filesystem::permissions(dir.file("locked"), std::filesystem::perms::none);
    try {
      fl::serial::SerialPort p(dir.file("locked"), 115200);
      FAIL();
    } catch (const fl::serial::SerialError& e) {
      EXPECT_NE(std::string(e.what()).find("permission denied"), std::string::npos);
    }
  }
}

TEST(BaseDriverProgram, BadPortAndMissingRobotExitWithTheFix) {
  TempDir dir;
  const std::string robot = fl::test::SourceDir() + "/config/robot/turtlebot2.yaml";
  const auto not_tty = RunCommand(
      BinDir() + "/fl-base-driver --lcm-url memq:// --robot " + robot + " --port /etc/hostname",
      dir);
  EXPECT_EQ(not_tty.status, 1) << not_tty.err;
  EXPECT_NE(not_tty.err.find("'/etc/hostname': not a serial port"), std::string::npos)
      << not_tty.err;
  const auto missing = RunCommand(
      BinDir() + "/fl-base-driver --lcm-url memq:// --robot " + robot + " --port /dev/nokobuki",
      dir);
  EXPECT_EQ(missing.status, 1) << missing.err;
  EXPECT_NE(missing.err.find("/dev/nokobuki': no such device: is it plugged in"), std::string::npos)
      << missing.err;
  const auto no_robot = RunCommand(BinDir() + "/fl-base-driver --lcm-url memq://", dir);
  EXPECT_EQ(no_robot.status, 2) << no_robot.err;
  EXPECT_NE(no_robot.err.find("--robot config/robot/turtlebot2.yaml"), std::string::npos);
  {
    std::ofstream bad(dir.file("robot.yaml"));
    bad << "base:\n  wheel_radius_m: 0.035\n  track_m: 0.23\n  tick_per_revolution: 2578\n";
  }
  const auto typo = RunCommand(BinDir() + "/fl-base-driver --robot robot.yaml", dir);
  EXPECT_EQ(typo.status, 2) << typo.err;
  EXPECT_NE(typo.err.find("unknown key 'base.tick_per_revolution'"), std::string::npos) << typo.err;
}

TEST(BaseDriverProgram, DriverRunsAgainstTheEmulatorProgram) {
  TempDir dir;
  const std::string robot = fl::test::SourceDir() + "/config/robot/turtlebot2.yaml";
  const auto r = RunCommand(
      "{ " + BinDir() + "/fl-base-emulator --duration 3 --link kobuki > emu.out 2> emu.err & " +
          "sleep 0.5; timeout --foreground --preserve-status -s INT 1.5 " + BinDir() +
          "/fl-base-driver --lcm-url memq:// --robot " + robot +
          " --port kobuki; echo rc=$?; wait; }",
      dir);
  EXPECT_NE(r.out.find("rc=0"), std::string::npos) << r.out << r.err;
  EXPECT_NE(r.err.find("fl-base-driver] odometry "), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("odometry 0,"), std::string::npos) << r.err;  // some odometry came out
}

}  // namespace
}  // namespace fl::base
