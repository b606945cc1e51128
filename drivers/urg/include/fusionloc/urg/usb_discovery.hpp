// Finding a USB Hokuyo (vendor id 0x15d1) and its /dev/ttyACM* node with libusb-1.0, and
// waiting for it to come back: libusb hotplug events where the platform has them
// (libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG)), polling otherwise.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fl::urg {

constexpr uint16_t kHokuyoVendorId = 0x15d1;

struct UsbSensor {
  std::string sysfs_name;  // "1-1.2": bus 1, ports 1.2
  uint16_t vendor_id = 0, product_id = 0;
  std::string tty;  // "/dev/ttyACM0"; empty if no tty node is bound (cdc_acm missing?)
};

// The kernel's name of a USB device: "<bus>-<port>.<port>..." ("1-1.2").
std::string UsbSysfsName(int bus, const std::vector<int>& ports);

// /dev/tty* nodes of the interfaces of USB device `sysfs_name` under `sysfs_root`
// (normally /sys/bus/usb/devices): <root>/<name>/<name>:C.I/tty/<node>, sorted.
std::vector<std::string> TtyNodesOfUsbDevice(const std::string& sysfs_root,
                                             const std::string& sysfs_name);

// Every USB device with Hokuyo's vendor id, with its tty node. *error is set (and the list is
// empty) if libusb cannot be initialised.
std::vector<UsbSensor> FindHokuyoSensors(std::string* error,
                                         const std::string& sysfs_root = "/sys/bus/usb/devices");

// Waits for Hokuyo USB devices to arrive or leave.
class UsbWatcher {
 public:
  UsbWatcher();
  ~UsbWatcher();
  UsbWatcher(const UsbWatcher&) = delete;
  UsbWatcher& operator=(const UsbWatcher&) = delete;

  // True if libusb delivers hotplug events here (else WaitForChange just waits).
  bool hotplug() const;
  // Waits up to timeout_ms; true if a Hokuyo arrived or left (hotplug), or the time is up
  // (polling: the caller should look again either way).
  bool WaitForChange(int timeout_ms);
  // Why there is no hotplug ("" if there is).
  const std::string& reason() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fl::urg
