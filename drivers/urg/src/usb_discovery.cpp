#include "fusionloc/urg/usb_discovery.hpp"

#include <libusb-1.0/libusb.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <thread>

namespace fl::urg {

namespace fs = std::filesystem;

std::string UsbSysfsName(int bus, const std::vector<int>& ports) {
  std::string s = std::to_string(bus) + "-";
  for (size_t i = 0; i < ports.size(); ++i) s += (i ? "." : "") + std::to_string(ports[i]);
  return s;
}

std::vector<std::string> TtyNodesOfUsbDevice(const std::string& sysfs_root,
                                             const std::string& sysfs_name) {
  std::vector<std::string> out;
  std::error_code ec;
  const fs::path dev = fs::path(sysfs_root) / sysfs_name;
  for (const auto& iface : fs::directory_iterator(dev, ec)) {
    const std::string n = iface.path().filename().string();
    if (n.rfind(sysfs_name + ":", 0) != 0) continue;
    std::error_code ec2;
    for (const auto& tty : fs::directory_iterator(iface.path() / "tty", ec2)) {
      out.push_back("/dev/" + tty.path().filename().string());
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<UsbSensor> FindHokuyoSensors(std::string* error, const std::string& sysfs_root) {
  std::vector<UsbSensor> out;
  libusb_context* ctx = nullptr;
  if (const int rc = libusb_init(&ctx); rc != 0) {
    *error = std::string("libusb_init failed: ") + libusb_error_name(rc);
    return out;
  }
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(ctx, &list);
  for (ssize_t i = 0; i < n; ++i) {
    libusb_device_descriptor desc;
    if (libusb_get_device_descriptor(list[i], &desc) != 0) continue;
    if (desc.idVendor != kHokuyoVendorId) continue;
    uint8_t ports[8];
    const int np = libusb_get_port_numbers(list[i], ports, sizeof(ports));
    if (np <= 0) continue;
    UsbSensor s;
    s.sysfs_name =
        UsbSysfsName(libusb_get_bus_number(list[i]), std::vector<int>(ports, ports + np));
    s.vendor_id = desc.idVendor;
    s.product_id = desc.idProduct;
    const auto ttys = TtyNodesOfUsbDevice(sysfs_root, s.sysfs_name);
    if (!ttys.empty()) s.tty = ttys.front();
    out.push_back(s);
  }
  if (n >= 0) libusb_free_device_list(list, 1);
  libusb_exit(ctx);
  return out;
}

struct UsbWatcher::Impl {
  libusb_context* ctx = nullptr;
  libusb_hotplug_callback_handle handle = 0;
  bool hotplug = false;
  bool changed = false;
  std::string reason;

  static int Callback(libusb_context*, libusb_device*, libusb_hotplug_event, void* user) {
    static_cast<Impl*>(user)->changed = true;
    return 0;  // stay registered
  }
};

UsbWatcher::UsbWatcher() : impl_(std::make_unique<Impl>()) {
  if (const int rc = libusb_init(&impl_->ctx); rc != 0) {
    impl_->ctx = nullptr;
    impl_->reason = std::string("libusb_init failed: ") + libusb_error_name(rc);
    return;
  }
  if (!libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG)) {
    impl_->reason = "libusb has no hotplug support here";
    return;
  }
  const int events = LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED | LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT;
  const int rc = libusb_hotplug_register_callback(
      impl_->ctx, static_cast<libusb_hotplug_event>(events), LIBUSB_HOTPLUG_NO_FLAGS,
      kHokuyoVendorId, LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY, &Impl::Callback,
      impl_.get(), &impl_->handle);
  if (rc != LIBUSB_SUCCESS) {
    impl_->reason =
        std::string("libusb_hotplug_register_callback failed: ") + libusb_error_name(rc);
    return;
  }
  impl_->hotplug = true;
}

UsbWatcher::~UsbWatcher() {
  if (impl_->ctx) {
    if (impl_->hotplug) libusb_hotplug_deregister_callback(impl_->ctx, impl_->handle);
    libusb_exit(impl_->ctx);
  }
}

bool UsbWatcher::hotplug() const { return impl_->hotplug; }
const std::string& UsbWatcher::reason() const { return impl_->reason; }

bool UsbWatcher::WaitForChange(int timeout_ms) {
  if (!impl_->hotplug) {
    std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
    return true;
  }
  impl_->changed = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (!impl_->changed && std::chrono::steady_clock::now() < deadline) {
    struct timeval tv = {0, 100000};
    libusb_handle_events_timeout_completed(impl_->ctx, &tv, nullptr);
  }
  // A tty node appears a little after the USB device: let udev create it.
  if (impl_->changed) std::this_thread::sleep_for(std::chrono::milliseconds(300));
  return true;
}

}  // namespace fl::urg
