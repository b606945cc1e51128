// Mapping a USB device to its ttyACM node through sysfs (on a fake sysfs tree), and libusb
// enumeration running without a Hokuyo attached.
#include "fusionloc/urg/usb_discovery.hpp"

#include <gtest/gtest.h>

#include <filesystem>

#include "test_paths.hpp"

namespace fl::urg {
namespace {

namespace fs = std::filesystem;

TEST(UsbDiscovery, SysfsNameOfBusAndPorts) {
  EXPECT_EQ(UsbSysfsName(1, {2}), "1-2");
  EXPECT_EQ(UsbSysfsName(3, {1, 4, 2}), "3-1.4.2");
}

TEST(UsbDiscovery, FindsTheTtyNodeOfTheDevicesInterface) {
  test::TempDir dir;
  // /sys/bus/usb/devices/1-1.2/1-1.2:1.0/tty/ttyACM3 as the cdc_acm driver makes it, and a
  // neighbour's node that must not be taken.
  fs::create_directories(dir.file("1-1.2/1-1.2:1.0/tty/ttyACM3"));
  fs::create_directories(dir.file("1-1.2/1-1.2:1.1"));
  fs::create_directories(dir.file("1-1.3/1-1.3:1.0/tty/ttyACM0"));
  fs::create_directories(dir.file("1-1.2/power"));
  EXPECT_EQ(TtyNodesOfUsbDevice(dir.path(), "1-1.2"), std::vector<std::string>{"/dev/ttyACM3"});
  EXPECT_EQ(TtyNodesOfUsbDevice(dir.path(), "1-1.3"), std::vector<std::string>{"/dev/ttyACM0"});
  EXPECT_TRUE(TtyNodesOfUsbDevice(dir.path(), "2-1").empty());
}

TEST(UsbDiscovery, EnumerationRunsAndReportsOnlyHokuyos) {
  std::string error;
  const auto found = FindHokuyoSensors(&error);
  // No Hokuyo on the build machines: none found (or libusb cannot run in this container,
  // which must be said, not crash).
  for (const auto& s : found) EXPECT_EQ(s.vendor_id, kHokuyoVendorId);
  if (!error.empty()) {
    EXPECT_NE(error.find("libusb_init failed"), std::string::npos) << error;
  }
  UsbWatcher watcher;
  if (!watcher.hotplug()) {
    EXPECT_FALSE(watcher.reason().empty());
  }
  EXPECT_TRUE(watcher.WaitForChange(50));  // returns: nothing plugged in, or time up
}

}  // namespace
}  // namespace fl::urg
