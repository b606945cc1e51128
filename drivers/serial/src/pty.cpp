#include "fusionloc/serial/pty.hpp"

#include <fcntl.h>
#include <poll.h>
#include <stdlib.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "fusionloc/serial/serial_port.hpp"

namespace fl::serial {

Pty::Pty() {
  master_ = ::posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (master_ < 0) {
    throw SerialError(std::string("cannot open a pseudo-terminal (posix_openpt): ") +
                      std::strerror(errno) + "; is /dev/pts mounted?");
  }
  if (::grantpt(master_) != 0 || ::unlockpt(master_) != 0) {
    const int err = errno;
    ::close(master_);
    throw SerialError(std::string("cannot unlock the pseudo-terminal: ") + std::strerror(err));
  }
  char name[128];
  if (::ptsname_r(master_, name, sizeof name) != 0) {
    const int err = errno;
    ::close(master_);
    throw SerialError(std::string("ptsname failed: ") + std::strerror(err));
  }
  slave_path_ = name;
  slave_keepalive_ = ::open(name, O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (slave_keepalive_ >= 0) {
    termios tio{};
    if (::tcgetattr(slave_keepalive_, &tio) == 0) {
      ::cfmakeraw(&tio);
      ::tcsetattr(slave_keepalive_, TCSANOW, &tio);
    }
  }
  ::fcntl(master_, F_SETFL, ::fcntl(master_, F_GETFL) | O_NONBLOCK);
}

Pty::~Pty() {
  if (slave_keepalive_ >= 0) ::close(slave_keepalive_);
  if (master_ >= 0) ::close(master_);
}

size_t Pty::Read(uint8_t* buffer, size_t size, int timeout_ms) {
  pollfd p{master_, POLLIN, 0};
  if (::poll(&p, 1, timeout_ms) <= 0 || !(p.revents & POLLIN)) return 0;
  const ssize_t n = ::read(master_, buffer, size);
  return n > 0 ? static_cast<size_t>(n) : 0;
}

size_t Pty::Write(const uint8_t* data, size_t size) {
  const ssize_t n = ::write(master_, data, size);
  return n > 0 ? static_cast<size_t>(n) : 0;
}

}  // namespace fl::serial
