// SerialPort: raw mode on a real tty (the emulator's pty), and the errors for what is not a
// sensor's port, each naming the device and the fix.
#include "fusionloc/urg/serial_port.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <fstream>

#include "fusionloc/urg/urg_emulator.hpp"
#include "test_paths.hpp"

namespace fl::urg {
namespace {

TEST(SerialPort, OpensThePtyAndExchangesBytes) {
  UrgEmulator emu(UrgEmulatorOptions{});
  ASSERT_TRUE(emu.Start().ok());
  SerialPort port;
  ASSERT_TRUE(port.Open(emu.device_path(), 115200).ok());
  ASSERT_TRUE(port.Write("BM\n").ok());
  std::string got, error;
  char buf[64];
  for (int i = 0; i < 50 && got.find("\n\n") == std::string::npos; ++i) {
    const int n = port.Read(buf, sizeof(buf), 100, &error);
    ASSERT_GE(n, 0) << error;
    got.append(buf, static_cast<size_t>(n));
  }
  EXPECT_EQ(got, "BM\n00P\n\n");
  EXPECT_EQ(port.Read(buf, sizeof(buf), 50, &error), 0);  // nothing more: a timeout
}

TEST(SerialPort, DevNullIsNotASerialDevice) {
  SerialPort port;
  const Status s = port.Open("/dev/null", 115200);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'/dev/null': not a serial device"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("/dev/ttyACM0 or /dev/hokuyo"), std::string::npos) << s.message();
}

TEST(SerialPort, ARegularFileIsNotASerialDevice) {
  test::TempDir dir;
  const std::string file = dir.file("scan.txt");
  std::ofstream(file) << "MD0044072501000\n";
  SerialPort port;
  const Status s = port.Open(file, 115200);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'" + file + "': not a serial device"), std::string::npos)
      << s.message();
}

TEST(SerialPort, AMissingDeviceAsksWhetherItIsPluggedIn) {
  SerialPort port;
  const Status s = port.Open("/dev/ttyACM_fl_missing", 115200);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'/dev/ttyACM_fl_missing': no such device. Is the sensor plugged in"),
            std::string::npos)
      << s.message();
}

TEST(SerialPort, PermissionDeniedNamesTheGroupAndTheUdevRule) {
  // The message itself (the seam: what open() failing with EACCES gives).
  const std::string m = DescribeOpenError("/dev/ttyACM0", EACCES);
  EXPECT_NE(m.find("'/dev/ttyACM0': permission denied"), std::string::npos) << m;
  EXPECT_NE(m.find("'dialout'"), std::string::npos) << m;
  EXPECT_NE(m.find("'fusionloc' with config/udev/99-fusionloc.rules"), std::string::npos) << m;
  // And for real, on the emulator's pty with its permissions taken away.
  if (geteuid() == 0)
    GTEST_SKIP() << "running as root: open() ignores permissions (CI runs as "
                    "root); the message is checked above";
  UrgEmulator emu(UrgEmulatorOptions{});
  ASSERT_TRUE(emu.Start().ok());
  ASSERT_EQ(chmod(emu.slave_path().c_str(), 0), 0);
  SerialPort port;
  const Status s = port.Open(emu.slave_path(), 115200);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("permission denied"), std::string::npos) << s.message();
}

TEST(SerialPort, ABitRateTheHostCannotSetIsRefused) {
  SerialPort port;
  const Status s = port.Open("/dev/null", 12345);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("bit rate 12345"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace fl::urg
