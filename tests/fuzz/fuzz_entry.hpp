// Fuzz entry points: one function per input path, `int Fuzz_<name>(const uint8_t*, size_t)`.
// The same function is the body of the libFuzzer target fl-fuzz-<name> (clang,
// -DFL_FUZZ=ON, tests/fuzz/fuzz_main.cpp) and is what fuzz_regression_test (gcc, the normal
// suite) feeds every committed seed and every kept crashing input to. An entry returns 0;
// a violated invariant aborts (FL_FUZZ_CHECK), which both report as a failure.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

namespace fl::fuzz {

// Aborts with the condition's text: an invariant the code under test promises is broken.
#define FL_FUZZ_CHECK(cond)                                                              \
  do {                                                                                   \
    if (!(cond)) {                                                                       \
      std::fprintf(stderr, "%s:%d: fuzz invariant failed: %s\n", __FILE__, __LINE__, #cond); \
      std::abort();                                                                      \
    }                                                                                    \
  } while (0)

// Reads the input front to back; past the end it yields zeros / empty views.
class Input {
 public:
  Input(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  bool empty() const { return pos_ >= size_; }
  size_t remaining() const { return size_ - pos_; }
  uint8_t Byte() { return pos_ < size_ ? data_[pos_++] : 0; }
  uint16_t U16() {
    const uint16_t lo = Byte();
    return static_cast<uint16_t>(lo | (Byte() << 8));
  }
  std::string_view Bytes(size_t n) {
    n = n < remaining() ? n : remaining();
    std::string_view v(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return v;
  }
  std::string_view Rest() { return Bytes(remaining()); }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

// The bytes as an anonymous in-memory file (memfd) with a path that open() accepts
// ("/proc/self/fd/N"), for readers that take a file name. Closed at destruction.
class MemFile {
 public:
  MemFile(const void* data, size_t size);
  ~MemFile();
  MemFile(const MemFile&) = delete;
  MemFile& operator=(const MemFile&) = delete;
  const std::string& path() const { return path_; }

 private:
  int fd_ = -1;
  std::string path_;
};

// Quiet logging (a fuzzer runs millions of inputs); called by the entries.
void QuietLogs();

}  // namespace fl::fuzz
