// A raw serial port (termios, 8N1, no flow control) for the device drivers, with errors that
// name the device and the fix: a path that does not exist, a permission error (the dialout
// group, the udev rule in config/udev/), a file that is not a tty, a device that vanished.
//
//   fl::serial::SerialPort port("/dev/kobuki", 115200);   // throws fl::serial::SerialError
//   port.Write(bytes.data(), bytes.size());
//   size_t n = port.Read(buf, sizeof buf, 20);             // waits up to 20 ms; 0 on timeout
//
// Pseudo-terminals (the emulators' /dev/pts/N) are ttys and work the same way.
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace fl::serial {

// Any failure to open, configure, read or write the port; the message names the device.
class SerialError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The device went away (cable pulled, USB reset, emulator closed): reopen it later.
class SerialDisconnected : public SerialError {
 public:
  using SerialError::SerialError;
};

// The message for an open() that failed with `err` (errno) on `path`: what happened and the
// fix (ENOENT: is it plugged in / the udev name; EACCES: the dialout group and the udev rule;
// EBUSY: another program holds it). Exposed for tests.
std::string OpenErrorMessage(const std::string& path, int err);

class SerialPort {
 public:
  // Opens and configures `path` raw at `baud` (one of the standard rates, 9600..4000000).
  // Throws SerialError (see OpenErrorMessage; "not a serial port" for a file that is not a
  // tty; an unsupported baud rate).
  SerialPort(const std::string& path, int baud);
  ~SerialPort();
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;

  // Reads what is available, waiting up to `timeout_ms` for the first byte. Returns the
  // number of bytes read (0 on timeout). Throws SerialDisconnected if the device is gone.
  size_t Read(uint8_t* buffer, size_t size, int timeout_ms);
  // Writes all of `size` bytes (waiting up to 1 s for room). Throws SerialDisconnected if the
  // device is gone, SerialError on a timeout.
  void Write(const uint8_t* data, size_t size);

  const std::string& path() const { return path_; }
  int fd() const { return fd_; }

 private:
  std::string path_;
  int fd_ = -1;
};

}  // namespace fl::serial
