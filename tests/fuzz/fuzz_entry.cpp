#include "fuzz_entry.hpp"

#include <sys/mman.h>
#include <unistd.h>

#include <stdexcept>

#include "fusionloc/common/log.hpp"

namespace fl::fuzz {

MemFile::MemFile(const void* data, size_t size) {
  fd_ = memfd_create("fl-fuzz", 0);
  if (fd_ < 0) throw std::runtime_error("memfd_create failed");
  const char* p = static_cast<const char*>(data);
  size_t done = 0;
  while (done < size) {
    const ssize_t n = write(fd_, p + done, size - done);
    if (n <= 0) throw std::runtime_error("memfd write failed");
    done += static_cast<size_t>(n);
  }
  lseek(fd_, 0, SEEK_SET);
  path_ = "/proc/self/fd/" + std::to_string(fd_);
}

MemFile::~MemFile() {
  if (fd_ >= 0) close(fd_);
}

void QuietLogs() { SetLogLevel(LogLevel::ERROR); }

}  // namespace fl::fuzz
