// Every LCM message type of the project (lcmtypes/*/*.lcm; the list is generated): the first
// byte picks the type, the rest is decoded as it. A message that decodes re-encodes to a
// message that decodes to the same encoding (no field is lost or invented), and a claimed
// array size is checked against the bytes before anything is allocated
// (lcmtypes/include/fusionloc_lcm_guard.hpp; libFuzzer's -malloc_limit_mb catches a miss).
#include <vector>

#include "../fuzz_entry.hpp"
#include "fl_fuzz_lcm_types.inc"  // FL_FUZZ_LCM_INCLUDES / FL_FUZZ_LCM_TYPES, from CMake

FL_FUZZ_LCM_INCLUDES

namespace {
template <class T>
void DecodeAs(std::string_view bytes) {
  T msg;
  const int n = static_cast<int>(bytes.size());
  if (msg.decode(bytes.data(), 0, n) != n) return;
  const int size = msg.getEncodedSize();
  FL_FUZZ_CHECK(size == n);
  std::vector<uint8_t> once(static_cast<size_t>(size));
  FL_FUZZ_CHECK(msg.encode(once.data(), 0, size) == size);
  T again;
  FL_FUZZ_CHECK(again.decode(once.data(), 0, size) == size);
  std::vector<uint8_t> twice(static_cast<size_t>(again.getEncodedSize()));
  FL_FUZZ_CHECK(twice.size() == once.size());
  FL_FUZZ_CHECK(again.encode(twice.data(), 0, size) == size);
  FL_FUZZ_CHECK(once == twice);
}

using Decoder = void (*)(std::string_view);
const Decoder kDecoders[] = {FL_FUZZ_LCM_TYPES};
}  // namespace

int Fuzz_lcm_decode(const uint8_t* data, size_t size) {
  fl::fuzz::Input in(data, size);
  const size_t which = in.Byte() % (sizeof(kDecoders) / sizeof(kDecoders[0]));
  kDecoders[which](in.Rest());
  return 0;
}
