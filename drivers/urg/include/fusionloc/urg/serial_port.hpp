// Byte streams to the sensor: the abstract ByteStream that UrgSensor speaks SCIP over (tests
// drive it directly), and SerialPort, a POSIX serial port (USB-ACM /dev/ttyACM*, RS-232
// /dev/ttyS* or /dev/ttyUSB*, or the emulator's pseudo-terminal) in raw mode.
#pragma once

#include <string>
#include <string_view>

#include "fusionloc/common/status.hpp"

namespace fl::urg {

class ByteStream {
 public:
  virtual ~ByteStream() = default;
  // Writes all of `bytes`; an error if the device is gone.
  virtual Status Write(std::string_view bytes) = 0;
  // Waits up to timeout_ms for bytes and reads up to `size` of them. Returns the count read
  // (> 0), 0 on timeout, or -1 if the device is gone or failed (*error says why).
  virtual int Read(char* buffer, int size, int timeout_ms, std::string* error) = 0;
  // Changes the host side's bit rate (RS-232 after SS); no effect on USB-ACM and pty.
  virtual Status SetBaud(int /*baud*/) { return Status::Ok(); }
  // Discards bytes received and not read yet.
  virtual void DiscardInput() {}
  // The device, for messages ("/dev/ttyACM0").
  virtual std::string name() const = 0;
};

// The user-facing message for a failed open() of `path` with errno `err`: names the device and
// the fix (ENOENT: plugged in? EACCES: the dialout / fusionloc group and the udev rule; ...).
std::string DescribeOpenError(const std::string& path, int err);

// The bit rates SCIP's SS command knows (19200 ... 750000); true if `baud` is one.
bool IsScipBaud(int baud);

class SerialPort : public ByteStream {
 public:
  SerialPort() = default;
  ~SerialPort() override;
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;

  // Opens `path` (O_NOCTTY, raw 8N1, no flow control, `baud` bit/s). Errors name the device and
  // the fix: missing, permission denied, not a terminal (a regular file, /dev/null), busy.
  Status Open(const std::string& path, int baud);
  void Close();
  bool is_open() const { return fd_ >= 0; }

  Status Write(std::string_view bytes) override;
  int Read(char* buffer, int size, int timeout_ms, std::string* error) override;
  Status SetBaud(int baud) override;
  void DiscardInput() override;
  std::string name() const override { return path_; }

 private:
  int fd_ = -1;
  std::string path_;
};

}  // namespace fl::urg
