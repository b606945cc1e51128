#include "fusionloc/urg/serial_port.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace fl::urg {
namespace {

bool BaudConstant(int baud, speed_t* out) {
  switch (baud) {
    case 19200:
      *out = B19200;
      return true;
    case 38400:
      *out = B38400;
      return true;
    case 57600:
      *out = B57600;
      return true;
    case 115200:
      *out = B115200;
      return true;
    case 230400:
      *out = B230400;
      return true;
    case 500000:
      *out = B500000;
      return true;
    default:
      return false;
  }
}

}  // namespace

bool IsScipBaud(int baud) {
  return baud == 19200 || baud == 38400 || baud == 57600 || baud == 115200 || baud == 250000 ||
         baud == 500000 || baud == 750000;
}

std::string DescribeOpenError(const std::string& path, int err) {
  const std::string what = "cannot open the laser's serial port '" + path + "': ";
  switch (err) {
    case ENOENT:
      return what +
             "no such device. Is the sensor plugged in and powered? (ls /dev/ttyACM* "
             "/dev/hokuyo; with port: \"\" the driver finds a USB Hokuyo itself)";
    case EACCES:
    case EPERM:
      return what + "permission denied. Add yourself to the group that owns it (ls -l " + path +
             "; usually 'dialout', or 'fusionloc' with config/udev/99-fusionloc.rules "
             "installed as docs/HARDWARE.md says): sudo usermod -aG fusionloc $USER, then log "
             "in again";
    case EBUSY:
      return what + "device busy: another program holds it (fuser " + path + ")";
    case ENOTTY:
      return what +
             "not a serial device (a regular file, /dev/null, ...). Give the sensor's port, "
             "e.g. /dev/ttyACM0 or /dev/hokuyo, or port: \"\" to find it over USB";
    case ENXIO:
    case ENODEV:
      return what + "the device is gone (unplugged?)";
    default:
      return what + std::strerror(err);
  }
}

SerialPort::~SerialPort() { Close(); }

void SerialPort::Close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

Status SerialPort::Open(const std::string& path, int baud) {
  Close();
  path_ = path;
  speed_t speed;
  if (!BaudConstant(baud, &speed)) {
    return Status::Error("bit rate " + std::to_string(baud) + " for '" + path +
                         "' is not one the host supports (19200, 38400, 57600, 115200, "
                         "230400, 500000)");
  }
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) return Status::Error(DescribeOpenError(path, errno));
  if (!S_ISCHR(st.st_mode)) return Status::Error(DescribeOpenError(path, ENOTTY));
  const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return Status::Error(DescribeOpenError(path, errno));
  struct termios tio;
  if (!::isatty(fd) || ::tcgetattr(fd, &tio) != 0) {
    ::close(fd);
    return Status::Error(DescribeOpenError(path, ENOTTY));
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~(CSTOPB | PARENB | CRTSCTS);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  ::cfsetispeed(&tio, speed);
  ::cfsetospeed(&tio, speed);
  if (::tcsetattr(fd, TCSANOW, &tio) != 0) {
    const int e = errno;
    ::close(fd);
    return Status::Error("cannot set raw mode on '" + path + "': " + std::strerror(e));
  }
  ::tcflush(fd, TCIOFLUSH);
  fd_ = fd;
  return Status::Ok();
}

Status SerialPort::Write(std::string_view bytes) {
  if (fd_ < 0) return Status::Error("'" + path_ + "' is not open");
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) {
      struct pollfd p = {fd_, POLLOUT, 0};
      if (::poll(&p, 1, 1000) <= 0 || (p.revents & (POLLERR | POLLHUP))) {
        return Status::Error("write to '" + path_ + "' timed out or the device is gone");
      }
      continue;
    }
    return Status::Error("write to '" + path_ + "' failed: " + std::strerror(errno) +
                         " (device unplugged?)");
  }
  return Status::Ok();
}

int SerialPort::Read(char* buffer, int size, int timeout_ms, std::string* error) {
  if (fd_ < 0) {
    *error = "'" + path_ + "' is not open";
    return -1;
  }
  struct pollfd p = {fd_, POLLIN, 0};
  int rc;
  do {
    rc = ::poll(&p, 1, timeout_ms);
  } while (rc < 0 && errno == EINTR);
  if (rc < 0) {
    *error = "poll on '" + path_ + "' failed: " + std::strerror(errno);
    return -1;
  }
  if (rc == 0) return 0;
  const ssize_t n = ::read(fd_, buffer, static_cast<size_t>(size));
  if (n > 0) return static_cast<int>(n);
  if (n < 0 && (errno == EAGAIN || errno == EINTR)) return 0;
  *error = "'" + path_ + "' is gone (" + (n == 0 ? std::string("hang-up") : std::strerror(errno)) +
           "): the sensor was unplugged or powered off";
  return -1;
}

Status SerialPort::SetBaud(int baud) {
  speed_t speed;
  if (!BaudConstant(baud, &speed)) {
    return Status::Error("the host cannot set " + std::to_string(baud) + " bit/s on '" + path_ +
                         "'");
  }
  struct termios tio;
  if (fd_ < 0 || ::tcgetattr(fd_, &tio) != 0) return Status::Error("'" + path_ + "' is not open");
  ::cfsetispeed(&tio, speed);
  ::cfsetospeed(&tio, speed);
  if (::tcsetattr(fd_, TCSADRAIN, &tio) != 0) {
    return Status::Error("cannot set " + std::to_string(baud) + " bit/s on '" + path_ +
                         "': " + std::strerror(errno));
  }
  return Status::Ok();
}

void SerialPort::DiscardInput() {
  if (fd_ >= 0) ::tcflush(fd_, TCIFLUSH);
}

}  // namespace fl::urg
