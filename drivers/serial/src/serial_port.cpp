#include "fusionloc/serial/serial_port.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace fl::serial {
namespace {

speed_t BaudConstant(int baud) {
  switch (baud) {
    case 9600:
      return B9600;
    case 19200:
      return B19200;
    case 38400:
      return B38400;
    case 57600:
      return B57600;
    case 115200:
      return B115200;
    case 230400:
      return B230400;
    case 460800:
      return B460800;
    case 500000:
      return B500000;
    case 921600:
      return B921600;
    case 1000000:
      return B1000000;
    case 2000000:
      return B2000000;
    case 3000000:
      return B3000000;
    case 4000000:
      return B4000000;
    default:
      return B0;
  }
}

bool IsDisconnect(int err) { return err == EIO || err == ENXIO || err == ENODEV || err == EBADF; }

}  // namespace

std::string OpenErrorMessage(const std::string& path, int err) {
  const std::string what = "serial port '" + path + "': ";
  switch (err) {
    case ENOENT:
    case ENXIO:
    case ENODEV:
      return what +
             "no such device: is it plugged in and powered? (the udev rules in config/udev/ "
             "give stable names such as /dev/kobuki; without them try /dev/ttyUSB0 or "
             "/dev/ttyACM0, see `ls /dev/serial/by-id/`)";
    case EACCES:
    case EPERM:
      return what + "permission denied: add your user to the group that owns it (`ls -l " + path +
             "`; usually dialout: `sudo usermod -aG dialout $USER`, then log in again), or "
             "install the rules in config/udev/ (group fusionloc, mode 0660), see "
             "docs/HARDWARE.md";
    case EBUSY:
      return what + "busy: another program holds it (`fuser " + path + "`)";
    case EISDIR:
      return what + "is a directory, not a serial port";
    default:
      return what + std::strerror(err);
  }
}

SerialPort::SerialPort(const std::string& path, int baud) : path_(path) {
  const speed_t speed = BaudConstant(baud);
  if (speed == B0) {
    throw SerialError("serial port '" + path + "': unsupported baud rate " + std::to_string(baud) +
                      " (use 9600, 19200, 38400, 57600, 115200, ...)");
  }
  fd_ = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) throw SerialError(OpenErrorMessage(path, errno));
  termios tio{};
  if (!::isatty(fd_) || ::tcgetattr(fd_, &tio) != 0) {
    ::close(fd_);
    fd_ = -1;
    throw SerialError("serial port '" + path +
                      "': not a serial port (not a tty); give the device node, e.g. "
                      "/dev/kobuki or /dev/ttyUSB0");
  }
  ::ioctl(fd_, TIOCEXCL);  // no second opener (best effort: fails harmlessly on some ptys)
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~static_cast<tcflag_t>(CSTOPB | PARENB | CRTSCTS | CSIZE);
  tio.c_cflag |= CS8;
  tio.c_iflag &= ~static_cast<tcflag_t>(IXON | IXOFF | IXANY);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  ::cfsetispeed(&tio, speed);
  ::cfsetospeed(&tio, speed);
  if (::tcsetattr(fd_, TCSANOW, &tio) != 0) {
    const int err = errno;
    ::close(fd_);
    fd_ = -1;
    throw SerialError("serial port '" + path + "': cannot configure it (" + std::strerror(err) +
                      ")");
  }
  ::tcflush(fd_, TCIOFLUSH);
}

SerialPort::~SerialPort() {
  if (fd_ >= 0) ::close(fd_);
}

size_t SerialPort::Read(uint8_t* buffer, size_t size, int timeout_ms) {
  pollfd p{fd_, POLLIN, 0};
  const int rc = ::poll(&p, 1, timeout_ms);
  if (rc < 0) {
    if (errno == EINTR) return 0;
    throw SerialError("serial port '" + path_ + "': poll failed: " + std::strerror(errno));
  }
  if (rc == 0) return 0;
  if ((p.revents & (POLLHUP | POLLERR | POLLNVAL)) && !(p.revents & POLLIN)) {
    throw SerialDisconnected("serial port '" + path_ + "': the device went away (hang-up)");
  }
  const ssize_t n = ::read(fd_, buffer, size);
  if (n > 0) return static_cast<size_t>(n);
  if (n == 0) {
    throw SerialDisconnected("serial port '" + path_ + "': the device went away (end of file)");
  }
  if (errno == EAGAIN || errno == EINTR) return 0;
  if (IsDisconnect(errno)) {
    throw SerialDisconnected("serial port '" + path_ + "': the device went away (" +
                             std::strerror(errno) + ")");
  }
  throw SerialError("serial port '" + path_ + "': read failed: " + std::strerror(errno));
}

void SerialPort::Write(const uint8_t* data, size_t size) {
  size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd_, data + done, size - done);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) {
      pollfd p{fd_, POLLOUT, 0};
      if (::poll(&p, 1, 1000) <= 0) {
        throw SerialError("serial port '" + path_ + "': write timed out (device not reading)");
      }
      continue;
    }
    if (n < 0 && IsDisconnect(errno)) {
      throw SerialDisconnected("serial port '" + path_ + "': the device went away (" +
                               std::strerror(errno) + ")");
    }
    throw SerialError("serial port '" + path_ + "': write failed: " +
                      std::string(n < 0 ? std::strerror(errno) : "nothing written"));
  }
}

}  // namespace fl::serial
