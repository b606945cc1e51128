// A pseudo-terminal for device emulators: the emulator reads and writes the master side, the
// driver under test opens slave_path() ("/dev/pts/N") as if it were the device.
//
// The constructor also opens the slave and keeps it open in raw mode, so that nothing the
// driver writes is echoed or translated before the driver configures the port itself, and so
// that the master does not see a hang-up while the driver closes and reopens the port.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace fl::serial {

class Pty {
 public:
  // Throws SerialError if no pseudo-terminal can be made.
  Pty();
  ~Pty();
  Pty(const Pty&) = delete;
  Pty& operator=(const Pty&) = delete;

  const std::string& slave_path() const { return slave_path_; }
  int master_fd() const { return master_; }

  // Reads what the driver wrote, waiting up to `timeout_ms`; 0 on timeout.
  size_t Read(uint8_t* buffer, size_t size, int timeout_ms);
  // Writes to the driver (drops what does not fit in the pty's buffer, as a serial line with
  // nobody reading would; returns the number of bytes written).
  size_t Write(const uint8_t* data, size_t size);

 private:
  int master_ = -1;
  int slave_keepalive_ = -1;
  std::string slave_path_;
};

}  // namespace fl::serial
