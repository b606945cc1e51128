// libFuzzer driver of one entry (FL_FUZZ_ENTRY, set by tests/fuzz/CMakeLists.txt).
#include <cstddef>
#include <cstdint>

int FL_FUZZ_ENTRY(const uint8_t* data, size_t size);

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return FL_FUZZ_ENTRY(data, size);
}
